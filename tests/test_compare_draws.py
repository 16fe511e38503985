"""scripts/compare_draws.py on a real tiny run: each draw metric where its value is known exactly, and the bounds the
paper-form CEBP's draw keeps at every sigmoid temperature."""
import csv
import math
from pathlib import Path

import pytest
import torch

from tests.modules import load_module
from torchrl_cebp.replay.episodes import episode_lengths
from torchrl_cebp.training.checkpoint import load_checkpoint, stored_episodes

REPO = Path(__file__).resolve().parents[1]
TEMPERATURES = ("0.001", "0.01", "0.1", "1", "5")
UNWEIGHTED = ("her", "cper")  # samplers without IS weights
compare_draws = load_module(REPO / "scripts" / "compare_draws.py")


@pytest.fixture(scope="module")
def draws(tiny_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("draws")
    compare_draws.main([str(tiny_run), "--samplers", *UNWEIGHTED, "cebp_initial", "--temperatures", *TEMPERATURES,
                        "--csv", str(out / "draws.csv"), "--out", str(out / "draws.png"),
                        "--summary", str(out / "summary.png")])
    with (out / "draws.csv").open() as f:
        return out, list(csv.DictReader(f))


def test_every_sampler_and_temperature_has_a_row_per_epoch(draws, tiny_run):
    out, rows = draws
    with (tiny_run / "progress.csv").open() as f:
        epochs = len(list(csv.DictReader(f)))
    labels = [*UNWEIGHTED, "cebp_initial", *(f"cebp_T{t}" for t in TEMPERATURES)]
    assert [(row["sampler"], int(row["epoch"])) for row in rows] == [(s, e) for s in labels for e in range(epochs)]
    assert {row["sampler"]: row["temperature"] for row in rows} == {
        **{s: "" for s in labels[:3]}, **{f"cebp_T{t}": str(float(t)) for t in TEMPERATURES}}
    assert (out / "draws.png").stat().st_size > 10_000 and (out / "summary.png").stat().st_size > 10_000


def test_uniform_draws_use_the_whole_buffer_and_samplers_without_weights_weight_each_draw_one(draws):
    _, rows = draws
    for row in rows:
        if row["sampler"] == "her":
            assert float(row["ess"]) == pytest.approx(1.0) and float(row["kl"]) == pytest.approx(0.0, abs=1e-12)
        if row["sampler"] in UNWEIGHTED:
            assert float(row["is_mean"]) == 1.0 and float(row["is_ess"]) == 1.0


def test_each_draws_spread_is_a_fraction_and_its_kl_is_bounded_by_its_ess(draws):
    _, rows = draws
    for row in rows:
        ess, kl = float(row["ess"]), float(row["kl"])
        assert 0 < ess <= 1 + 1e-12 and 0 < float(row["is_mean"]) <= 1 and 0 < float(row["is_ess"]) <= 1, row
        # Jensen: KL = E_p[log(N p)] <= log E_p[N p] = log(N sum p^2) = -log(ess); both 0 only for a uniform draw.
        assert -1e-12 <= kl <= -math.log(ess) + 1e-12, row


def test_the_paper_forms_draw_stays_within_twice_uniform_at_every_temperature(draws, tiny_run):
    # With every episode as long (Push never ends one early), each priority k sum_t sigmoid(T c(t)) over c >= 0 lies
    # in [k L / 2, k L): Kantorovich's inequality then bounds the draw's ess by 4 * 2 / (1 + 2)^2 = 8/9 from below,
    # and the bound above its KL by log(9/8). Larger T need not raise the KL: once every episode's energy is positive
    # from its first steps, a large T saturates every sigmoid and draws uniformly again, so no order over T is asserted.
    episodes, _ = stored_episodes(load_checkpoint(tiny_run))
    assert episode_lengths(episodes).unique().numel() == 1
    _, rows = draws
    for row in rows:
        if row["sampler"].startswith("cebp_T"):
            assert float(row["ess"]) >= 8 / 9 - 1e-12 and float(row["kl"]) <= math.log(9 / 8) + 1e-12, row


@pytest.mark.parametrize("workers", [1, 2])
def test_importance_weight_spread_is_the_spread_of_the_weights_the_samplers_draws_carry(workers):
    from tests.replay.conftest import make_episodes, sparse_reward
    from torchrl_cebp.replay import HindsightRelabel, make_replay_buffer
    from torchrl_cebp.replay.samplers import CEBPSampler, PerWorkerSampler

    batch, batches = 64, 400
    shards = [CEBPSampler(temperature=0.1) for _ in range(workers)]
    sampler = shards[0] if workers == 1 else PerWorkerSampler(*shards)
    # Episodes from no touch to full touch: priorities from k L / 2 to nearly k L, weights from 1 to nearly 1/2.
    episodes = make_episodes(100, touch=torch.rand(100, 50, 2) * torch.linspace(0, 1, 100).view(100, 1, 1))
    replay = make_replay_buffer(sampler, HindsightRelabel(sparse_reward), capacity=100 * episodes.shape[1],
                                batch_size=batch * workers)
    replay.extend(episodes)
    torch.manual_seed(0)
    weights = torch.stack([replay.sample()["priority_weight"].double().view(workers, batch)
                           for _ in range(batches)])  # [batches, workers, batch]: each worker's batch of its own
    spread = compare_draws.importance_weight_spread(sampler, batch, batches, seed=0)
    assert spread["is_mean"] < 0.95  # the weights differ: the checks below could fail
    assert spread["is_mean"] == pytest.approx(weights.mean().item(), abs=0.01)
    ess = weights.sum(-1).square() / (batch * weights.square().sum(-1))
    assert spread["is_ess"] == pytest.approx(ess.mean().item(), abs=0.01)


@pytest.mark.parametrize("arguments, refusal", [
    (["--temperatures", "0.01", "0"], "--temperatures: 0 is not a sigmoid temperature: each must be positive"),
    (["--temperatures", "0.01", "0.010"], "--temperatures: 0.01 0.01 names a temperature twice"),
    (["--summary", "summary.png"], "--summary draws the metrics against --temperatures: name at least one"),
])
def test_compare_draws_refuses_temperatures_it_cannot_draw(arguments, refusal, capsys):
    with pytest.raises(SystemExit) as exit:
        compare_draws.main(["runs/none", *arguments])
    assert exit.value.code == 2 and refusal in capsys.readouterr().err
