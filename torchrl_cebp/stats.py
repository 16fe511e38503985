"""Aggregate statistics over seeds with rliable's conventions (Agarwal et al., 2021), in NumPy.

* interquartile mean (IQM): the mean of the middle 50% of runs, trimming ``int(0.25 n)`` runs at
  each end (``scipy.stats.trim_mean(x, 0.25)``, as ``rliable.metrics.aggregate_iqm``);
* 95% confidence intervals from a stratified bootstrap: runs are resampled with replacement
  within each task, and the interval is the percentile interval of the statistic (rliable's
  ``get_interval_estimates`` default);
* probability of improvement ``P(X > Y)``: per task the Mann-Whitney statistic
  ``(1 / (n m)) sum_i sum_j S(x_i, y_j)`` with ``S = 1`` if ``x_i > y_j``, ``1/2`` if equal, else 0,
  averaged over tasks, with a stratified-bootstrap interval that resamples both sets.

Scores are arrays ``[runs, tasks]`` (a 1-D array is one task). rliable itself pulls ``arch`` and
``pandas<3``; these few functions follow its definitions without those dependencies.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

CONFIDENCE = 0.95
BOOTSTRAP_REPS = 5000


def _as_runs_by_tasks(scores) -> np.ndarray:
    scores = np.asarray(scores, dtype=np.float64)
    if scores.ndim == 1:
        scores = scores[:, None]
    if scores.ndim != 2 or scores.shape[0] == 0:
        raise ValueError(f"scores must be [runs] or [runs, tasks] with at least one run; got shape {scores.shape}")
    return scores


def iqm(scores, axis: int | None = None) -> np.ndarray | float:
    """Interquartile mean: ``scipy.stats.trim_mean(scores, 0.25)`` over all runs and tasks (or along ``axis``).

    Args:
        scores (array_like): the scores, e.g. ``[runs, tasks]``.
        axis (int, optional): the axis of the runs to trim and average; ``None`` pools every score.
            Defaults to ``None``.

    Returns:
        a float when pooled (or for a 1-D ``scores``), else an array without ``axis``.

    Examples:
        >>> iqm([1.0, 2.0, 3.0, 4.0])  # drops 1 and 4
        2.5
        >>> round(iqm([0.0, 0.1, 0.2]), 12)  # three runs: int(0.75) = 0 trimmed, the plain mean
        0.1
    """
    values = np.asarray(scores, dtype=np.float64)
    if axis is None:
        values, axis = values.reshape(-1), 0
    values = np.sort(values, axis=axis)
    n = values.shape[axis]
    cut = int(0.25 * n)
    kept = np.take(values, np.arange(cut, n - cut), axis=axis)
    out = kept.mean(axis=axis)
    return float(out) if np.ndim(out) == 0 else out


def _resamples(scores: np.ndarray, reps: int, rng: np.random.Generator) -> np.ndarray:
    # [runs, tasks] -> [reps, runs, tasks]: runs drawn with replacement within each task (stratified).
    runs, tasks = scores.shape
    picks = rng.integers(0, runs, size=(reps, runs, tasks))
    return np.take_along_axis(np.broadcast_to(scores, (reps, runs, tasks)), picks, axis=1)


def _percentile_interval(values: np.ndarray, confidence: float) -> tuple[float, float]:
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(values, [tail, 100 - tail])
    return float(low), float(high)


def stratified_bootstrap_ci(
    scores,
    statistic: Callable[[np.ndarray], np.ndarray] = lambda s: iqm(s.reshape(s.shape[0], -1), axis=1),
    reps: int = BOOTSTRAP_REPS,
    confidence: float = CONFIDENCE,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile interval of ``statistic`` over ``reps`` stratified bootstrap resamples of ``scores`` [runs, tasks].

    Args:
        scores (array_like): ``[runs, tasks]``, or ``[runs]`` for one task.
        statistic (callable, optional): maps a batch ``[reps, runs, tasks]`` of resampled scores to ``[reps]``
            values. Defaults to the IQM of each resample.
        reps (int, optional): the bootstrap resamples. Defaults to ``BOOTSTRAP_REPS`` (5000).
        confidence (float, optional): the interval's coverage. Defaults to ``CONFIDENCE`` (0.95).
        seed (int, optional): seeds the resampling. Defaults to ``0``.

    Returns:
        ``(low, high)``.

    Raises:
        ValueError: ``scores`` is not ``[runs]`` or ``[runs, tasks]`` with at least one run.

    Examples:
        >>> stratified_bootstrap_ci([0.5, 0.5, 0.5])
        (0.5, 0.5)
        >>> low, high = stratified_bootstrap_ci([0.0, 0.5, 1.0])
        >>> 0.0 <= low < 0.5 < high <= 1.0
        True
    """
    resampled = _resamples(_as_runs_by_tasks(scores), reps, np.random.default_rng(seed))
    return _percentile_interval(statistic(resampled), confidence)


def _mann_whitney(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # x [..., n, tasks], y [..., m, tasks] -> P(X > Y) per task, averaged over tasks: [...]
    greater = (x[..., :, None, :] > y[..., None, :, :]).astype(np.float64)
    ties = (x[..., :, None, :] == y[..., None, :, :]).astype(np.float64)
    return (greater + 0.5 * ties).mean(axis=(-3, -2)).mean(-1)


def probability_of_improvement(x, y) -> float:
    """``P(X > Y)``: how likely a run of ``x`` scores above a run of ``y`` (ties count half), averaged over tasks.

    Args:
        x (array_like): ``[runs, tasks]``, or ``[runs]`` for one task.
        y (array_like): the same for the other method; its run count may differ.

    Raises:
        ValueError: ``x`` and ``y`` score different numbers of tasks, or either has no run.

    Examples:
        >>> probability_of_improvement([1.0, 2.0], [0.0, 2.0])  # (1 + 0 + 1 + 0.5) / 4
        0.625
        >>> probability_of_improvement([0.3, 0.3], [0.3])
        0.5
    """
    x, y = _as_runs_by_tasks(x), _as_runs_by_tasks(y)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x and y must score the same tasks; got {x.shape[1]} and {y.shape[1]}")
    return float(_mann_whitney(x, y))


def probability_of_improvement_ci(
    x, y, reps: int = BOOTSTRAP_REPS, confidence: float = CONFIDENCE, seed: int = 0
) -> tuple[float, float]:
    """Stratified-bootstrap percentile interval of :func:`probability_of_improvement`, resampling both sets.

    Args:
        x (array_like): ``[runs, tasks]``, or ``[runs]`` for one task.
        y (array_like): the same for the other method.
        reps (int, optional): the bootstrap resamples. Defaults to ``BOOTSTRAP_REPS`` (5000).
        confidence (float, optional): the interval's coverage. Defaults to ``CONFIDENCE`` (0.95).
        seed (int, optional): seeds the resampling. Defaults to ``0``.

    Returns:
        ``(low, high)``.

    Examples:
        >>> probability_of_improvement_ci([1.0, 1.0], [0.0, 0.0])
        (1.0, 1.0)
    """
    x, y = _as_runs_by_tasks(x), _as_runs_by_tasks(y)
    rng = np.random.default_rng(seed)
    return _percentile_interval(_mann_whitney(_resamples(x, reps, rng), _resamples(y, reps, rng)), confidence)
