"""Checkpoints and policy files: plain tensors and dicts (loadable with ``weights_only=True``), written atomically.

A run directory holds ``checkpoint.pt`` (everything a resumed run needs, replay buffer included),
``policy.pt`` (what acting needs: the actor and the observation normaliser, a few hundred KB) and
``best_policy.pt`` (the policy of the epoch with the highest test success so far).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict
from tensordict.nn import TensorDictSequential
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.scheduler import LinearScheduler

from torchrl_cebp import _upstream
from torchrl_cebp.agents import ObsGoalNormalizer, make_actor
from torchrl_cebp.training.builders import Agent
from torchrl_cebp.training.config import ConfigError, check_same_run

CHECKPOINT_NAME = "checkpoint.pt"
POLICY_NAME = "policy.pt"
BEST_POLICY_NAME = "best_policy.pt"
POLICY_FORMAT = "torchrl_cebp.policy/1"
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
    return _save_atomically(state, Path(run_dir) / CHECKPOINT_NAME)


def _save_atomically(state: dict[str, Any], path: Path) -> Path:
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)
    return path


def load_checkpoint(run_dir: str | Path, map_location: torch.device | str = "cpu") -> dict[str, Any]:
    """Loads ``run_dir/checkpoint.pt`` without unpickling code (``weights_only=True``)."""
    return torch.load(Path(run_dir) / CHECKPOINT_NAME, map_location=map_location, weights_only=True)


def stored_episodes(state: dict[str, Any]) -> tuple[TensorDict, int]:
    """The episodes in a checkpoint's replay buffer, ``[episodes, T]``, oldest first, and how many came before them.

    Once the buffer is full, new episodes overwrite the oldest; the second number counts those overwritten, so
    that episode ``i`` of the result was the ``(i + second)``-th collected.
    """
    storage = state["replay"][_upstream.BUFFER_STORAGE_KEY][_upstream.STORAGE_STATE_KEY]
    episodes = TensorDict().load_state_dict(storage, strict=False).unflatten_keys(".")
    next_row, written = _upstream.round_robin_position(state["replay"])
    if written > len(episodes):  # wrapped: the oldest episode is in the row the writer fills next
        episodes = episodes[torch.arange(next_row, next_row + len(episodes)) % len(episodes)]
    return episodes, written - len(episodes)


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


def policy_state(
    cfg: DictConfig, agent: Agent, epoch: int | None = None, test_success: float | None = None
) -> dict[str, Any]:
    """What acting needs, as plain tensors: the actor, the observation normaliser, the hidden sizes and the env config.

    A trainer adds the ``epoch`` the policy finished and its ``test_success``.

    Example:
        >>> from omegaconf import OmegaConf
        >>> from torchrl_cebp.training.builders import TaskDims, make_agent
        >>> cfg = OmegaConf.create({"env": {"task": "push"}, "agent": {"hidden": [32], "random_eps": 0.3,
        ...                         "noise_std": 0.2, "action_l2": 1.0, "tau": 0.05}})
        >>> sorted(policy_state(cfg, make_agent(cfg, TaskDims(25, 3, 4, 50))))
        ['actor', 'env', 'format', 'hidden', 'normalizer']
    """
    return {
        "format": POLICY_FORMAT,
        "env": OmegaConf.to_container(cfg.env, resolve=True),
        "hidden": list(cfg.agent.hidden),
        "actor": agent.policy[1].state_dict(),
        "normalizer": agent.normalizer.state_dict(),
        **({} if epoch is None else {"epoch": epoch}),
        **({} if test_success is None else {"test_success": test_success}),
    }


class BestPolicy:
    """Keeps a run's best policy in ``run_dir/best_policy.pt``: the last epoch whose test success is the highest.

    A resumed run (``resume=True``) reads back what it has to beat from the file, so it keeps comparing with the
    epochs before it; a new run ignores a file left in its folder. Ties replace the file: the later policy has
    trained longer for the same score.

    Example:
        >>> import tempfile
        >>> from omegaconf import OmegaConf
        >>> from torchrl_cebp.training.builders import TaskDims, make_agent
        >>> cfg = OmegaConf.create({"env": {"task": "push"}, "agent": {"hidden": [32], "random_eps": 0.3,
        ...                         "noise_std": 0.2, "action_l2": 1.0, "tau": 0.05}})
        >>> agent = make_agent(cfg, TaskDims(25, 3, 4, 50))
        >>> with tempfile.TemporaryDirectory() as d:
        ...     best = BestPolicy(d)
        ...     first = best.offer(policy_state(cfg, agent, epoch=0, test_success=0.4))
        ...     worse = best.offer(policy_state(cfg, agent, epoch=1, test_success=0.3))
        ...     first, worse, BestPolicy(d, resume=True).test_success
        (True, False, 0.4)
    """

    def __init__(self, run_dir: str | Path, resume: bool = False) -> None:
        self.path = Path(run_dir) / BEST_POLICY_NAME
        self.test_success = -math.inf
        if resume and self.path.is_file():
            self.test_success = float(torch.load(self.path, map_location="cpu", weights_only=True)["test_success"])

    def offer(self, state: dict[str, Any]) -> bool:
        """Writes ``state`` (a :func:`policy_state` with ``test_success``) if it scores at least the best so far."""
        if not state["test_success"] >= self.test_success:  # a NaN score never becomes the best
            return False
        save_policy(state, self.path)
        self.test_success = float(state["test_success"])
        return True


def save_policy(state: dict[str, Any], path: str | Path) -> Path:
    """Writes a :func:`policy_state` to ``path`` (a run directory gets ``policy.pt``), atomically."""
    path = Path(path)
    return _save_atomically(state, path / POLICY_NAME if path.is_dir() else path)


_ACTOR_PREFIX = "actor_network_params."


def read_policy_state(source: str | Path) -> dict[str, Any]:
    """The :func:`policy_state` of a run directory, its ``checkpoint.pt``, or a policy file, read with ``weights_only=True``.

    A run directory is read from its ``policy.pt`` when it has one (runs before that file: from the checkpoint).
    """
    path = Path(source)
    if path.is_dir():
        path = path / POLICY_NAME if (path / POLICY_NAME).is_file() else path / CHECKPOINT_NAME
    if not path.is_file():
        raise FileNotFoundError(
            f"No policy at {str(path)!r} (expected a run directory, its {CHECKPOINT_NAME}, or a {POLICY_NAME} file)."
        )
    state = torch.load(path, map_location="cpu", weights_only=True)
    if state.get("format") == POLICY_FORMAT:
        return state
    missing = {"config", "loss", "normalizer"} - set(state)
    if missing:
        raise ValueError(f"{str(path)!r} is neither a policy file nor a training checkpoint: it lacks {sorted(missing)}.")
    # The loss trains the policy's actor through its functional copy: those are the actor's weights (not the target's).
    actor = {key.removeprefix(_ACTOR_PREFIX): value for key, value in state["loss"].items() if key.startswith(_ACTOR_PREFIX)}
    return {
        "format": POLICY_FORMAT, "env": state["config"].get("env", {}), "hidden": state["config"]["agent"]["hidden"],
        "actor": actor, "normalizer": state["normalizer"],
    }


def load_policy(source: str | Path) -> TensorDictSequential:
    """The deterministic policy (normaliser, then actor) of a run directory, its ``checkpoint.pt``, or a policy file.

    The hidden sizes come from the file, the observation, goal and action sizes from the saved tensors
    (the joint robot acts in 7 or 8 dimensions, and observes touch on some tasks).

    Example:
        >>> import tempfile
        >>> from omegaconf import OmegaConf
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.training.builders import TaskDims, make_agent
        >>> cfg = OmegaConf.create({"env": {"task": "push"}, "agent": {"hidden": [32], "random_eps": 0.3,
        ...                         "noise_std": 0.2, "action_l2": 1.0, "tau": 0.05}})
        >>> with tempfile.TemporaryDirectory() as d:
        ...     path = save_policy(policy_state(cfg, make_agent(cfg, TaskDims(25, 3, 4, 50))), d)
        ...     policy = load_policy(path)
        >>> policy(TensorDict(observation=torch.zeros(25), desired_goal=torch.zeros(3)))["action"].shape
        torch.Size([4])
    """
    return policy_from_state(read_policy_state(source))


def policy_from_state(state: dict[str, Any]) -> TensorDictSequential:
    """The deterministic policy of a :func:`read_policy_state` (for callers that also need its ``env``)."""
    weights = [value for key, value in state["actor"].items() if key.endswith("weight")]
    obs_dim, goal_dim = state["normalizer"]["obs.sum"].numel(), state["normalizer"]["goal.sum"].numel()
    normalizer = ObsGoalNormalizer(obs_dim, goal_dim)
    normalizer.load_state_dict(state["normalizer"])
    actor = make_actor(obs_dim + goal_dim, weights[-1].shape[0], state["hidden"])
    actor.load_state_dict(state["actor"])
    return TensorDictSequential(normalizer, actor).eval()
