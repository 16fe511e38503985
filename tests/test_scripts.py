"""The scripts: the run queues read without training (PYTHON=echo prints each run's command), and the analyses on tiny real runs."""

import csv
import itertools
import math
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
import torch
from torchrl_cebp.training.config import compose_config
from hydra.core.hydra_config import HydraConfig
from tensordict import TensorDict

from tests.modules import load_module
from torchrl_cebp.training.config import validate_config

REPO = Path(__file__).resolve().parents[1]
# The experiments' own tooling, not the library: run with -m bookkeeping (.ci/run does).
pytestmark = pytest.mark.bookkeeping


def queued_runs(*overrides: str, only: str = "") -> list[list[str]]:
    out = subprocess.run(
        ["bash", "scripts/run_comparison.sh", *overrides], cwd=REPO, capture_output=True, text=True, check=True,
        env={**os.environ, "PYTHON": "echo", "JOBS": "2", "SKIP_COMMITTED": "0", "ONLY": only},
    )
    return [line.split()[1:] for line in out.stdout.splitlines() if line.startswith("train.py")]


def test_run_comparison_queues_one_valid_run_per_stage_and_seed():
    runs = queued_runs()
    assert sorted(queued_runs("epochs=1")) == sorted([*run, "epochs=1"] for run in runs)  # overrides reach every run
    assert all(sum(o.startswith("seed=") for o in run) == 1 for run in runs)
    # The shipped agents' runs carry a comparison run on past its horizon: they alone set their epochs.
    agents = [run for run in runs if any(o.startswith("epochs=") for o in run)]
    stage_runs = [run for run in runs if run not in agents]
    seeds = [next(o for o in run if o.startswith("seed=")) for run in stage_runs]
    stages = Counter(" ".join(o for o in run if not o.startswith("seed=")) for run in stage_runs)
    assert set(stages.values()) == {3} and Counter(seeds) == {f"seed={s}": len(stages) for s in range(3)}
    assert len(agents) == 2 and all("seed=0" in run for run in agents)
    folders, epochs = {}, {}
    for run in runs:
        cfg = compose_config(*run, return_hydra_config=True)
        validate_config(cfg)  # every stage and sampler exists, every value is allowed
        HydraConfig.instance().set_config(cfg)  # the folder's name reads hydra:runtime.choices
        folders[" ".join(run)], epochs[" ".join(run)] = cfg.hydra.run.dir, cfg.epochs
    stage_folders = [folders[" ".join(run)] for run in stage_runs]
    # A stage that differs from another by a sampler value alone must name its own folder, or it resumes the other's.
    assert len(set(stage_folders)) == len(stage_runs), Counter(stage_folders).most_common(1)
    for agent in agents:  # an agent resumes its comparison run's folder, and trains it longer
        extended = [run for run in stage_runs if folders[" ".join(run)] == folders[" ".join(agent)]]
        assert len(extended) == 1 and epochs[" ".join(agent)] > epochs[" ".join(extended[0])]


def test_run_comparison_only_queues_the_runs_matching_its_pattern():
    every_run = queued_runs()
    stage = queued_runs(only="pick_place_temperature")
    assert sorted(stage) == sorted(run for run in every_run if "+comparison=pick_place_temperature" in run)
    assert len(stage) == 18 and sum("sampler=her" in run for run in stage) == 3  # 5 temperatures and HER, 3 seeds
    assert queued_runs(only="no_such_stage") == []


def test_run_comparison_runs_nothing_once_every_run_is_committed(tmp_path):
    passes_none = tmp_path / "passes_none"  # stands for pending_runs.py when every run is committed
    passes_none.write_text("#!/bin/sh\ncat >/dev/null\n")
    passes_none.chmod(0o755)
    out = subprocess.run(
        ["bash", "scripts/run_comparison.sh"], cwd=REPO, capture_output=True, text=True, check=True,
        env={**os.environ, "PYTHON": "echo", "FILTER_PYTHON": str(passes_none), "SKIP_COMMITTED": "1"},
    )
    assert "train.py" not in out.stdout and "[comparison]" not in out.stdout


def test_pending_runs_skips_a_run_only_once_its_committed_csv_holds_all_its_epochs(tmp_path):
    stage = "+comparison=pick_place_standard sampler=her replay.per_worker=false"  # 20 epochs
    for seed, epochs in (0, 20), (1, 19):
        progress = tmp_path / "pick_place-standard" / "her" / "paper" / f"seed{seed}" / "progress.csv"
        progress.parent.mkdir(parents=True)
        progress.write_text("epoch,test_success\n" + "".join(f"{epoch},0.5\n" for epoch in range(epochs)))
    queue = "".join(f"{stage} seed={seed}\n" for seed in range(3))
    out = subprocess.run(
        [sys.executable, "scripts/pending_runs.py", "--committed", str(tmp_path)], cwd=REPO, input=queue,
        capture_output=True, text=True, check=True,
    )
    assert out.stdout.splitlines() == [f"{stage} seed=1", f"{stage} seed=2"]
    assert "skipped, 20 of 20 epochs committed: pick_place-standard/her/paper/seed0" in out.stderr


def test_pending_runs_plan_counts_resumable_or_all_committed_epochs_priced_by_nearest_relatives(tmp_path):
    stage = "+comparison=pick_place_standard sampler=her replay.per_worker=false"  # 20 epochs, in her/paper/
    committed, runs = tmp_path / "committed", tmp_path / "runs"
    for root, folder, epochs, seconds in (
        (committed, "her/paper/seed0", 20, 720),  # the configuration's own seed prices the others
        (committed, "cper/paper-per_worker/seed0", 20, 10),  # a farther relative, not used
        (runs, "her/paper/seed1", 5, 360),  # finished here, resumable; this machine is 2x faster
        (committed, "her/paper/seed1", 4, 360),  # its committed copy, which must not read as another machine's pace
        (committed, "her/paper/seed2", 7, 720),  # committed in part, not resumable here: restarts from epoch 0
    ):
        progress = root / "pick_place-standard" / folder / "progress.csv"
        progress.parent.mkdir(parents=True)
        progress.write_text("epoch,epoch_s\n" + "".join(f"{epoch},{seconds}\n" for epoch in range(epochs)))
    out = subprocess.run(
        [sys.executable, "scripts/pending_runs.py", "--plan", "--jobs", "2", "--committed", str(committed),
         "--runs", str(runs)], cwd=REPO, input="".join(f"{stage} seed={seed}\n" for seed in range(3)),
        capture_output=True, text=True, check=True,
    )
    lines = [" ".join(line.split()) for line in out.stdout.splitlines()]
    assert lines[:3] == [f"pick_place-standard/her/paper/seed{seed} {done} of 20 epochs done {20 - done} left"
                         for seed, done in ((0, 20), (1, 5), (2, 0))]
    assert lines[3].startswith("35 run-epochs left; about 1.8 hours at 2 run(s) at a time")  # 35 x 720 s / 2 / 2 runs
    assert "other machines' times 0.50, this machine's pace" in lines[3]


def test_machine_pace_compares_this_machines_runs_with_other_machines_relatives_only(tmp_path):
    pending_runs = _script("pending_runs")
    committed, runs = tmp_path / "committed", tmp_path / "runs"
    for root in committed, runs:  # a run of this machine and its committed copy, nothing else
        progress = root / "push-standard" / "her" / "paper" / "seed0" / "progress.csv"
        progress.parent.mkdir(parents=True)
        progress.write_text("epoch,epoch_s\n0,200\n")
    assert pending_runs.machine_pace(committed, runs, pending_runs.live_folders(runs)) is None  # not 1.0: the copy is no other machine's pace
    other = committed / "push-standard" / "her" / "paper" / "seed1" / "progress.csv"
    other.parent.mkdir(parents=True)
    other.write_text("epoch,epoch_s\n0,800\n")
    assert pending_runs.machine_pace(committed, runs, pending_runs.live_folders(runs)) == 0.25


def test_compare_draws_replays_a_runs_episodes_to_the_draw_the_run_itself_had(tmp_path):
    from tests.training.test_training import config
    from torchrl_cebp.training import train

    train(config("sampler=mep", "env=push", "cycles_per_epoch=3", "workers=2"), tmp_path)
    out = subprocess.run(
        [sys.executable, "scripts/compare_draws.py", str(tmp_path), "--samplers", "mep", "her", "--csv",
         str(tmp_path / "draws.csv"), "--out", str(tmp_path / "draws.png")], cwd=REPO, capture_output=True, text=True,
        check=True,
    )
    with (tmp_path / "draws.csv").open() as f:
        draws = {(row["sampler"], int(row["epoch"])): row for row in csv.DictReader(f)}
    with (tmp_path / "progress.csv").open() as f:
        run = list(csv.DictReader(f))
    for epoch, row in enumerate(run):
        # MEP's ranks hang on each refit's place in the epoch and on its fit's random stream: both as the run had them
        assert float(draws["mep", epoch]["ess"]) == pytest.approx(float(row["priority_ess_fraction"]), rel=1e-6)
        assert float(draws["her", epoch]["ess"]) == pytest.approx(1.0)
        assert draws["her", epoch]["top1% weighted"] == draws["her", epoch]["top1%"]  # HER weights nothing
        assert int(draws["her", epoch]["episodes"]) == (epoch + 1) * 3 * 2 * 2  # cycles x episodes x workers
    assert "mep" in out.stdout and "moved" in out.stdout and (tmp_path / "draws.png").stat().st_size > 10_000


def _script(name: str):
    return load_module(REPO / "scripts" / f"{name}.py")


def test_pending_runs_prices_a_run_by_ever_farther_relatives():
    pending_runs = _script("pending_runs")
    assert pending_runs.relatives(Path("push-standard/cebp_initial/paper-per_worker-beta0/seed0")) == [
        "push-standard/cebp_initial/paper-per_worker-beta0/*/progress.csv",
        "push-standard/cebp_initial/paper-per_worker*/*/progress.csv",
        "push-standard/cebp_initial/paper*/*/progress.csv",
        "push-standard/cebp_initial/*/*/progress.csv",
        "push-standard/**/progress.csv",
    ]


def test_compare_draws_reads_each_episodes_valid_steps_only():
    compare_draws = _script("compare_draws")
    steps = 4
    start = torch.tensor([1.3, 0.7, 0.42])
    achieved = start.expand(3, steps, 3).clone()
    next_achieved = achieved.clone()
    next_achieved[0, 2:, 0] += 0.02  # episode 0 pushes its object 2 cm
    next_achieved[2, 2:] = 0.0  # episode 2 ended after 2 steps: the rest is padding
    touch, reward, done = torch.zeros(3, steps, 2), -torch.ones(3, steps, 1), torch.zeros(3, steps, 1, dtype=torch.bool)
    touch[0, 1, 1] = 3.0
    reward[0, -1] = 0.0
    done[2, 1] = True
    touch[2, 3], reward[2, 2:] = 5.0, 0.0  # padding, not read
    episodes = TensorDict({"achieved_goal": achieved, "next": {"achieved_goal": next_achieved, "touch": touch,
                                                                "reward": reward, "done": done}}, [3, steps])
    features = compare_draws.episode_features(episodes, moved_m=0.01)
    assert {name: flags.tolist() for name, flags in features.items()} == {
        "moved": [True, False, False], "touched": [True, False, False], "reached": [True, False, False]}
    shares = compare_draws.draw_shares(torch.tensor([2.0, 1.0, 1.0]), features,
                                       sample_weight=torch.tensor([1.0, 1.0, 1.0]))
    assert shares == pytest.approx({"moved": 0.5, "touched": 0.5, "reached": 0.5, "top1%": 0.5,
                                    "moved weighted": 1 / 3, "top1% weighted": 1 / 3})


@pytest.mark.parametrize("batch", [2, 3])
def test_compare_draws_expects_each_batch_divided_by_its_largest_weight(batch):
    compare_draws = _script("compare_draws")
    p = torch.tensor([0.5, 0.2, 0.2, 0.1], dtype=torch.float64)
    w = torch.tensor([0.3, 0.6, 0.6, 1.0], dtype=torch.float64)  # a tie, as equal priorities give
    others = list(itertools.product(range(4), repeat=batch - 1))  # every draw of the batch's other members
    brute = [p[i] * sum(math.prod(p[j] for j in rest) * w[i] / max(w[[i, *rest]]) for rest in others)
             for i in range(4)]
    assert compare_draws.expected_batch_weights(p, w, batch).tolist() == pytest.approx([float(b) for b in brute])


def test_compare_draws_weighs_each_worker_over_its_own_episodes():
    from tests.replay.conftest import make_episodes, sparse_reward
    from torchrl_cebp.replay import HindsightRelabel, make_replay_buffer
    from torchrl_cebp.replay.samplers import InitialCEBPSampler, PerWorkerSampler

    compare_draws = _script("compare_draws")
    episodes = make_episodes(300)  # 300 in all, 150 a worker: under the 256 an InitialCEBPSampler weights from
    for sampler in (InitialCEBPSampler(), PerWorkerSampler(InitialCEBPSampler(), InitialCEBPSampler())):
        replay = make_replay_buffer(sampler, HindsightRelabel(sparse_reward), capacity=300 * episodes.shape[1])
        replay.extend(episodes)
        weight = compare_draws.critic_sample_weight(sampler, replay.storage, 300, batch=256)
        draw = sampler.probabilities(torch.arange(300)).double()
        weighs = isinstance(sampler, InitialCEBPSampler)
        assert torch.allclose(weight, draw / draw.sum()) != weighs, type(sampler).__name__


def test_compare_draws_names_the_samplers_it_can_compare():
    out = subprocess.run([sys.executable, "scripts/compare_draws.py", "runs/none", "--samplers", "per"], cwd=REPO,
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert "'per' is not a sampler config that draws by episode priority; choose from cebp, cebp_initial" in out.stderr


def test_the_sim2real_training_script_resumes_the_shipped_policys_run_with_its_shared_replay():
    out = subprocess.run(["bash", "scripts/run_sim2real_training.sh"], cwd=REPO, capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHON": "echo"})
    overrides = out.stdout.split()[1:]
    cfg = compose_config(*overrides)
    validate_config(cfg)
    assert cfg.replay.capacity_per == "total" and cfg.resume and cfg.workers == 8


def test_ship_agent_checks_the_runs_command_and_ships_only_at_the_tasks_bar(tiny_run, tmp_path, monkeypatch):
    from tests.tiny_run import TINY, TINY_RUN
    from torchrl_cebp.agents.shipped import SHIPPED_AGENTS
    from torchrl_cebp.evaluate import success_rate
    from torchrl_cebp.training import load_policy
    from torchrl_cebp.training.config import ConfigError

    ship = load_module(REPO / "scripts" / "ship_agent.py")
    policy = tiny_run / "best_policy.pt"
    with pytest.raises(FileNotFoundError, match=r"\.hydra/overrides\.yaml is missing: pass the run's train\.py overrides"):
        ship.run_overrides(tiny_run)  # trained from Python, not by train.py
    with pytest.raises(ValueError, match="was trained on 'push', not 'pick_place'"):
        ship.card_state("pick_place", policy, [*TINY, *TINY_RUN], 2)
    with pytest.raises(ConfigError, match="batch_size=16, this config has batch_size=256"):
        ship.card_state("push", policy, list(TINY_RUN), 2)  # a command that would not rebuild the run
    state = ship.card_state("push", policy, [*TINY, *TINY_RUN], 2)
    card = state["card"]
    assert card["command"] == "python train.py " + " ".join([*TINY, *TINY_RUN])
    assert card["epochs"] == 2 and card["sampler"] == "UniformEpisodeSampler, HER 'future'" and card["episodes"] == 2
    with pytest.raises(SystemExit, match=r"0\.500 is below the push bar of 0\.95: not shipped"):
        ship.ship("push", {**state, "card": {**card, "success": 0.5}}, force=False)
    assert card["suite_check"] == success_rate(policy, 10, 777)  # what tests/agents asks of a shipped agent
    with pytest.raises(SystemExit, match=r"0\.700 over the test suite's 10 episodes \(seed 777\) is below its 0\.8"):
        ship.ship("push", {**state, "card": {**card, "success": 0.96, "suite_check": 0.7}}, force=False)

    monkeypatch.setitem(SHIPPED_AGENTS, "push", tmp_path / "package" / "push.pt")
    monkeypatch.setattr(ship, "REPO", tmp_path)
    page = tmp_path / "agents.md"
    page.write_text(f"# Agents\n\n{ship.CARDS_START}\nold\n{ship.CARDS_END}\n\nmore\n")
    monkeypatch.setattr(ship, "AGENTS_PAGE", page)
    ship.ship("push", state, force=True)
    assert SHIPPED_AGENTS["push"].stat().st_size < 1_000_000 and load_policy(SHIPPED_AGENTS["push"]) is not None
    assert torch.load(SHIPPED_AGENTS["push"], weights_only=True)["card"] == card
    strip = iio_read(tmp_path / "docs" / "img" / "agent_push_frames.png")
    assert strip.shape == (180, 6 * 240, 3)
    assert len(iio_read(tmp_path / "docs" / "img" / "agent_push.mp4")) == 2 * 51
    text = page.read_text()
    assert "old" not in text and text.endswith(f"{ship.CARDS_END}\n\nmore\n")
    assert f"## push: success {card['success']:.2f} over 2 fresh episodes" in text


def iio_read(path: Path):
    import imageio.v3 as iio

    return iio.imread(path)


@pytest.mark.parametrize("script", sorted(path.name for path in (REPO / "scripts").glob("*.sh")))
def test_every_shell_script_explains_itself_on_help_and_changes_nothing(script):
    status = subprocess.run(["git", "status", "--porcelain"], cwd=REPO, capture_output=True, text=True).stdout
    out = subprocess.run(["bash", f"scripts/{script}", "--help"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and len(out.stdout.split()) >= 8, (out.stdout, out.stderr)
    assert subprocess.run(["git", "status", "--porcelain"], cwd=REPO, capture_output=True, text=True).stdout == status


@pytest.mark.parametrize(
    "argv, message",
    [
        (["setup.sh", "tests"], r"unknown extra 'tests'; pyproject.toml has: test bench real loggers slurm docs"),
        (["sync_results.sh", "--every"], "--every needs a number of seconds, got ''"),
        (["sync_results.sh", "--dry-run"], "unknown option --dry-run: the only option is --every SECONDS"),
    ],
)
def test_a_shell_script_refuses_an_unknown_argument_before_it_acts(argv, message):
    out = subprocess.run(["bash", f"scripts/{argv[0]}", *argv[1:]], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and message in out.stderr
