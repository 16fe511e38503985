"""rliable's statistics: IQM, stratified-bootstrap intervals and probability of improvement, against hand values."""
import itertools

import numpy as np
import pytest
from scipy.stats import trim_mean

from torchrl_cebp.stats import iqm, probability_of_improvement, probability_of_improvement_ci, stratified_bootstrap_ci


def test_iqm_by_hand_and_as_scipy_trim_mean():
    assert iqm(np.arange(1.0, 9.0)) == pytest.approx(4.5)  # 8 runs: drops 1, 2 and 7, 8
    assert iqm([[0.0, 10.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]) == pytest.approx(trim_mean([0, 10, 1, 1, 2, 2, 3, 3], 0.25))
    rng = np.random.default_rng(0)
    for n in range(1, 13):
        x = rng.random(n)
        assert iqm(x) == pytest.approx(trim_mean(x, 0.25))


def test_bootstrap_interval_converges_to_the_exact_resampling_distribution():
    scores = np.array([0.0, 0.1, 0.5, 0.9])
    exact = [iqm(np.array(resample)) for resample in itertools.product(scores, repeat=4)]  # all 256, equally likely
    low, high = stratified_bootstrap_ci(scores, reps=40000)
    np.testing.assert_allclose([low, high], np.percentile(exact, [2.5, 97.5]), atol=0.03)


def test_stratified_bootstrap_keeps_runs_within_their_task():
    # Two tasks on very different scales: resampling within each task never mixes them, so the IQM
    # over both stays between what each task's runs allow.
    scores = np.array([[0.0, 100.0], [0.0, 100.0], [1.0, 101.0]])
    low, high = stratified_bootstrap_ci(scores, reps=2000)
    assert 50.0 <= low <= high <= 51.0


def test_probability_of_improvement_by_hand():
    # 0.1 beats nothing; 0.5 beats 0.2 and ties 0.5; 0.9 beats both: (0 + 1.5 + 2) / 6
    assert probability_of_improvement([0.1, 0.5, 0.9], [0.2, 0.5]) == pytest.approx(3.5 / 6)
    assert probability_of_improvement([0.2, 0.5], [0.1, 0.5, 0.9]) == pytest.approx(1 - 3.5 / 6)
    with pytest.raises(ValueError, match="same tasks"):
        probability_of_improvement(np.zeros((2, 2)), np.zeros((2, 3)))


def test_probability_of_improvement_interval_by_hand():
    # resampling x = [0, 1] gives {0,0}, {0,1}, {1,0}, {1,1}: P(X > 0.5) is 0, 0.5, 0.5, 1
    assert probability_of_improvement_ci([0.0, 1.0], [0.5], reps=4000) == (0.0, 1.0)
    low, high = probability_of_improvement_ci([0.6, 0.7, 0.8], [0.1, 0.2, 0.3])
    assert low == high == 1.0
