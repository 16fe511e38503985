import math
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf
from tensordict import TensorDict

from tests.tiny_run import REPO, TINY, TINY_RUN, config, copy_run, rows
from torchrl_cebp.replay import HindsightRelabel
from torchrl_cebp.training import ConfigError, load_checkpoint, load_policy, train, validate_config
from torchrl_cebp.replay.samplers import PerWorkerSampler
from torchrl_cebp.training.config import CONFIG_DIR, check_same_run, env_label, warn_if_bf16_is_emulated
from torchrl_cebp.training.builders import (
    TaskDims, derive_seed, episode_steps, make_agent, make_env, make_replay, make_sampler, make_training_collector,
    replay_capacity, worker_share,
)
from torchrl_cebp.training.checkpoint import BEST_POLICY_NAME, BestPolicy, stored_episodes, CHECKPOINT_NAME, POLICY_NAME
from torchrl_cebp.training.evaluation import evaluate_success_rate
from torchrl_cebp.training.metrics import RUN_SOURCES
from torchrl_cebp.training.trainer import TEST_STREAM, Learner, RelabelledTransitions

SAMPLERS = ["her", "per", "ebp", "mep", "cper", "cebp", "cebp_released", "cebp_initial"]


@pytest.mark.parametrize("sampler", ["per", "mep", "cebp"])
def test_tiny_run_writes_csv_and_checkpoint(tmp_path, sampler):
    csv_path = train(config(f"sampler={sampler}", "env=pick_place"), tmp_path)
    log = rows(csv_path)
    assert [row["epoch"] for row in log] == ["0", "1"]
    assert {"test_success", "loss_actor", "loss_value", "env_steps_per_s", "wall_s"} <= set(log[0])
    state = load_checkpoint(tmp_path)  # weights_only=True: no pickled code inside
    assert state["epoch"] == 1
    assert {"format", "loss", "normalizer", "optimizer", "replay", "rng"} <= set(state)
    # the row's success is the checkpointed policy's, on the epoch's test seeds
    cfg = config(f"sampler={sampler}", "env=pick_place")
    test_env = make_env(cfg, cfg.rollouts_per_cycle)
    test_env.set_seed(derive_seed(cfg.seed, 1, TEST_STREAM))
    assert float(log[-1]["test_success"]) == evaluate_success_rate(test_env, load_policy(tmp_path), cfg.test_episodes)


def test_mep_refits_once_an_epoch_before_the_last_cycles_episodes_are_stored(tmp_path, monkeypatch):
    # As the paper's code: fit_density_model() at cycle n_cycles - 1, before that cycle's store_episode().
    calls = []
    for name in ("store", "refit_sampler"):
        method = getattr(Learner, name)
        monkeypatch.setattr(Learner, name, lambda self, *args, _m=method, _n=name: (calls.append(_n), _m(self, *args))[1])
    train(config("sampler=mep", "env=push", "epochs=2", "cycles_per_epoch=3"), tmp_path)
    assert calls == ["store", "store", "refit_sampler", "store"] * 2
    sampler = load_checkpoint(tmp_path)["replay"]["_sampler"]
    assert sampler["n_refits"] == 2


@pytest.mark.parametrize("workers", [1, 2])
def test_per_training_feeds_td_errors_back_on_merged_and_per_worker_replay(tmp_path, workers):
    # Per-worker PER once drew uniformly for ever: TorchRL's update_tensordict_priority skips a PerWorkerSampler.
    train(config("sampler=per", "env=push", f"workers={workers}", "epochs=1"), tmp_path)
    sampler = load_checkpoint(tmp_path)["replay"]["_sampler"]
    shards = sampler["shards"] if workers > 1 else [sampler]
    assert all(float(shard["max_priority"]) != 1.0 for shard in shards)  # 1.0: the untouched default
    assert float(rows(tmp_path / "progress.csv")[0]["is_weight_min"]) < 1.0


def test_best_policy_is_the_last_epoch_with_the_highest_success_across_a_resume(tiny_run, tmp_path):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    train(config(*TINY_RUN, "epochs=4", "resume=true"), run_dir)
    successes = [float(row["test_success"]) for row in rows(run_dir / "progress.csv")]
    best = torch.load(run_dir / BEST_POLICY_NAME, weights_only=True)
    assert best["test_success"] == pytest.approx(max(successes))
    assert best["epoch"] == max(epoch for epoch, success in enumerate(successes) if success == max(successes))


def test_best_policy_keeps_its_record_across_a_resume_and_ties_replace_it(tmp_path):
    def policy(epoch: int, success: float) -> dict:
        return {"format": "torchrl_cebp.policy/1", "epoch": epoch, "test_success": success}

    assert BestPolicy(tmp_path).offer(policy(0, 0.5))
    resumed = BestPolicy(tmp_path, resume=True)
    assert not resumed.offer(policy(1, 0.4)) and not resumed.offer(policy(2, float("nan")))
    assert resumed.offer(policy(3, 0.5))  # a tie: the later policy has trained longer
    assert torch.load(tmp_path / BEST_POLICY_NAME, weights_only=True)["epoch"] == 3
    fresh = BestPolicy(tmp_path)  # a new run in the same folder: the old record is not its own
    assert fresh.offer(policy(0, 0.1))


def test_stored_episodes_are_the_checkpointed_buffers_whole_episodes(tiny_run):
    episodes, overwritten = stored_episodes(load_checkpoint(tiny_run))
    assert overwritten == 0 and episodes.shape == (int(rows(tiny_run / "progress.csv")[-1]["stored_episodes"]), 50)
    # each row is one whole episode: it starts where the env reset it and its last step is the truncation
    assert episodes["next", "truncated"][:, -1].all() and not episodes["next", "truncated"][:, :-1].any()
    torch.testing.assert_close(episodes["next", "observation"][:, :-1], episodes["observation"][:, 1:])


def test_stored_episodes_of_a_wrapped_buffer_are_oldest_first(tmp_path):
    # 3 epochs of 2 cycles x 2 episodes: 12 episodes written into room for 8 (400 transitions of 50 steps)
    train(config("sampler=her", "env=push", "epochs=3", "replay.capacity=400"), tmp_path)
    episodes, overwritten = stored_episodes(load_checkpoint(tmp_path))
    assert (len(episodes), overwritten) == (8, 4)
    # the row each episode was written to: episodes 9-12 overwrote rows 0-3, so the oldest kept is row 4's
    assert episodes["index"][:, 0].tolist() == [4, 5, 6, 7, 0, 1, 2, 3]


def test_policy_file_is_small_and_acts_as_the_checkpoint(tmp_path):
    train(config("sampler=her", "env=pick_place", "epochs=1", "agent.hidden=[256,256,256]"), tmp_path)
    policy_file = tmp_path / POLICY_NAME
    assert policy_file.stat().st_size < 1_000_000  # the paper's 3x256 actor and the normaliser, no replay
    state = torch.load(policy_file, weights_only=True)
    assert set(state) == {"format", "env", "hidden", "actor", "normalizer", "epoch", "test_success"}
    assert state["env"]["task"] == "pick_place" and state["epoch"] == 0
    observations = TensorDict(observation=torch.randn(8, 25), desired_goal=torch.randn(8, 3), batch_size=[8])
    from_file, from_checkpoint = load_policy(policy_file), load_policy(tmp_path / CHECKPOINT_NAME)
    actions = from_file(observations.clone())["action"]
    torch.testing.assert_close(actions, from_checkpoint(observations.clone())["action"], rtol=0, atol=0)
    assert not torch.allclose(actions, actions[:1])  # a trained, input-dependent actor, not a constant


LEARNING_COLUMNS = ("test_success", "loss_actor", "loss_value", "q_mean", "is_weight_mean", "priority_ess_fraction")


# The overlapping variants wait on an env process each run starts (minutes on a loaded 2-core machine): slow set.
@pytest.mark.parametrize(("overlap", "threads"), [
    ("false", 1), pytest.param("true", 1, marks=pytest.mark.slow), pytest.param("true", 2, marks=pytest.mark.slow),
])
def test_resume_repeats_the_uninterrupted_run(tmp_path, overlap, threads):
    # CEBP: the sampler's priorities and the IS weights must come back too; with overlap, the
    # env process's env and exploration streams too, whatever threads the updates switch between
    run = ("sampler=cebp", f"overlap_collection={overlap}", f"threads={threads}")
    straight = rows(train(config(*run), tmp_path / "straight"))
    train(config(*run, "epochs=1"), tmp_path / "split")
    resumed = rows(train(config(*run, "resume=true"), tmp_path / "split"))
    assert [row["epoch"] for row in resumed] == ["0", "1"]
    for key in LEARNING_COLUMNS:
        assert [r[key] for r in resumed] == [r[key] for r in straight]
    assert load_checkpoint(tmp_path / "split")["epoch"] == 1


@pytest.mark.parametrize(("overlap", "sampler", "workers"), [
    ("false", "cebp", 1),
    pytest.param("true", "cebp", 1, marks=pytest.mark.slow),
    pytest.param("false", "per", 2, marks=pytest.mark.slow),
])
def test_kill_9_mid_epoch_then_resume_repeats_the_uninterrupted_run(tmp_path, overlap, sampler, workers):
    # workers=2: per-worker replay, every worker's PER trees and the annealed beta must come back
    run = (f"sampler={sampler}", f"overlap_collection={overlap}", f"workers={workers}", "epochs=3", "cycles_per_epoch=6")
    straight = rows(train(config(*run), tmp_path / "straight"))
    killed = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, "train.py", *TINY, *run, f"hydra.run.dir={killed}"], cwd=REPO,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    while not (killed / CHECKPOINT_NAME).exists() and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)
    time.sleep(0.3)  # into epoch 1
    process.kill()
    process.wait()
    assert load_checkpoint(killed)["epoch"] < 2, "the run ended before it could be killed mid-run"
    resumed = _cli(*TINY, *run, "resume=true", f"hydra.run.dir={killed}")
    assert resumed.returncode == 0, resumed.stderr
    for key in set(LEARNING_COLUMNS) & set(straight[0]):
        assert [r[key] for r in rows(killed / "progress.csv")] == [r[key] for r in straight]


def test_a_quick_runs_checkpoint_holds_only_its_episodes_and_restores_the_replay_exactly(tmp_path):
    cfg = config("preset=quick", "epochs=1", "cycles_per_epoch=4")  # the quick preset's replay: 1e6 transitions
    train(cfg, tmp_path)
    size_mb = (tmp_path / CHECKPOINT_NAME).stat().st_size / 2**20
    assert size_mb < 20, f"{size_mb:.0f} MB"
    state = load_checkpoint(tmp_path)
    replays = [make_replay(cfg, instantiate(cfg.sampler), make_env(cfg))[0] for _ in range(2)]
    replays[0].load_state_dict(state["replay"])
    replays[1].load_state_dict(state["replay"])
    assert replays[0].storage.max_size == cfg.replay.capacity and len(replays[0]) == 4 * 2 * 50
    for _ in range(3):
        assert (replays[0].sample() == replays[1].sample()).all()


def test_a_checkpoint_of_the_rollout_worker_trainer_is_refused_with_a_way_out(tiny_run, tmp_path):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    state = load_checkpoint(run_dir)
    del state["format"]
    torch.save(state, run_dir / CHECKPOINT_NAME)
    with pytest.raises(ConfigError, match="format 1.*code_commit"):
        train(config(*TINY_RUN, "resume=true"), run_dir)


def test_two_env_processes_collect_and_train(tmp_path):
    log = rows(train(config("collector_processes=2", "rollouts_per_cycle=4"), tmp_path))
    assert [row["epoch"] for row in log] == ["0", "1"]
    assert int(log[-1]["stored_episodes"]) == 2 * 2 * 4


def test_bf16_precision_trains_with_bfloat16_products(tmp_path):
    fp32 = rows(train(config("epochs=1"), tmp_path / "fp32"))[0]
    bf16 = rows(train(config("epochs=1", "precision=bf16"), tmp_path / "bf16"))[0]
    for key in ("loss_actor", "loss_value", "q_mean"):
        assert math.isfinite(float(bf16[key]))
        # same seed, same data until the first update: only the rounding of the products differs
        assert float(bf16[key]) != float(fp32[key])
        assert float(bf16[key]) == pytest.approx(float(fp32[key]), rel=0.1, abs=0.05)


def test_bf16_on_a_cpu_without_bfloat16_instructions_warns(monkeypatch):
    monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda: False)
    monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda: False)
    with pytest.warns(UserWarning, match="precision=bf16: this CPU has neither AVX512-BF16 nor AMX"):
        warn_if_bf16_is_emulated("bf16", torch.device("cpu"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_if_bf16_is_emulated("fp32", torch.device("cpu"))


def test_background_batch_is_busy_until_its_episodes_are_ready():
    cfg = config("overlap_collection=true")
    agent = make_agent(cfg, TaskDims(25, 3, 4, 50))
    batches = make_training_collector(cfg, agent, TaskDims(25, 3, 4, 50))
    try:
        assert not batches.busy()
        batches.request(seed=0, background=True)
        assert batches.busy()  # two 50-step episodes take far longer than this line
        deadline = time.monotonic() + 60
        while batches.busy() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not batches.busy()
        assert batches.result().shape == (cfg.rollouts_per_cycle, 50)
    finally:
        batches.close()


def test_refuses_to_overwrite_a_checkpoint_or_resume_another_run(tiny_run, tmp_path):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    with pytest.raises(ConfigError, match="resume=true"):
        train(config(*TINY_RUN), run_dir)
    with pytest.raises(ConfigError, match=r"made with sampler\._target_=.*UniformEpisodeSampler', this config has sampler\._target_=.*CPERSampler'"):
        train(config("env=push", "sampler=cper", "resume=true"), run_dir)


@pytest.mark.parametrize("env", ["push_released", "pick_place_released", "slide_released"])
def test_released_robot_trains_and_names_its_run_folder(tmp_path, env):
    cfg = config(f"env={env}", "sampler=cebp_released", "epochs=1")
    assert (cfg.env.goal_space, cfg.env.control, cfg.env.touch_ignores_table) == ("extended", "joint", True)
    log = rows(train(cfg, tmp_path))
    assert len(log) == 1 and log[0]["code_commit"]
    policy = load_policy(tmp_path)
    env_obs = 25 + 2 * cfg.env.touch_in_observation
    td = TensorDict(observation=torch.zeros(env_obs), desired_goal=torch.zeros(3))
    assert policy(td)["action"].shape == (8 if env == "pick_place_released" else 7,)
    touch = "-touchobs" if cfg.env.touch_in_observation else ""
    assert env_label(cfg.env) == f"{cfg.env.task}-extended-joint-tableblind{touch}"
    assert "runs/${env_label:${env}}/" in (CONFIG_DIR / "config.yaml").read_text()


def test_capacity_below_one_cycle_and_bad_cebp_parameters_are_named_before_any_env_starts(tmp_path):
    with pytest.raises(ConfigError, match=r"replay.capacity=700: smaller than one cycle's .* at least 800 transitions"):
        train(config("preset=paper", "replay.capacity=700", "replay.capacity_per=total"), tmp_path / "capacity")
    with pytest.raises(ConfigError, match=r"replay.capacity=99: smaller than a worker's .* at least 100 transitions"):
        train(config("preset=paper", "replay.capacity=99"), tmp_path / "capacity")  # 2 episodes of 50 steps each
    with pytest.raises(ConfigError, match=r"replay.capacity_per='shard': must be one of \['worker', 'total'\]"):
        train(config("replay.capacity_per=shard"), tmp_path / "capacity")
    with pytest.raises(Exception, match=r"temperature=-1.0: allowed values lie in \(0.0, inf\)"):
        train(config("sampler=cebp", "sampler.temperature=-1.0"), tmp_path / "temperature")
    with pytest.raises(Exception, match=r"scale=0.0: allowed values lie in \(0.0, inf\)"):
        train(config("sampler=cebp", "sampler.scale=0.0"), tmp_path / "scale")
    assert not any(tmp_path.rglob("progress.csv"))


def test_wrong_control_is_listed_with_what_is_allowed():
    with pytest.raises(ConfigError, match=r"env.control='cartesian': must be one of \['mocap', 'joint'\]"):
        validate_config(config("env.control=cartesian"))
    with pytest.raises(ConfigError, match="env.control='joint': the Franka task has the mocap robot"):
        validate_config(config("env=franka_pick_place", "env.control=joint"))
    with pytest.raises(ConfigError, match="env.touch_ignores_table=True: the Franka task has the mocap robot"):
        validate_config(config("env=franka_pick_place", "env.touch_ignores_table=true"))


# Each task's sampler values, written out: the paper's CEBP temperature T (0.01 on PickAndPlace and Push, 5 on
# Slide), EBP's energy clip (only PickAndPlace clips), the released code's CEBP slope k and gripper box.
INF = math.inf
TASK_SAMPLER_VALUES = {
    "pick_place": {"clip_energy": 0.5, "temperature": 0.01, "k": 0.1, "workspace": ((1.05, 0.4, 0.419), (1.55, 1.1, INF))},
    "push": {"clip_energy": 999.0, "temperature": 0.01, "k": 0.1, "workspace": ((1.05, 0.4, 0.4), (1.55, 1.11, INF))},
    "slide": {"clip_energy": 999.0, "temperature": 5.0, "k": 0.05, "workspace": ((0.7, 0.3, 0.4), (1.95, 1.2, INF))},
}


def expected_sampler(sampler: str, env: str) -> tuple[str, dict]:
    """The class a sampler config builds on a task, and the values it must hold."""
    task = TASK_SAMPLER_VALUES[env]
    return {
        "her": ("UniformEpisodeSampler", {}),
        # TINY: capacity 5000; beta anneals over epochs x cycles x updates = 2 x 2 x 3 draws
        "per": ("PERSampler", {"alpha": 0.6, "beta": 0.4, "beta_end": 1.0, "beta_anneal_draws": 12, "_max_capacity": 5000}),
        "ebp": ("EBPSampler", {"clip_energy": task["clip_energy"], "temperature": 1.0}),
        "mep": ("MEPSampler", {"n_components": 3, "temperature": 1.0, "seed": 0}),
        "cper": ("CPERSampler", {"threshold": 1.0, "lam": 10.0}),
        "cebp": ("CEBPSampler", {"scale": 100.0, "temperature": task["temperature"], "beta": 1.0, "workspace": None}),
        "cebp_released": ("ReleasedCEBPSampler", {"k": task["k"], "workspace": task["workspace"]}),
        "cebp_initial": ("InitialCEBPSampler", {"beta": 0.7, "workspace": task["workspace"]}),
    }[sampler]


@pytest.mark.parametrize("sampler", SAMPLERS)
@pytest.mark.parametrize("env", ["pick_place", "push", "slide"])
def test_every_sampler_config_builds_its_sampler_with_the_tasks_values(sampler, env):
    built = instantiate(config(f"sampler={sampler}", f"env={env}").sampler)
    name, values = expected_sampler(sampler, env)
    assert type(built).__name__ == name
    assert {key: getattr(built, key) for key in values} == values


def test_per_anneals_over_the_run_or_over_the_papers_50_epochs_in_a_comparison():
    assert config("sampler=per").sampler.beta_anneal_draws == 2 * 2 * 3  # TINY's epochs x cycles x updates
    truncated = config("+comparison=push_standard", "sampler=per")  # its runs are the first of the paper's 50 epochs
    assert (truncated.epochs, truncated.sampler.beta_anneal_draws) == (2, 50 * 2 * 3)
    with pytest.raises(ConfigError, match="schedule_epochs=0: must be a positive integer"):
        validate_config(config("schedule_epochs=0"))


def test_bad_values_are_listed_with_what_is_allowed():
    with pytest.raises(ConfigError) as err:
        validate_config(config("device=tpu", "epochs=0", "replay.future_p=1.5", "env.goal_space=huge",
                               "precision=fp16"))
    message = str(err.value)
    assert "device='tpu': must be one of ['auto', 'cpu', 'cuda']" in message
    assert "epochs=0: must be a positive integer" in message
    assert "replay.future_p=1.5: must be a number in [0.0, 1.0]" in message
    assert "env.goal_space='huge': must be one of ['standard', 'extended']" in message
    assert "precision='fp16': must be one of ['fp32', 'bf16']" in message


def test_collector_processes_must_split_a_cycle_evenly():
    with pytest.raises(ConfigError, match=r"collector_processes=3: must divide the 2 episodes of a cycle"):
        validate_config(config("collector_processes=3"))
    with pytest.raises(ConfigError, match=r"collector_processes=-1: must be a non-negative integer"):
        validate_config(config("collector_processes=-1"))


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "train.py", *args], cwd=REPO, capture_output=True, text=True, timeout=300
    )


def _tiny_stage(stage: str, sweep_dir: Path, *overrides: str) -> subprocess.CompletedProcess:
    # One worker and the tiny schedule instead of the paper's scale; in this process, one run after another.
    return _cli("-m", f"+comparison={stage}", *TINY, "workers=1", "seed=0", "hydra/launcher=basic",
                f"hydra.sweep.dir={sweep_dir}", *overrides)


@pytest.mark.bookkeeping
def test_comparison_stage_continues_where_it_stopped(tmp_path):
    first = _tiny_stage("push", tmp_path, "sampler=her,cebp", "epochs=1")
    assert first.returncode == 0, first.stderr
    her, cebp = (tmp_path / f"push-extended/{name}/paper/seed0/progress.csv" for name in ("her", "cebp"))
    first_epoch = rows(her)
    assert [row["epoch"] for row in first_epoch] == ["0"] and [row["epoch"] for row in rows(cebp)] == ["0"]
    again = _tiny_stage("push", tmp_path, "sampler=her,cebp", "epochs=2")  # the stage's resume=true
    assert again.returncode == 0, again.stderr
    assert [row["epoch"] for row in rows(her)] == ["0", "1"]
    assert rows(her)[0] == first_epoch[0]  # the finished epoch was not redone


@pytest.mark.bookkeeping
def test_per_worker_and_merged_runs_get_their_own_folders(tmp_path):
    result = _cli("-m", "+comparison=push_standard", *TINY, "epochs=1", "workers=2", "seed=0", "sampler=her",
                  "replay.per_worker=true,false", "hydra/launcher=basic", f"hydra.sweep.dir={tmp_path}")
    assert result.returncode == 0, result.stderr
    for folder, layout in (("paper-per_worker", "per_worker"), ("paper", "merged")):
        assert rows(tmp_path / f"push-standard/her/{folder}/seed0/progress.csv")[0]["replay"] == layout


@pytest.mark.bookkeeping
def test_temperature_stage_gives_each_temperature_its_own_runs(tmp_path):
    result = _tiny_stage("push_temperature", tmp_path, "sampler.temperature=0.1,1.0")
    assert result.returncode == 0, result.stderr
    for temperature in ("0.1", "1.0"):
        assert load_checkpoint(tmp_path / f"push-standard-temperature/cebp_T{temperature}/paper/seed0")["epoch"] == 1


def test_cli_rejects_a_bad_value_at_start(tmp_path):
    result = _cli("workers=-2", f"hydra.run.dir={tmp_path}")
    assert result.returncode != 0
    assert "workers=-2: must be a positive integer" in result.stderr and "Traceback" not in result.stderr


def test_cli_lists_the_sampler_choices(tmp_path):
    result = _cli("sampler=nope", f"hydra.run.dir={tmp_path}")
    assert result.returncode != 0
    assert "cebp_released" in result.stderr and "mep" in result.stderr


def test_normaliser_sees_goals_achieved_later_in_the_episode():
    n, T = 3, 5
    achieved = torch.arange(n * T, dtype=torch.float32).reshape(n, T, 1).expand(n, T, 3)
    episodes = TensorDict(
        {
            "observation": torch.zeros(n, T, 25),
            "desired_goal": torch.full((n, T, 3), -1.0),
            "next": {"achieved_goal": achieved.clone(), "desired_goal": torch.full((n, T, 3), -1.0)},
        },
        [n, T],
    )
    reward = lambda ag, g: torch.zeros(*ag.shape[:-1], 1)  # noqa: E731
    feed = RelabelledTransitions(HindsightRelabel(reward, future_p=1.0))
    goals = feed(episodes)["desired_goal"][:, 0].reshape(n, T)
    step_ids = torch.arange(n * T, dtype=torch.float32).reshape(n, T)
    # goal of (e, t) is the achieved goal of a later next-state of the same episode
    assert (goals >= step_ids).all() and (goals < (torch.arange(n) + 1).unsqueeze(1) * T).all()


def test_tensorboard_logger_gets_every_csv_column(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    train(config("sampler=cebp", "env=push", "epochs=1", "logger=tensorboard"), tmp_path)
    events = next((tmp_path / "logs").rglob("events.out.tfevents.*"))
    scalars = EventAccumulator(str(events.parent)).Reload().Tags()["scalars"]
    assert {"test_success", "loss_value", "is_weight_mean", "env_steps_per_s"} <= set(scalars)


def test_unknown_logger_is_refused_with_the_valid_ones():
    with pytest.raises(ConfigError, match="logger='tb'.*tensorboard"):
        validate_config(config("logger=tb"))


def test_every_row_names_the_commit_and_the_cpu_kernels_it_ran_on(tmp_path):
    if subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True).returncode != 0:
        pytest.skip("not a git checkout")
    log = rows(train(config("epochs=1"), tmp_path))
    commit = log[0]["code_commit"].removesuffix("+dirty")

    def git(*args: str) -> int:
        return subprocess.run(["git", *args], cwd=REPO, capture_output=True).returncode

    # The commit is read once per process, so results syncs may have moved HEAD since; never the run's code.
    assert git("merge-base", "--is-ancestor", commit, "HEAD") == 0, commit
    assert git("diff", "--quiet", commit, "HEAD", "--", *RUN_SOURCES) == 0, f"the run's code changed since {commit}"
    assert float(log[0]["load_avg"]) >= 0.0
    assert log[0]["cpu_capability"] == torch.backends.cpu.get_cpu_capability()


def test_per_resumes_its_beta(tmp_path):
    per = ("sampler=per", "sampler.beta_anneal_draws=12")  # the 2-epoch run's horizon, for the split run too
    straight = rows(train(config(*per), tmp_path / "straight"))
    train(config(*per, "epochs=1"), tmp_path / "split")
    resumed = rows(train(config(*per, "resume=true"), tmp_path / "split"))
    for key in ("loss_value", "is_weight_mean", "is_weight_min"):
        assert [r[key] for r in resumed] == [r[key] for r in straight]


def git_checkout(root):
    def git(*args):
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, check=True).stdout.strip()

    (root / "torchrl_cebp").mkdir(parents=True)
    (root / "torchrl_cebp" / "core.py").write_text("x = 1\n")
    (root / "README.md").write_text("notes\n")
    git("init", "-q")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "first")
    return git


def test_code_version_is_the_commit_the_process_loaded(tmp_path):
    from torchrl_cebp.training.metrics import code_version

    git = git_checkout(tmp_path)
    first = git("rev-parse", "--short=12", "HEAD")
    assert code_version(tmp_path) == first
    (tmp_path / "torchrl_cebp" / "core.py").write_text("x = 2\n")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qam", "second")  # HEAD moves mid-sweep
    assert code_version(tmp_path) == first


def test_code_version_is_dirty_only_when_the_code_a_run_executes_changed(tmp_path):
    from torchrl_cebp.training.metrics import code_version

    read_now = code_version.__wrapped__  # past the once-per-process cache
    git = git_checkout(tmp_path)
    commit = git("rev-parse", "--short=12", "HEAD")
    (tmp_path / "README.md").write_text("results of the epoch that just finished\n")
    assert read_now(tmp_path) == commit
    (tmp_path / "torchrl_cebp" / "core.py").write_text("x = 2\n")
    assert read_now(tmp_path) == f"{commit}+dirty"


@pytest.mark.parametrize(("workers", "per_worker", "layout"), [(2, "true", "per_worker"), (2, "false", "merged"),
                                                                (1, "true", "single")])
def test_every_row_names_the_replay_layout_that_ran(tmp_path, workers, per_worker, layout):
    cfg = config("sampler=cebp_initial", "epochs=1", f"workers={workers}", f"replay.per_worker={per_worker}")
    log = rows(train(cfg, tmp_path))
    assert log[0]["replay"] == layout and log[0]["her_strategy"] == "future"
    sampler = make_sampler(cfg)
    assert isinstance(sampler, PerWorkerSampler) == (layout == "per_worker")
    if layout == "per_worker":
        assert [shard.n_episodes for shard in sampler.samplers] == [0, 0]


def test_a_checkpoint_from_before_capacity_per_resumes_with_the_shared_capacity_it_had():
    saved = OmegaConf.to_container(config("preset=paper"), resolve=True)
    del saved["replay"]["capacity_per"]
    check_same_run(saved, config("preset=paper", "replay.capacity_per=total"))
    with pytest.raises(ConfigError, match=r"made with replay.capacity_per='total', this config has "
                                          r"replay.capacity_per='worker' \(to resume .* add the override "
                                          r"replay.capacity_per=total; runs made before"):
        check_same_run(saved, config("preset=paper"))
    one_worker = OmegaConf.to_container(config(), resolve=True)
    del one_worker["replay"]["capacity_per"]
    check_same_run(one_worker, config())  # one worker's capacity is the total: nothing to refuse
    check_same_run(OmegaConf.to_container(config("replay.capacity_per=total"), resolve=True), config())
    new = OmegaConf.to_container(config("preset=paper"), resolve=True)
    with pytest.raises(ConfigError, match=r"made with replay.capacity_per='worker', .* add the override "
                                          r"replay.capacity_per=worker;"):
        check_same_run(new, config("+comparison=push_standard"))


@pytest.mark.parametrize("comparison", sorted(path.stem for path in (CONFIG_DIR / "comparison").glob("*.yaml")))
def test_the_comparisons_keep_the_shared_capacity_their_runs_began_with(comparison):
    # Slide's 50-epoch stage has no runs yet, and would fill a worker's 1/8 from epoch 25.
    expected = "worker" if comparison == "slide" else "total"
    assert config(f"+comparison={comparison}").replay.capacity_per == expected
    assert config("preset=paper").replay.capacity_per == "worker"


def test_a_checkpoint_from_before_per_worker_replay_resumes_only_as_merged():
    saved = {key: value for key, value in OmegaConf.to_container(config("workers=2"), resolve=True).items()}
    del saved["replay"]["per_worker"]
    check_same_run(saved, config("workers=2", "replay.per_worker=false"))
    with pytest.raises(ConfigError, match="made with replay.per_worker=False, this config has replay.per_worker=True"):
        check_same_run(saved, config("workers=2"))


@pytest.mark.parametrize("key, legacy, override", [
    ("episode_steps", "None", "50"),  # before env.episode_steps: the task's own length
    ("grasped_start", "0.0", "0.5"),  # before env.grasped_start: every episode from the table
])
def test_a_checkpoint_from_before_an_env_option_resumes_as_that_run_did(key, legacy, override):
    saved = OmegaConf.to_container(config("env=franka_pick_place"), resolve=True)
    del saved["env"][key]
    check_same_run(saved, config("env=franka_pick_place"))
    with pytest.raises(ConfigError, match=f"made with env.{key}={legacy}, this config has env.{key}={override}"):
        check_same_run(saved, config("env=franka_pick_place", f"env.{key}={override}"))


def test_a_refused_resume_names_each_differing_setting_and_how_to_extend_a_per_run(tmp_path):
    train(config("sampler=per", "env=push", "epochs=1"), tmp_path)
    extended = ["sampler=per", "env=push", "epochs=2", "resume=true"]
    with pytest.raises(ConfigError) as err:
        train(config(*extended, "agent.hidden=[32,16]"), tmp_path)
    assert str(err.value).startswith(
        "cannot resume: the checkpoint was made with sampler.beta_anneal_draws=6, this config has "
        "sampler.beta_anneal_draws=12 (PER anneals beta")
    assert "add the override sampler.beta_anneal_draws=6)" in str(err.value)
    assert str(err.value).endswith("the checkpoint was made with agent.hidden=[32, 32], this config has "
                                   "agent.hidden=[32, 16]")
    train(config(*extended, "sampler.beta_anneal_draws=6"), tmp_path)  # the hint's override resumes the run
    assert [row["epoch"] for row in rows(tmp_path / "progress.csv")] == ["0", "1"]


def test_grasped_start_is_checked_and_names_the_run_folder():
    franka = config("env=franka_pick_place", "env.episode_steps=50", "env.grasped_start=0.5")
    validate_config(franka)
    assert env_label(franka.env) == "franka_pick_place-standard-T50-grasped50"
    assert env_label(config("env=franka_pick_place").env) == "franka_pick_place-standard"
    with pytest.raises(ConfigError, match=r"env.grasped_start=1.5: must be a number in \[0.0, 1.0\]"):
        validate_config(config("env=franka_pick_place", "env.grasped_start=1.5"))
    with pytest.raises(ConfigError, match="env.grasped_start=0.5: only env=franka_pick_place has grasped starts"):
        validate_config(config("env=push", "env.grasped_start=0.5"))


def test_only_the_training_collector_starts_episodes_grasped():
    cfg = config("env=franka_pick_place", "env.episode_steps=10", "env.grasped_start=1.0", "rollouts_per_cycle=2")
    dims = TaskDims(25, 3, 4, 10)
    batches = make_training_collector(cfg, make_agent(cfg, dims), dims)
    try:
        batches.request(seed=0)
        episodes = batches.result()
    finally:
        batches.close()
    assert (episodes["touch"][:, 0] > 0).all()  # both pads on the cube from the first step
    test_env = make_env(cfg, 2)
    assert (test_env.reset()["touch"] == 0).all()
    test_env.close()


def test_episode_steps_give_slide_and_the_franka_their_own_length_and_folder():
    cfg = config("+comparison=slide_standard")
    assert cfg.env.episode_steps == 70 and env_label(cfg.env) == "slide-standard-T70"
    assert episode_steps(cfg) == 70 and episode_steps(config("env=slide")) == 50
    with pytest.raises(ConfigError, match="env.episode_steps=1: must be null or an integer above 1"):
        validate_config(config("env.episode_steps=1"))
    franka = config("env=franka_pick_place", "env.episode_steps=50")
    validate_config(franka)
    assert episode_steps(franka) == 50 and env_label(franka.env) == "franka_pick_place-standard-T50"
    assert episode_steps(config("env=franka_pick_place")) == 100


@pytest.mark.parametrize(("workers", "per_worker", "capacity_per", "capacities", "storage"), [
    (1, "true", "worker", [1_000_020], 1_000_020), (1, "true", "total", [1_000_020], 1_000_020),
    (2, "false", "total", [1_000_020], 1_000_020), (2, "false", "worker", [2_000_040], 2_000_040),
    (8, "true", "total", [125_020] * 8, 1_000_020), (8, "true", "worker", [1_000_020] * 8, 8_000_160),
])
def test_a_per_holds_priorities_for_every_transition_of_70_step_episodes(workers, per_worker, capacity_per,
                                                                          capacities, storage):
    # 1e6 transitions of 70-step Slide episodes are 14,286 rows (TorchRL rounds up): 1,000,020 transitions,
    # shared by the workers or each worker's own (as each of baselines' MPI workers has its own 1e6).
    cfg = config("sampler=per", "env=slide", "env.episode_steps=70", f"workers={workers}",
                 f"replay.per_worker={per_worker}", "replay.capacity=1000000", f"replay.capacity_per={capacity_per}")
    sampler = make_sampler(cfg)
    shards = sampler.samplers if isinstance(sampler, PerWorkerSampler) else [sampler]
    assert [shard.max_size for shard in shards] == capacities
    env = make_env(cfg)
    replay, _ = make_replay(cfg, sampler, env)  # the buffer accepts them: its storage rounds alike
    env.close()
    assert replay.storage.max_size == storage


def test_each_workers_own_capacity_is_rounded_up_to_whole_cycles_of_its_episodes():
    # 1e6 transitions are 14,286 rows of 70 steps; in whole cycles of a worker's 4 episodes, 14,288.
    cfg = config("preset=paper", "env=slide", "env.episode_steps=70", "rollouts_per_cycle=4", "replay.capacity=1000000")
    assert replay_capacity(cfg) == 8 * 14_288 * 70
    assert worker_share(replay_capacity(cfg), 70, 8, 4) == 14_288 * 70


@pytest.mark.parametrize(("capacity_per", "episodes_kept"), [("total", [2, 2]), ("worker", [4, 4])])
def test_each_worker_keeps_its_own_capacity_of_episodes_when_capacity_is_per_worker(tmp_path, capacity_per,
                                                                                     episodes_kept):
    # Two workers, two 50-step episodes each per cycle, 200 transitions: shared, one cycle fills the storage and
    # each worker keeps its last 2 episodes; per worker, each keeps 4 (its last two cycles).
    cfg = config("workers=2", "epochs=1", "cycles_per_epoch=3", "replay.capacity=200",
                 f"replay.capacity_per={capacity_per}", "sampler=per")
    train(cfg, tmp_path)
    state = load_checkpoint(tmp_path)
    sampler = make_sampler(cfg)
    env = make_env(cfg)
    replay, _ = make_replay(cfg, sampler, env)
    env.close()
    replay.load_state_dict(state["replay"])
    assert [len(view) // 50 for view in sampler.worker_views(replay.storage)] == episodes_kept
    assert len(replay) == sum(episodes_kept) * 50
    assert rows(tmp_path / "progress.csv")[0]["replay_capacity"] == str(len(replay))  # 3 cycles filled it


def test_help_says_what_the_default_scale_gives_and_how_to_train_a_working_agent():
    out = subprocess.run([sys.executable, "train.py", "--help"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "preset=paper" in out.stdout and "50 epochs in about 50 minutes" in out.stdout
    assert "docs/results.md" in out.stdout
