"""Checkpoints of plain tensors and dicts (loadable with ``weights_only=True``), written atomically."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch
from tensordict.nn import TensorDictSequential

from torchrl_cebp.agents import ObsGoalNormalizer, make_actor

CHECKPOINT_NAME = "checkpoint.pt"


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
