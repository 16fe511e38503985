"""The training config: where its files are, how to compose it, and the checks Hydra's own (group choices, known
keys) leaves out."""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict
from numbers import Real
from pathlib import Path

import torch
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig, OmegaConf

from torchrl_cebp.envs import ALL_TASKS, CONTROLS, FRANKA_TASK, GOAL_SPACES, RobotOptions
from torchrl_cebp.replay.her import STRATEGIES
from torchrl_cebp.training.builders import episode_steps, episodes_per_cycle
from torchrl_cebp.training.metrics import LOGGERS

# The Hydra configs (config.yaml and its groups), shipped inside the package so that an installed copy trains.
CONFIG_DIR = Path(__file__).resolve().parents[1] / "conf"
DEVICES = ("auto", "cpu", "cuda")
PRECISIONS = ("fp32", "bf16")
CAPACITY_PER = ("worker", "total")

# ``${mul:a,b,...}`` lets a config derive a count, e.g. PER's beta-annealing horizon.
if not OmegaConf.has_resolver("mul"):
    OmegaConf.register_new_resolver("mul", lambda *factors: math.prod(factors))


def env_label(env: DictConfig) -> str:
    """The run folder's env part: ``<task>-<goal_space>``, then the robot's label unless it is the default mocap Fetch,
    then ``-T<steps>`` when the episode length is set (``env.episode_steps``), then ``-grasped<percent>`` when
    training episodes start grasped (``env.grasped_start``).

    Args:
        env (DictConfig): the env config.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> env_label(OmegaConf.create({"task": "push", "goal_space": "extended", "control": "joint",
        ...                             "touch_ignores_table": True, "touch_in_observation": False}))
        'push-extended-joint-tableblind'
        >>> env_label(OmegaConf.create({"task": "push", "goal_space": "standard"}))
        'push-standard'
        >>> env_label(OmegaConf.create({"task": "slide", "goal_space": "standard", "episode_steps": 70}))
        'slide-standard-T70'
        >>> env_label(OmegaConf.create({"task": "franka_pick_place", "goal_space": "standard", "episode_steps": 50,
        ...                             "grasped_start": 0.5}))
        'franka_pick_place-standard-T50-grasped50'
    """
    label = RobotOptions.from_config(env).label
    steps = env.get("episode_steps")
    grasped = env.get("grasped_start") or 0.0
    return (f"{env.task}-{env.goal_space}" + (f"-{label}" if label else "") + (f"-T{steps}" if steps is not None else "")
            + (f"-grasped{round(100 * grasped):g}" if grasped else ""))


# ``${env_label:${env}}`` names the run folders (conf/config.yaml), so that the robots do not share one.
if not OmegaConf.has_resolver("env_label"):
    OmegaConf.register_new_resolver("env_label", env_label)


def replay_label(workers: int, per_worker: bool, strategy: str = "future") -> str:
    """The run folder's suffix after the preset: ``-per_worker`` for per-worker replay of several workers, then
    ``-her_<strategy>`` for a HER strategy other than baselines' ``future``.

    Runs of the merged buffer and of ``future`` keep the folders they had before these options existed.

    Args:
        workers (int): the number of emulated workers.
        per_worker (bool): each worker replays from its own buffer.
        strategy (str, optional): the HER relabelling strategy. Defaults to ``"future"``.

    Examples:
        >>> replay_label(8, True), replay_label(8, False), replay_label(1, True), replay_label(8, True, "past")
        ('-per_worker', '', '', '-per_worker-her_past')
    """
    return ("-per_worker" if workers > 1 and per_worker else "") + (f"-her_{strategy}" if strategy != "future" else "")


if not OmegaConf.has_resolver("replay_label"):
    OmegaConf.register_new_resolver("replay_label", replay_label)


def temperature_label(sampler: str, temperature: float | None = None) -> str:
    """The run folder's sampler part in a temperature ablation: ``cebp_T<T>`` for CEBP, the sampler's name otherwise.

    Args:
        sampler (str): the sampler's config name (``hydra:runtime.choices.sampler``).
        temperature (float, optional): the sampler's sigmoid temperature; ``None`` for a sampler without one.
            Defaults to ``None``.

    Examples:
        >>> temperature_label("cebp", 0.01), temperature_label("cebp", 5), temperature_label("her")
        ('cebp_T0.01', 'cebp_T5', 'her')
    """
    return sampler if temperature is None else f"{sampler}_T{temperature}"


if not OmegaConf.has_resolver("temperature_label"):
    OmegaConf.register_new_resolver("temperature_label", temperature_label)


def compose_config(*overrides: str, return_hydra_config: bool = False) -> DictConfig:
    """The training config of :data:`CONFIG_DIR` with Hydra ``overrides``, as ``train.py`` composes it.

    For :func:`~torchrl_cebp.training.train` outside the command line: every key has its default.

    Args:
        *overrides (str): Hydra overrides, e.g. ``"sampler=cebp"``, ``"+comparison=push_standard"``.
        return_hydra_config (bool, optional): keep the ``hydra`` node (run folders, sweeps). Defaults to ``False``.

    Example:
        >>> cfg = compose_config("sampler=cebp", "env=pick_place", "preset=quick")
        >>> cfg.sampler.temperature, cfg.epochs, cfg.env.task
        (0.01, 5, 'pick_place')
    """
    with initialize_config_dir(str(CONFIG_DIR), version_base="1.3"):
        return compose("config", overrides=list(overrides), return_hydra_config=return_hydra_config)


class ConfigError(ValueError):
    """A config value outside its allowed range or set.

    Example:
        >>> from omegaconf import OmegaConf
        >>> try:
        ...     validate_config(OmegaConf.create({"seed": -1}))
        ... except ConfigError as err:
        ...     print(isinstance(err, ValueError), "seed=-1" in str(err))
        True True
    """


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_real(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool)


def validate_config(cfg: DictConfig) -> None:
    """Raises :class:`ConfigError` listing every invalid value of ``cfg`` and what is allowed.

    Args:
        cfg (DictConfig): the composed training config (``conf/config.yaml``).

    Raises:
        ConfigError: one line per invalid value.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> cfg = OmegaConf.create({"device": "tpu"})
        >>> try:
        ...     validate_config(cfg)
        ... except ConfigError as err:
        ...     print(str(err).splitlines()[1])
          device='tpu': must be one of ['auto', 'cpu', 'cuda']
    """
    errors: list[str] = []

    def check(key: str, ok, allowed: str) -> None:
        value = OmegaConf.select(cfg, key)
        if not ok(value):
            errors.append(f"  {key}={value!r}: must be {allowed}")

    def one_of(key: str, choices) -> None:
        check(key, lambda v: v in choices, f"one of {list(choices)}")

    def positive_int(key: str) -> None:
        check(key, lambda v: _is_int(v) and v > 0, "a positive integer")

    def real_in(key: str, low: float, high: float, *, open_low: bool = False) -> None:
        bracket = "(" if open_low else "["
        check(
            key,
            lambda v: _is_real(v) and (low < v if open_low else low <= v) and v <= high,
            f"a number in {bracket}{low}, {high}]",
        )

    one_of("device", DEVICES)
    one_of("env.task", ALL_TASKS)
    one_of("env.goal_space", GOAL_SPACES)
    one_of("env.control", CONTROLS)
    for key in ("env.touch_ignores_table", "env.touch_in_observation"):
        check(key, lambda v: isinstance(v, bool), "true or false")
    one_of("precision", PRECISIONS)
    one_of("logger", LOGGERS)
    one_of("replay.strategy", STRATEGIES)
    one_of("replay.capacity_per", CAPACITY_PER)
    check("seed", lambda v: _is_int(v) and v >= 0, "a non-negative integer")
    for key in (
        "workers", "epochs", "schedule_epochs", "cycles_per_epoch", "rollouts_per_cycle", "updates_per_cycle",
        "batch_size", "test_episodes", "threads", "replay.capacity",
    ):
        positive_int(key)
    check("resume", lambda v: isinstance(v, bool), "true or false")
    check("overlap_collection", lambda v: isinstance(v, bool), "true or false")
    check("replay.per_worker", lambda v: isinstance(v, bool), "true or false")
    check("env.episode_steps", lambda v: v is None or (_is_int(v) and v > 1), "null or an integer above 1")
    real_in("env.grasped_start", 0.0, 1.0)
    check("collector_processes", lambda v: _is_int(v) and v >= 0, "a non-negative integer")
    real_in("replay.future_p", 0.0, 1.0)
    real_in("agent.tau", 0.0, 1.0, open_low=True)
    real_in("agent.random_eps", 0.0, 1.0)
    real_in("agent.noise_std", 0.0, math.inf)
    real_in("agent.action_l2", 0.0, math.inf)
    real_in("agent.lr_actor", 0.0, math.inf, open_low=True)
    real_in("agent.lr_critic", 0.0, math.inf, open_low=True)
    check("agent.hidden", lambda v: v is not None and len(v) > 0 and all(_is_int(h) and h > 0 for h in v),
          "a non-empty list of positive integers")
    errors += _franka_robot_errors(cfg) + _collection_errors(cfg)
    if cfg.get("device") == "cuda" and not torch.cuda.is_available():
        errors.append("  device='cuda': CUDA is not available here; use device=auto or device=cpu")
    if errors:
        raise ConfigError("invalid config:\n" + "\n".join(errors))


def _franka_robot_errors(cfg: DictConfig) -> list[str]:
    if OmegaConf.select(cfg, "env.task") != FRANKA_TASK:
        grasped = OmegaConf.select(cfg, "env.grasped_start", default=0.0)
        return [f"  env.grasped_start={grasped!r}: only env={FRANKA_TASK} has grasped starts; use 0"] if grasped else []
    return [
        f"  env.{key}={OmegaConf.select(cfg, f'env.{key}')!r}: the Franka task has the mocap robot "
        f"with its own pads only; use env.{key}={default!r}"
        for key, default in asdict(RobotOptions()).items()
        if OmegaConf.select(cfg, f"env.{key}", default=default) != default
    ]


def _collection_errors(cfg: DictConfig) -> list[str]:
    """What a cycle's episodes must fit: the replay, and the collector's env processes."""
    if not all(_is_int(cfg.get(key)) for key in ("rollouts_per_cycle", "workers")):
        return []
    errors = []
    n_envs = episodes_per_cycle(cfg)
    steps = episode_steps(cfg)
    capacity = OmegaConf.select(cfg, "replay.capacity")
    own = OmegaConf.select(cfg, "replay.capacity_per") == "worker"  # a worker's episodes of a cycle must fit
    episodes, whose, factors = ((cfg.rollouts_per_cycle, "a worker's episodes of one cycle", "rollouts_per_cycle") if own
                                else (n_envs, "one cycle's episodes", "rollouts_per_cycle x workers"))
    if steps is not None and _is_int(capacity) and capacity < episodes * steps:
        errors.append(f"  replay.capacity={capacity}: smaller than {whose}; needs at least {episodes * steps} "
                      f"transitions ({factors} x {steps} steps)")
    processes = cfg.get("collector_processes")
    if _is_int(processes) and processes > 0 and n_envs % processes:
        errors.append(f"  collector_processes={processes}: must divide the {n_envs} episodes of a cycle "
                      "(rollouts_per_cycle x workers) evenly")
    return errors


def resolve_device(name: str) -> torch.device:
    """The device ``name`` means: ``"auto"`` is CUDA when available, else the CPU.

    Args:
        name (str): ``"auto"``, ``"cpu"`` or ``"cuda"``.

    Example:
        >>> resolve_device("cpu")
        device(type='cpu')
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def warn_if_bf16_is_emulated(precision: str, device: torch.device) -> None:
    """Warns when ``precision=bf16`` would run on a CPU without bfloat16 instructions (slower than fp32).

    Args:
        precision (str): ``"fp32"`` or ``"bf16"``.
        device (torch.device): where the updates run.

    Example:
        >>> warn_if_bf16_is_emulated("fp32", torch.device("cpu"))  # fp32 never warns
    """
    if precision != "bf16" or device.type != "cpu":
        return
    if not (torch.cpu._is_avx512_bf16_supported() or torch.cpu._is_amx_tile_supported()):
        warnings.warn(
            "precision=bf16: this CPU has neither AVX512-BF16 nor AMX, so bfloat16 products are emulated "
            "and the updates will likely be slower than with precision=fp32",
            stacklevel=2,
        )


# What a resumed run must share with the checkpointed one (epochs may grow; device, threads and precision may change).
RUN_DEFINING_KEYS = (
    "seed", "workers", "cycles_per_epoch", "rollouts_per_cycle", "updates_per_cycle", "batch_size",
    "test_episodes", "env", "sampler", "agent", "replay",
)


# What a checkpoint made before a run-defining key existed ran with: checkpoints before per-worker replay
# merged the workers' episodes into one buffer, those before env.episode_steps ran the task's own length, and
# those before env.grasped_start started every episode from the table.
# The samplers' module before it moved into the replay package: checkpoints of older runs name their sampler by it.
MOVED_SAMPLERS_MODULE, SAMPLERS_MODULE = "torchrl_cebp.samplers.", "torchrl_cebp.replay.samplers."
LEGACY_DEFAULTS: dict[tuple[str, str], object] = {
    ("replay", "per_worker"): False, ("replay", "capacity_per"): "total", ("env", "episode_steps"): None,
    ("env", "grasped_start"): 0.0,
}


def with_legacy_defaults(saved: dict) -> dict:
    """A checkpoint's config with the keys added since it was made, set to what that run did.

    Args:
        saved (dict): the config saved in a checkpoint.

    Example:
        >>> with_legacy_defaults({"replay": {"capacity": 10}})["replay"]
        {'capacity': 10, 'per_worker': False, 'capacity_per': 'total'}
        >>> with_legacy_defaults({"sampler": {"_target_": "torchrl_cebp.samplers.CEBPSampler"}})["sampler"]
        {'_target_': 'torchrl_cebp.replay.samplers.CEBPSampler'}
    """
    saved = {**saved}
    for (group, key), value in LEGACY_DEFAULTS.items():
        if isinstance(saved.get(group), dict) and key not in saved[group]:
            saved[group] = {**saved[group], key: value}
    sampler = saved.get("sampler")
    if isinstance(sampler, dict) and str(sampler.get("_target_", "")).startswith(MOVED_SAMPLERS_MODULE):
        saved["sampler"] = {**sampler, "_target_": sampler["_target_"].replace(MOVED_SAMPLERS_MODULE, SAMPLERS_MODULE, 1)}
    return saved


def _as_run(config: dict) -> dict:
    """``config`` with the settings that change nothing in its run made equal: one worker's capacity is the total."""
    if config.get("workers") == 1 and isinstance(config.get("replay"), dict) and "capacity_per" in config["replay"]:
        return {**config, "replay": {**config["replay"], "capacity_per": "worker"}}
    return config


def check_same_run(saved: dict, cfg: DictConfig) -> None:
    """Raises :class:`ConfigError` when ``cfg`` differs from a checkpoint's config in a run-defining key.

    The error names each differing setting by its dotted path, as a Hydra override would.

    Args:
        saved (dict): the config saved in the checkpoint.
        cfg (DictConfig): the config of the run that resumes it.

    Raises:
        ConfigError: one clause per differing setting, with a hint where a new default explains it.

    Examples:
        >>> from omegaconf import OmegaConf
        >>> check_same_run({"seed": 0, "epochs": 5}, OmegaConf.create({"seed": 0, "epochs": 9}))
        >>> try:
        ...     check_same_run({"seed": 0, "agent": {"hidden": [64], "lr": 0.001}},
        ...                    OmegaConf.create({"seed": 1, "agent": {"hidden": [64], "lr": 0.01}}))
        ... except ConfigError as err:
        ...     print(err)
        cannot resume: the checkpoint was made with seed=0, this config has seed=1; the checkpoint was made with agent.lr=0.001, this config has agent.lr=0.01
    """
    current = _as_run(OmegaConf.to_container(cfg, resolve=True))
    saved = _as_run(with_legacy_defaults(saved))
    differences = [
        f"the checkpoint was made with {path}={was!r}, this config has {path}={now!r}"
        + RESUME_HINTS.get(path, "").format(was=was)
        for key in RUN_DEFINING_KEYS
        for path, was, now in _differing_settings(key, saved.get(key), current.get(key))
    ]
    if differences:
        raise ConfigError("cannot resume: " + "; ".join(differences))


# Why a setting differs from a checkpoint's (a new default, or one that follows epochs), and how to keep its value.
RESUME_HINTS = {
    "replay.capacity_per": (
        " (to resume the checkpoint's run, add the override replay.capacity_per={was}; runs made before the setting "
        "existed shared replay.capacity among their workers)"
    ),
    "sampler.beta_anneal_draws": (
        " (PER anneals beta over schedule_epochs, which follows epochs unless set, so more epochs change its "
        "schedule; to extend the run on the checkpoint's schedule, add the override sampler.beta_anneal_draws={was})"
    ),
}


def _differing_settings(path: str, was: object, now: object) -> list[tuple[str, object, object]]:
    """The leaves, by dotted path, where two config values differ (a leaf absent on one side is None there)."""
    if isinstance(was, dict) and isinstance(now, dict):
        return [difference for key in {**was, **now}
                for difference in _differing_settings(f"{path}.{key}", was.get(key), now.get(key))]
    return [] if was == now else [(path, was, now)]
