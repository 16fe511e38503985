"""Checkpoints of plain tensors and dicts (loadable with ``weights_only=True``), written atomically."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict.nn import TensorDictSequential
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.scheduler import LinearScheduler

from torchrl_cebp.agents import ObsGoalNormalizer, make_actor
from torchrl_cebp.training.builders import Agent
from torchrl_cebp.training.config import ConfigError, check_same_run

CHECKPOINT_NAME = "checkpoint.pt"
# 2: episodes from TorchRL collectors, one optimiser over actor and critic. Runs of format 1 (a hand-written
# rollout worker) cannot be continued by this trainer: their exploration streams differ.
CHECKPOINT_FORMAT = 2


def save_checkpoint(state: dict[str, Any], run_dir: str | Path) -> Path:
    """Writes ``state`` to ``run_dir/checkpoint.pt`` through a temporary file and a rename.

    A crash while writing leaves the previous checkpoint intact.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     _ = save_checkpoint({"epoch": 3, "w": torch.ones(2)}, d)
        ...     load_checkpoint(d)["epoch"]
        3
    """
    path = Path(run_dir) / CHECKPOINT_NAME
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)
    return path


def load_checkpoint(run_dir: str | Path, map_location: torch.device | str = "cpu") -> dict[str, Any]:
    """Loads ``run_dir/checkpoint.pt`` without unpickling code (``weights_only=True``)."""
    return torch.load(Path(run_dir) / CHECKPOINT_NAME, map_location=map_location, weights_only=True)


def has_checkpoint(run_dir: str | Path) -> bool:
    return (Path(run_dir) / CHECKPOINT_NAME).is_file()


def training_state(
    epoch: int, wall_s: float, cfg: DictConfig, agent: Agent, optimizer: torch.optim.Optimizer,
    replay: TensorDictReplayBuffer, beta_scheduler: LinearScheduler | None,
) -> dict[str, Any]:
    """Everything a resumed run needs after ``epoch``, as plain tensors and dicts."""
    return {
        "format": CHECKPOINT_FORMAT,
        "epoch": epoch,
        "wall_s": wall_s,
        "config": OmegaConf.to_container(cfg, resolve=True),
        "loss": agent.loss.state_dict(),
        "normalizer": agent.normalizer.state_dict(),
        "optimizer": optimizer.state_dict(),
        "replay": replay.state_dict(),
        **({"beta_scheduler": beta_scheduler.state_dict()} if beta_scheduler is not None else {}),
        "rng": rng_state(),
    }


def restore_training_state(
    state: dict[str, Any], cfg: DictConfig, agent: Agent, optimizer: torch.optim.Optimizer,
    replay: TensorDictReplayBuffer, beta_scheduler: LinearScheduler | None,
) -> tuple[int, float]:
    """Loads a :func:`training_state` into the run's parts; returns the epoch to start from and the wall time so far."""
    if state.get("format") != CHECKPOINT_FORMAT:
        raise ConfigError(
            f"cannot resume: the checkpoint has format {state.get('format', 1)}, this trainer writes format "
            f"{CHECKPOINT_FORMAT} (episodes from TorchRL collectors); continue it with the commit in its "
            "progress.csv's code_commit column, or start a new run"
        )
    check_same_run(state["config"], cfg)
    agent.loss.load_state_dict(state["loss"])
    agent.normalizer.load_state_dict(state["normalizer"])
    optimizer.load_state_dict(state["optimizer"])
    replay.load_state_dict(state["replay"])
    if beta_scheduler is not None:
        beta_scheduler.load_state_dict(state["beta_scheduler"])
    # Restored last, so that building the run's parts drew nothing from the restored stream.
    set_rng_state(state["rng"])
    return state["epoch"] + 1, state["wall_s"]


def rng_state() -> dict[str, Any]:
    """The torch RNG states (CPU and, when present, CUDA): the samplers, HER and exploration draw from them."""
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


_ACTOR_PREFIX = "actor_network_params."


def load_policy(checkpoint: str | Path) -> TensorDictSequential:
    """The deterministic policy (normaliser, then actor) of a checkpoint written by ``torchrl_cebp.training``.

    ``checkpoint`` is the ``checkpoint.pt`` file or the run directory holding it. The actor's weights
    are the loss's ``actor_network_params`` (not the delayed target copy); its hidden sizes come
    from the checkpoint's config, the observation, goal and action sizes from the saved tensors
    (the joint robot acts in 7 or 8 dimensions, and observes touch on some tasks).

    Example:
        >>> policy = load_policy("runs/franka_pick_place-standard/cebp/default/seed0")  # doctest: +SKIP
        >>> policy(env.reset())["action"]  # doctest: +SKIP
    """
    path = Path(checkpoint)
    if path.is_dir():
        path = path / CHECKPOINT_NAME
    if not path.is_file():
        raise FileNotFoundError(f"No checkpoint at {str(path)!r} (expected a {CHECKPOINT_NAME} or a run directory).")
    state = torch.load(path, map_location="cpu", weights_only=True)
    missing = {"config", "loss", "normalizer"} - set(state)
    if missing:
        raise ValueError(f"{str(path)!r} is not a training checkpoint: it lacks {sorted(missing)}.")
    actor_state = {
        key.removeprefix(_ACTOR_PREFIX): value for key, value in state["loss"].items() if key.startswith(_ACTOR_PREFIX)
    }
    weights = [value for key, value in actor_state.items() if key.endswith("weight")]
    obs_dim, goal_dim = state["normalizer"]["obs.sum"].numel(), state["normalizer"]["goal.sum"].numel()
    normalizer = ObsGoalNormalizer(obs_dim, goal_dim)
    normalizer.load_state_dict(state["normalizer"])
    actor = make_actor(obs_dim + goal_dim, weights[-1].shape[0], state["config"]["agent"]["hidden"])
    actor.load_state_dict(actor_state)
    return TensorDictSequential(normalizer, actor).eval()
