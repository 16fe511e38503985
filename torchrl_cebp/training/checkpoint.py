"""Checkpoints and policy files: plain tensors and dicts (loadable with ``weights_only=True``), written atomically.

A run directory holds ``checkpoint.pt`` (everything a resumed run needs, replay buffer included),
``checkpoint_previous.pt`` (the same, one epoch older: what a resume falls back to when the newest does not load),
``policy.pt`` (what acting needs: the actor and the observation normaliser, a few hundred KB) and
``best_policy.pt`` (the policy of the epoch with the highest test success so far).
"""

from __future__ import annotations

import logging
import math
import os
import pickle
import re
import zipfile
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
from torchrl_cebp.training.config import ConfigError, check_same_run, with_legacy_defaults

CHECKPOINT_NAME = "checkpoint.pt"
PREVIOUS_CHECKPOINT_NAME = "checkpoint_previous.pt"
POLICY_NAME = "policy.pt"
BEST_POLICY_NAME = "best_policy.pt"
POLICY_FORMAT = "torchrl_cebp.policy/1"
# 2: episodes from TorchRL collectors, one optimiser over actor and critic. Runs of format 1 (a hand-written
# rollout worker) cannot be continued by this trainer: their exploration streams differ.
CHECKPOINT_FORMAT = 2

logger = logging.getLogger(__name__)


class UnreadableFileError(ValueError):
    """A checkpoint or policy file that does not hold what it should; the message names the file and what is wrong.

    Example:
        >>> try:
        ...     load_checkpoint("/nonexistent-run")
        ... except UnreadableFileError as error:
        ...     print(isinstance(error, ValueError), "there is no such file" in str(error))
        True True
    """


def load_file(path: str | Path, map_location: torch.device | str = "cpu") -> Any:
    """``torch.load(path, weights_only=True)``; a file that does not load raises :class:`UnreadableFileError`.

    The error's message is one line: the file, and why it does not load (missing, empty, truncated or not
    written by ``torch.save``, or holding pickled code).

    Args:
        path (str or Path): the file.
        map_location (torch.device or str, optional): where the tensors are loaded. Defaults to ``"cpu"``.

    Raises:
        UnreadableFileError: the file does not load.

    Example:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     path = Path(d) / "policy.pt"
        ...     _ = path.write_text("not a checkpoint")
        ...     try:
        ...         load_file(path)
        ...     except UnreadableFileError as error:
        ...         print(str(error).removeprefix(str(path)))
         does not load: it is not a complete file of torch.save (16 bytes: truncated, or another format)
    """
    path = Path(path)
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except Exception as error:  # torch raises any of RuntimeError, EOFError, KeyError, UnpicklingError for a bad file
        raise UnreadableFileError(f"{path} does not load: {_why_unreadable(path, error)}") from error


def _why_unreadable(path: Path, error: Exception) -> str:
    if not path.is_file():
        return "there is no such file"
    size = path.stat().st_size
    if size == 0:
        return "it is empty (0 bytes)"
    if not zipfile.is_zipfile(path):
        return f"it is not a complete file of torch.save ({size} bytes: truncated, or another format)"
    if isinstance(error, pickle.UnpicklingError):
        found = re.search(r"GLOBAL (\S+)", str(error))
        what = f"a pickled {found.group(1)}" if found else "pickled objects"
        return f"it holds {what}, not only tensors and plain containers (it was not written by torchrl_cebp)"
    message = str(error).splitlines()[0] if str(error) else ""
    return f"{type(error).__name__}: {message.split('. ')[0]}"


class RunCheckpoints:
    """A run directory's checkpoints: the newest, ``checkpoint.pt``, and the previous epoch's beside it.

    :meth:`save` writes the new checkpoint in full (a temporary file and a rename) before the newest becomes
    the previous one, so a crash at any moment leaves a whole checkpoint. :meth:`load` falls back to the previous
    checkpoint when the newest does not load, saying so in one line: the damage costs one epoch, not the run.

    Args:
        run_dir (str or Path): the run directory.

    Example:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     checkpoints = RunCheckpoints(d)
        ...     _ = checkpoints.save({"epoch": 3})
        ...     _ = checkpoints.save({"epoch": 4})
        ...     _ = checkpoints.newest.write_bytes(b"")  # a disk fault
        ...     RunCheckpoints(d).load()["epoch"]
        3
    """

    def __init__(self, run_dir: str | Path) -> None:
        run_dir = Path(run_dir)
        self.newest, self.previous = run_dir / CHECKPOINT_NAME, run_dir / PREVIOUS_CHECKPOINT_NAME

    def exists(self) -> bool:
        """Whether the run directory holds a checkpoint (either file)."""
        return self.newest.is_file() or self.previous.is_file()

    def save(self, state: dict[str, Any]) -> Path:
        """Writes ``state`` as the newest checkpoint; the one it replaces becomes the previous one, unless it is damaged
        (a load fell back from it, or it is no whole file of ``torch.save``): then the previous one stays.

        Args:
            state (dict): plain tensors and containers (:func:`training_state`).

        Returns:
            the newest checkpoint's path.
        """
        damaged = _is_damaged(self.newest)  # it must not replace the previous one, which loads
        _save_atomically(state, self.newest, keep_replaced_as=None if damaged else self.previous)
        _FELL_BACK_FROM.pop(self.newest.resolve(), None)
        return self.newest

    def load(self, map_location: torch.device | str = "cpu") -> dict[str, Any]:
        """The newest checkpoint that loads (``weights_only=True``), its config as a run would read it today
        (:func:`~torchrl_cebp.training.config.with_legacy_defaults`: an older run's sampler module, and the keys
        added since, set to what that run did), so that every reader of it builds what the run ran.

        Args:
            map_location (torch.device or str, optional): where the tensors are loaded. Defaults to ``"cpu"``.

        Raises:
            UnreadableFileError: neither checkpoint loads; the message names both files and why.
        """
        state = self._load(map_location)
        if "config" in state:
            state["config"] = with_legacy_defaults(state["config"])
        return state

    def _load(self, map_location: torch.device | str) -> dict[str, Any]:
        try:
            return load_file(self.newest, map_location)
        except UnreadableFileError as newest_error:
            try:
                state = load_file(self.previous, map_location)
            except UnreadableFileError as previous_error:
                raise UnreadableFileError(
                    f"no checkpoint of {self.newest.parent} loads: {newest_error}; {previous_error}"
                ) from None
            _FELL_BACK_FROM[self.newest.resolve()] = _file_version(self.newest)
            # The previous checkpoint is one epoch older than the newest: falling back repeats that one epoch.
            logger.warning(f"{newest_error}; resuming from {self.previous.name} (epoch {state['epoch']}) instead, "
                           f"which repeats 1 epoch (epoch {state['epoch'] + 1})")
            return state


# The newest checkpoints a load of this process fell back from, each with the size and time of the version that did
# not load: the next save, by whichever RunCheckpoints or save_checkpoint, must not keep it as the previous one.
_FELL_BACK_FROM: dict[Path, tuple[int, int] | None] = {}


def _file_version(path: Path) -> tuple[int, int] | None:
    """A file's size and modification time (``None`` if there is none): a file written again has another."""
    try:
        stat = path.stat()
    except FileNotFoundError:
        return None
    return stat.st_size, stat.st_mtime_ns


def _is_damaged(newest: Path) -> bool:
    """Whether the newest checkpoint is one a load fell back from, or not a whole file of ``torch.save`` (a zip)."""
    fell_back_from = _FELL_BACK_FROM.get(newest.resolve(), False)
    if fell_back_from is not False and fell_back_from == _file_version(newest):
        return True
    return newest.is_file() and not zipfile.is_zipfile(newest)


def save_checkpoint(state: dict[str, Any], run_dir: str | Path) -> Path:
    """Writes ``state`` to ``run_dir/checkpoint.pt`` atomically, keeping the one it replaces (:class:`RunCheckpoints`).

    Args:
        state (dict): plain tensors and containers.
        run_dir (str or Path): the run directory.

    Returns:
        the checkpoint's path.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     _ = save_checkpoint({"epoch": 3, "w": torch.ones(2)}, d)
        ...     load_checkpoint(d)["epoch"]
        3
    """
    return RunCheckpoints(run_dir).save(state)


def _save_atomically(state: dict[str, Any], path: Path, keep_replaced_as: Path | None = None) -> Path:
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    if keep_replaced_as is not None and path.is_file():
        os.replace(path, keep_replaced_as)
    os.replace(tmp, path)
    return path


def load_checkpoint(run_dir: str | Path, map_location: torch.device | str = "cpu") -> dict[str, Any]:
    """The newest checkpoint of ``run_dir`` that loads, without unpickling code (:meth:`RunCheckpoints.load`).

    Args:
        run_dir (str or Path): the run directory.
        map_location (torch.device or str, optional): where the tensors are loaded. Defaults to ``"cpu"``.

    Raises:
        UnreadableFileError: neither checkpoint loads.
    """
    return RunCheckpoints(run_dir).load(map_location)


def stored_episodes(state: dict[str, Any]) -> tuple[TensorDict, int]:
    """The episodes in a checkpoint's replay buffer, ``[episodes, T]``, oldest first, and how many came before them.

    Once the buffer is full, new episodes overwrite the oldest; the second number counts those overwritten, so
    that episode ``i`` of the result was the ``(i + second)``-th collected.

    Args:
        state (dict): a training checkpoint (:func:`load_checkpoint`).
    """
    storage = state["replay"][_upstream.BUFFER_STORAGE_KEY][_upstream.STORAGE_STATE_KEY]
    episodes = TensorDict().load_state_dict(storage, strict=False).unflatten_keys(".")
    next_row, written = _upstream.round_robin_position(state["replay"])
    if written > len(episodes):  # wrapped: the oldest episode is in the row the writer fills next
        episodes = episodes[torch.arange(next_row, next_row + len(episodes)) % len(episodes)]
    return episodes, written - len(episodes)


def has_checkpoint(run_dir: str | Path) -> bool:
    """Whether ``run_dir`` holds a checkpoint (the newest or the previous one).

    Args:
        run_dir (str or Path): the run directory.
    """
    return RunCheckpoints(run_dir).exists()


def training_state(
    epoch: int, wall_s: float, cfg: DictConfig, agent: Agent, optimizer: torch.optim.Optimizer,
    replay: TensorDictReplayBuffer, beta_scheduler: LinearScheduler | None,
) -> dict[str, Any]:
    """Everything a resumed run needs after ``epoch``, as plain tensors and dicts.

    Args:
        epoch (int): the epoch just finished.
        wall_s (float): the run's training time so far, in seconds.
        cfg (DictConfig): the training config.
        agent (Agent): the trained modules.
        optimizer (torch.optim.Optimizer): their optimiser.
        replay (TensorDictReplayBuffer): the replay, with its sampler's state.
        beta_scheduler (LinearScheduler or None): PER's beta schedule, if any.
    """
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
    """Loads a :func:`training_state` into the run's parts; returns the epoch to start from and the wall time so far.

    Args:
        state (dict): a :func:`training_state`.
        cfg (DictConfig): the resuming run's config; it must define the same run.
        agent (Agent): loaded in place.
        optimizer (torch.optim.Optimizer): loaded in place.
        replay (TensorDictReplayBuffer): loaded in place.
        beta_scheduler (LinearScheduler or None): loaded in place, if any.

    Raises:
        ConfigError: a checkpoint of another format, or of another run (:func:`check_same_run`); one of another
            sampler names the fix, a new run folder.
    """
    if state.get("format") != CHECKPOINT_FORMAT:
        raise ConfigError(
            f"cannot resume: the checkpoint has format {state.get('format', 1)}, this trainer writes format "
            f"{CHECKPOINT_FORMAT} (episodes from TorchRL collectors); continue it with the commit in its "
            "progress.csv's code_commit column, or start a new run"
        )
    try:
        check_same_run(state["config"], cfg)
    except ConfigError as error:
        saved_sampler = (state["config"].get("sampler") or {}).get("_target_")
        if saved_sampler == OmegaConf.select(cfg, "sampler._target_"):
            raise
        # Its priorities are another sampler's (the sampler refuses its state too): nothing of the run carries over.
        raise ConfigError(f"{error}; a run with another sampler is a new run: give it a new run folder "
                          "(hydra.run.dir=...)") from None
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
    """Restores the torch RNG states of :func:`rng_state` (CUDA's only where CUDA is present).

    Args:
        state (dict): a :func:`rng_state`.
    """
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def policy_state(
    cfg: DictConfig, agent: Agent, epoch: int | None = None, test_success: float | None = None
) -> dict[str, Any]:
    """What acting needs, as plain tensors: the actor, the observation normaliser, the hidden sizes and the env config.

    Args:
        cfg (DictConfig): the training config; reads ``env`` and ``agent.hidden``.
        agent (Agent): the trained modules.
        epoch (int, optional): the epoch the policy finished. Defaults to ``None`` (not recorded).
        test_success (float, optional): its test success. Defaults to ``None`` (not recorded).

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

    Args:
        run_dir (str or Path): the run directory.
        resume (bool, optional): read the score to beat from an existing file. Defaults to ``False``.

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
            # The best policy is a by-product of the run: a damaged one must not stop the run resuming.
            try:
                self.test_success = float(load_file(self.path)["test_success"])
            except UnreadableFileError as error:
                logger.warning(f"{error}; the run's next policy replaces it")
            except (KeyError, TypeError, ValueError):
                logger.warning(f"{self.path} holds no test success; the run's next policy replaces it")

    def offer(self, state: dict[str, Any]) -> bool:
        """Writes ``state`` if it scores at least the best so far.

        Args:
            state (dict): a :func:`policy_state` with ``test_success``.

        Returns:
            whether it was written.
        """
        if not state["test_success"] >= self.test_success:  # a NaN score never becomes the best
            return False
        save_policy(state, self.path)
        self.test_success = float(state["test_success"])
        return True


def save_policy(state: dict[str, Any], path: str | Path) -> Path:
    """Writes a :func:`policy_state` to ``path``, atomically.

    Args:
        state (dict): a :func:`policy_state`.
        path (str or Path): a file, or a run directory (which gets ``policy.pt``).

    Returns:
        the file written.
    """
    path = Path(path)
    return _save_atomically(state, path / POLICY_NAME if path.is_dir() else path)


_ACTOR_PREFIX = "actor_network_params."


def _policy_path(source: str | Path) -> Path:
    path = Path(source)
    if path.is_dir():
        path = path / POLICY_NAME if (path / POLICY_NAME).is_file() else path / CHECKPOINT_NAME
    if not path.is_file():
        raise FileNotFoundError(
            f"No policy at {str(path)!r} (expected a run directory, its {CHECKPOINT_NAME}, or a {POLICY_NAME} file)."
        )
    return path


def read_policy_state(source: str | Path) -> dict[str, Any]:
    """The :func:`policy_state` of a run directory, its ``checkpoint.pt``, or a policy file, read with ``weights_only=True``.

    A run directory is read from its ``policy.pt`` when it has one (runs before that file: from the checkpoint).

    Args:
        source (str or Path): a run directory, a checkpoint or a policy file.

    Raises:
        FileNotFoundError: there is no such file.
        UnreadableFileError: the file does not load, or holds neither a policy nor a training checkpoint.
    """
    path = _policy_path(source)
    state = load_file(path)
    if not isinstance(state, dict):
        raise UnreadableFileError(
            f"{path} is neither a policy file nor a training checkpoint: it holds a {type(state).__name__}, not a dict"
        )
    if state.get("format") == POLICY_FORMAT:
        return state
    missing = {"config", "loss", "normalizer"} - set(state)
    if missing:
        raise UnreadableFileError(
            f"{path} is neither a policy file nor a training checkpoint: it lacks {sorted(missing)}"
        )
    # The loss trains the policy's actor through its functional copy: those are the actor's weights (not the target's).
    actor = {key.removeprefix(_ACTOR_PREFIX): value for key, value in state["loss"].items() if key.startswith(_ACTOR_PREFIX)}
    return {
        "format": POLICY_FORMAT, "env": state["config"].get("env", {}), "hidden": state["config"]["agent"]["hidden"],
        "actor": actor, "normalizer": state["normalizer"],
    }


def read_policy(source: str | Path) -> tuple[TensorDictSequential, dict[str, Any]]:
    """The policy of :func:`load_policy`, and the :func:`read_policy_state` it was built from (with its ``env``).

    Args:
        source (str or Path): a run directory, a checkpoint or a policy file.

    Raises:
        FileNotFoundError: there is no such file.
        UnreadableFileError: the file does not load, or its weights do not make a policy; one line says why.
    """
    path = _policy_path(source)
    state = read_policy_state(path)
    try:
        return policy_from_state(state), state
    except (KeyError, IndexError, TypeError, AttributeError, RuntimeError) as error:
        # load_state_dict's message opens with a header line; the next one names the first mismatch.
        what = " ".join(line.strip() for line in str(error).splitlines()[:2])
        raise UnreadableFileError(f"{path} does not hold a whole policy: {type(error).__name__}: {what}") from error


def load_policy(source: str | Path) -> TensorDictSequential:
    """The deterministic policy (normaliser, then actor) of a run directory, its ``checkpoint.pt``, or a policy file.

    The hidden sizes come from the file, the observation, goal and action sizes from the saved tensors
    (the joint robot acts in 7 or 8 dimensions, and observes touch on some tasks). A damaged or foreign file
    raises :class:`UnreadableFileError`, whose one-line message names the file and what is wrong with it.

    Args:
        source (str or Path): a run directory, a checkpoint or a policy file.

    Raises:
        FileNotFoundError: there is no such file.
        UnreadableFileError: the file does not load, or does not hold a whole policy.

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
    return read_policy(source)[0]


def policy_from_state(state: dict[str, Any]) -> TensorDictSequential:
    """The deterministic policy of a :func:`read_policy_state` (for callers that also need its ``env``).

    Args:
        state (dict): a :func:`read_policy_state`.
    """
    weights = [value for key, value in state["actor"].items() if key.endswith("weight")]
    obs_dim, goal_dim = state["normalizer"]["obs.sum"].numel(), state["normalizer"]["goal.sum"].numel()
    normalizer = ObsGoalNormalizer(obs_dim, goal_dim)
    normalizer.load_state_dict(state["normalizer"])
    actor = make_actor(obs_dim + goal_dim, weights[-1].shape[0], state["hidden"])
    actor.load_state_dict(state["actor"])
    return TensorDictSequential(normalizer, actor).eval()
