"""Episode-level prioritised sampling over a ``[episode, t]`` TorchRL storage.

Every sampler here draws an *episode row* with probability proportional to a
priority computed when the episode is written (MEP's ranks also change with
every write and refit), and then a step inside it. Priorities live in a sum
segment tree (TorchRL's C++ one), so a draw costs O(batch x log episodes) and
never rescans the buffer. Episodes may end before
their row does (an ``("next", "done")`` flag before ``T``): the steps after the
end are padding, which priorities ignore and draws never return.
"""
from __future__ import annotations

import abc
import json
import math
import os
from multiprocessing.context import get_spawning_popen
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.samplers import Sampler, SumSegmentTreeFp64
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import episode_lengths, shared_length, stored_lengths, valid_steps
from torchrl_cebp.replay.storage import RowWriteWatch

FLOAT32_EPS = float(torch.finfo(torch.float32).eps)
# TorchRL's samplers' words for it, so that code catching theirs catches ours.
EMPTY_STORAGE_ERROR = "Cannot sample from an empty storage."


def require_key(
    episodes: TensorDictBase, key: NestedKey, trailing_shape: tuple[int | None, ...]
) -> torch.Tensor:
    """Returns ``episodes[key]`` after checking it is there with shape ``[n, T, *trailing_shape]``.

    ``None`` in ``trailing_shape`` accepts any size in that dimension.

    Examples:
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"next": {"touch": torch.zeros(2, 50, 2)}}, [2, 50])
        >>> require_key(td, ("next", "touch"), (2,)).shape
        torch.Size([2, 50, 2])
    """
    value = episodes.get(key, None)
    if value is None:
        raise KeyError(
            f"episode data has no key {key!r} (expected shape {_shape_text(trailing_shape)}); "
            f"present keys: {sorted(map(str, episodes.keys(True, True)))}"
        )
    if value.ndim != 2 + len(trailing_shape) or any(
        want is not None and got != want for got, want in zip(value.shape[2:], trailing_shape)
    ):
        raise ValueError(
            f"key {key!r} has shape {list(value.shape)}, expected {_shape_text(trailing_shape)}"
        )
    return value


def _shape_text(trailing_shape: tuple[int | None, ...]) -> str:
    # Only built for an error: HER checks its keys on every draw.
    return "[n_episodes, T, " + ", ".join("*" if d is None else str(d) for d in trailing_shape) + "]"


def checked(owner: str, name: str, value: float, *, minimum: float = 0.0, exclusive: bool = False,
            maximum: float = math.inf) -> float:
    """``value`` as a float, after checking it lies in the allowed range (``minimum`` excluded if ``exclusive``).

    Examples:
        >>> checked("CEBPSampler", "beta", 1)
        1.0
        >>> checked("CEBPSampler", "beta", -1)
        Traceback (most recent call last):
        ...
        ValueError: CEBPSampler beta=-1.0: allowed values lie in [0.0, inf)
    """
    value = float(value)
    if not ((value > minimum if exclusive else value >= minimum) and value <= maximum):
        bounds = f"{'(' if exclusive else '['}{minimum}, {maximum}{')' if maximum == math.inf else ']'}"
        raise ValueError(f"{owner} {name}={value!r}: allowed values lie in {bounds}")
    return value


def batch_normalised_weights(probabilities: torch.Tensor, n_episodes: int, beta: float) -> torch.Tensor:
    """Importance-sampling weights ``(N p)^-beta`` of drawn episodes, over the batch's largest (PER's form).

    Examples:
        >>> batch_normalised_weights(torch.tensor([0.5, 0.25]), 2, 1.0).tolist()
        [0.5, 1.0]
    """
    weights = (n_episodes * probabilities) ** (-beta)
    return weights / weights.max()


def episode_positions(
    episodes: TensorDictBase, position_key: NestedKey, next_position_key: NestedKey
) -> torch.Tensor:
    """Stacks the state before step 0 with every next-state: ``[n, T + 1, 3]``.

    Examples:
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"achieved_goal": torch.zeros(1, 4, 3),
        ...                  "next": {"achieved_goal": torch.ones(1, 4, 3)}}, [1, 4])
        >>> episode_positions(td, "achieved_goal", ("next", "achieved_goal")).shape
        torch.Size([1, 5, 3])
    """
    first = require_key(episodes, position_key, (3,))[:, :1]
    following = require_key(episodes, next_position_key, (3,))
    return torch.cat([first, following], dim=1).double()


def stored_rows(index: torch.Tensor) -> torch.Tensor:
    """Episode rows touched by a write, in order, from the ``[n * T, 2]`` index a buffer reports.

    Examples:
        >>> stored_rows(torch.tensor([[3, 0], [3, 1], [0, 0], [0, 1]])).tolist()
        [0, 3]
    """
    index = torch.as_tensor(index)
    rows = (index[..., 0] if index.ndim > 1 else index).reshape(-1)
    # A buffer's index lists each row's steps together: collapsing those runs first leaves one entry a row.
    return torch.unique(rows.unique_consecutive())


def split_index(index: torch.Tensor | tuple) -> tuple[torch.Tensor, torch.Tensor]:
    """Returns ``(rows, steps)`` from a ``(rows, steps)`` tuple or a ``[B, 2]`` tensor."""
    if isinstance(index, tuple):
        return index[0], index[1]
    return index[..., 0], index[..., 1]


@runtime_checkable
class EpisodeSampler(Protocol):
    """What a sampler that draws whole episodes answers besides TorchRL's :class:`~torchrl.data.replay_buffers.Sampler`.

    Every :class:`EpisodePrioritySampler` is one, and so is a
    :class:`~torchrl_cebp.replay.samplers.PerWorkerSampler` of them. A trainer reads it to log the draw's spread
    and to refit a density model (MEP) once an epoch.

    Examples:
        >>> from torchrl.data import RandomSampler
        >>> from torchrl_cebp.replay.samplers import UniformEpisodeSampler
        >>> isinstance(UniformEpisodeSampler(), EpisodeSampler), isinstance(RandomSampler(), EpisodeSampler)
        (True, False)
    """

    @property
    def n_episodes(self) -> int:
        """Episode rows written so far."""

    def probabilities(self, rows: torch.Tensor) -> torch.Tensor:
        """Probability that one draw takes each of ``rows``."""

    def refit(self, storage: Storage) -> None:
        """Re-ranks the stored episodes from the whole ``storage`` (once an epoch)."""


class EpisodePrioritySampler(Sampler, abc.ABC):
    """Base class: draws episode rows by a per-episode priority, then a step.

    Subclasses implement :meth:`episode_priority`, mapping the ``[n, T]``
    tensordict of freshly written episodes and its ``[n, T]`` mask of valid
    (non-padding) steps to ``n`` non-negative priorities, and may override
    :meth:`step_weights` (non-uniform steps) and :meth:`importance_weights`. Works with a stock
    :class:`~torchrl.data.TensorDictReplayBuffer` over
    ``LazyTensorStorage(capacity_in_transitions, ndim=2)``: the buffer's
    writer notifies the sampler through :meth:`mark_update` after each write,
    which is when the priority of each written episode is computed. A sampler
    given a storage that already holds episodes scores them all when it first
    meets it. Priorities live in the process that draws: sent with the buffer
    to a spawned process (a collector's ``replay_buffer=``), the sampler leaves
    the episodes written there to the drawing process, which scores them at its
    next draw from the storage's shared row counts
    (:class:`~torchrl_cebp.replay.storage.RowWrites`); a forked copy, or a storage
    that keeps no such counts, refuses with the supported way.

    Args:
        end_key (NestedKey): the flag that ends an episode before its row does.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> class LongestReach(EpisodePrioritySampler):
        ...     "Episodes whose object travelled further are drawn more often."
        ...     def episode_priority(self, episodes, valid):
        ...         path = episodes["next", "achieved_goal"]
        ...         return (path[:, -1] - path[:, 0]).norm(dim=-1).double()
        >>> episodes = TensorDict({"next": {"achieved_goal": torch.zeros(2, 50, 3)}}, [2, 50])
        >>> episodes["next", "achieved_goal"][1, -1, 0] = 0.3  # only episode 1 moved the object
        >>> rb = TensorDictReplayBuffer(storage=EpisodeStorage(10 * 50), sampler=LongestReach(),
        ...                             batch_size=16, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> rb.sample()["index"][:, 0].unique().tolist()
        [1]
    """

    def __init__(self, end_key: NestedKey = ("next", "done")) -> None:
        self.end_key = end_key
        self._priorities = torch.zeros(0, dtype=torch.float64)
        self._cumulative_step_weights: torch.Tensor | None = None
        self._tree: SumSegmentTreeFp64 | None = None
        self._n_stored = 0
        self._owner_pid = os.getpid()
        self._spawned_copy = False  # sent to another process, where it leaves each write to the owner
        self._writes_watch: RowWriteWatch | None = None

    # ---- what subclasses define -------------------------------------------------
    @abc.abstractmethod
    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Priority of each episode of a ``[n, T]`` tensordict (shape ``[n]``, >= 0) from its ``valid`` steps."""

    def step_weights(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor | None:
        """Per-step sampling weights ``[n, T]`` (0 on padding), or ``None`` for uniform valid steps."""
        return None

    def importance_weights(
        self, probabilities: torch.Tensor, n_episodes: int
    ) -> torch.Tensor | None:
        """IS weights of the drawn episodes, or ``None`` when the method uses none."""
        return None

    def episode_keys(self) -> dict[NestedKey, tuple[int | None, ...]]:
        """The entries :meth:`episode_priority` and :meth:`step_weights` read, with their per-step shapes."""
        return {}

    def check_episodes(self, episodes: TensorDictBase) -> None:
        """Refuses ``[n, T]`` episodes that lack an entry this sampler reads, naming it and its shape.

        The episode storages call it before they store a write, so that a write this sampler cannot
        score stores nothing.
        """
        for key, shape in self.episode_keys().items():
            require_key(episodes, key, shape)

    def refit(self, storage: Storage) -> None:
        """Re-ranks the stored episodes from the whole ``storage``; a trainer calls it once per epoch.

        Priorities fixed at write time need nothing here; a density model (MEP) refits on it.
        """

    # ---- TorchRL sampler interface ----------------------------------------------
    @property
    def n_episodes(self) -> int:
        """Number of episode rows written so far (at most the storage's rows)."""
        return self._n_stored

    def _ensure_tree(self, storage: Storage) -> None:
        # The storage's row count is fixed once it holds data: one tree for its lifetime.
        n_rows = storage.max_size // storage.shape[1]
        if self._tree is None:
            self._tree = SumSegmentTreeFp64(n_rows)
            self._priorities = torch.zeros(n_rows, dtype=torch.float64)
        elif self._tree.size != n_rows:
            raise ValueError(
                f"{type(self).__name__} holds priorities for {self._tree.size} episode rows (of another buffer, "
                f"or loaded from the state of one), but this storage has {n_rows}: use one sampler per buffer"
            )

    def mark_update(
        self, index: torch.Tensor | int, *, storage: Storage | None = None
    ) -> None:
        if storage is None:
            raise RuntimeError(
                f"{type(self).__name__} computes priorities from the written episodes and "
                "needs the storage: use it inside a replay buffer whose writer notifies it."
            )
        if os.getpid() != self._owner_pid:
            if self._spawned_copy and getattr(storage, "row_writes", None) is not None:
                return  # the storage counted the write in memory the owner shares: it scores the rows at its next draw
            raise RuntimeError(
                f"{type(self).__name__} keeps its priorities in process {self._owner_pid}, which draws, and cannot "
                f"learn of the episodes process {os.getpid()} writes: a forked process, or a storage without shared "
                "row counts, leaves it none. Send the buffer over an EpisodeStorage (or EpisodeMemmapStorage) to a "
                "spawned process (torch.multiprocessing's 'spawn', a collector's replay_buffer=), or extend it in the "
                "process that samples it, with the collector's batches (writer=EpisodeWriter(T) assembles their "
                "episodes)."
            )
        watch = self._watch(storage)
        # On first meeting a storage, the rows it held before count as written now.
        rows = stored_rows(index) if self._tree is not None else torch.arange(storage.shape[0])
        self._score_rows(rows, storage)
        if watch is not None:
            watch.saw(rows)

    def _watch(self, storage: Storage) -> RowWriteWatch | None:
        """This sampler's watch of the storage's row counts (``None`` for a storage without them)."""
        writes = getattr(storage, "row_writes", None)
        if writes is None:
            return None
        if self._writes_watch is None or self._writes_watch.writes is not writes:
            self._writes_watch = writes.watch()
        return self._writes_watch

    def _catch_up(self, storage: Storage) -> None:
        """Scores the rows no write told this sampler of: all the storage holds when it first meets it, then the
        rows other processes write (O(rows) after such a write, one shared read when there was none)."""
        watch = self._watch(storage)
        if self._tree is None:
            if len(storage):
                self._score_rows(torch.arange(storage.shape[0]), storage)
            return
        if watch is not None:
            rows = watch.new_rows()
            if rows.numel():
                self._score_rows(rows, storage)

    def _score_rows(self, rows: torch.Tensor, storage: Storage) -> None:
        if getattr(storage, "ndim", 1) != 2:
            raise ValueError(
                f"{type(self).__name__} needs an episode storage with ndim=2 "
                f"(rows = episodes, columns = steps), got ndim={getattr(storage, 'ndim', 1)}"
            )
        first, last = int(rows[0]), int(rows[-1])
        # A write is usually one run of consecutive rows: read it as a view, not a copy.
        episodes = storage.get(slice(first, last + 1)) if last - first + 1 == rows.numel() else storage.get(rows)
        self._ensure_tree(storage)
        self.write_priorities(rows, episodes, stored_lengths(storage, rows, self.end_key))

    def write_priorities(
        self, rows: torch.Tensor, episodes: TensorDictBase, lengths: torch.Tensor | None = None
    ) -> None:
        """Computes and stores the priorities of ``episodes`` written at ``rows``.

        Args:
            rows (torch.Tensor): where they are stored.
            episodes (TensorDictBase): the ``[n, T]`` episodes.
            lengths (torch.Tensor, optional): their valid lengths. Defaults to reading them from their flags.
        """
        if lengths is None:
            lengths = episode_lengths(episodes, self.end_key)
        valid = valid_steps(lengths, episodes.shape[1])
        priority = self.episode_priority(episodes, valid).to(torch.float64)
        if priority.shape != rows.shape or not torch.isfinite(priority).all() or (priority < 0).any():
            raise ValueError(
                f"{type(self).__name__}.episode_priority must give {rows.numel()} finite "
                f"non-negative priorities, got {priority}"
            )
        self.set_priorities(rows, priority)
        steps = self.step_weights(episodes, valid)
        if steps is not None:
            if self._cumulative_step_weights is None:
                self._cumulative_step_weights = torch.zeros(
                    self._priorities.numel(), episodes.shape[1], dtype=torch.float64
                )
            self._cumulative_step_weights[rows] = steps.double().cumsum(-1)
        self._n_stored = max(self._n_stored, int(rows.max()) + 1)

    def set_priorities(self, rows: torch.Tensor, priority: torch.Tensor) -> None:
        """Overwrites the priorities of ``rows`` (used on write, and by samplers that re-rank)."""
        self._priorities[rows] = priority
        self._tree[rows] = priority

    def _uniform(self, *shape: int) -> torch.Tensor:
        return torch.rand(*shape, generator=_upstream.sampler_generator(self), dtype=torch.float64)

    def draw_episodes(self, batch_size: int) -> torch.Tensor:
        """Episode rows drawn proportionally to their priority (O(batch x log rows))."""
        total = self._tree.query(0, self._tree.size)
        if not total > 0:
            raise RuntimeError(
                f"{type(self).__name__}: every stored episode has priority 0, nothing to draw"
            )
        mass = self._uniform(batch_size) * total
        rows = self._tree.scan_lower_bound(mass)
        # Float round-off at the very top of the range can land past the last stored row.
        return rows.clamp_(max=self._n_stored - 1)

    def draw_steps(self, rows: torch.Tensor, storage: Storage) -> torch.Tensor:
        """A valid step per drawn row: uniform, or by the cumulative step weights; the storage knows the lengths."""
        if self._cumulative_step_weights is None:
            shared = shared_length(storage, self.end_key)
            if shared is not None:
                return torch.randint(shared, rows.shape, generator=_upstream.sampler_generator(self))
        lengths = stored_lengths(storage, rows, self.end_key)
        if self._cumulative_step_weights is None:
            return (self._uniform(rows.numel()) * lengths).long().clamp_(max=lengths - 1)
        cumulative = self._cumulative_step_weights[rows]
        mass = self._uniform(rows.numel(), 1) * cumulative[:, -1:]
        steps = torch.searchsorted(cumulative, mass, right=True).squeeze(-1)
        return torch.minimum(steps, lengths - 1)

    def probabilities(self, rows: torch.Tensor) -> torch.Tensor:
        """Probability of drawing each of ``rows`` under the current priorities."""
        return self._priorities[rows] / self._tree.query(0, self._tree.size)

    def sample(self, storage: Storage, batch_size: int) -> tuple[tuple, dict]:
        self._catch_up(storage)
        if self._n_stored == 0:
            raise RuntimeError(EMPTY_STORAGE_ERROR)
        rows = self.draw_episodes(batch_size)
        steps = self.draw_steps(rows, storage)
        info: dict[str, Any] = {}
        # Without an importance_weights of its own a sampler uses none: its draws skip the probabilities
        # (some 4% of a uniform draw of 256).
        if type(self).importance_weights is not EpisodePrioritySampler.importance_weights:
            weights = self.importance_weights(self.probabilities(rows), self._n_stored)
            if weights is not None:
                info["priority_weight"] = weights.to(torch.float32)
        return (rows, steps), info

    # ---- state --------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        state = {"priorities": self._priorities.clone(), "n_stored": self._n_stored}
        if self._cumulative_step_weights is not None:
            state["cumulative_step_weights"] = self._cumulative_step_weights.clone()
        return state

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        # Older states also carry the valid lengths, which the storage keeps: they are left unread.
        self._priorities = state_dict["priorities"].clone().to(torch.float64)
        self._n_stored = int(state_dict["n_stored"])
        steps = state_dict.get("cumulative_step_weights")
        self._cumulative_step_weights = None if steps is None else steps.clone()
        self._tree = SumSegmentTreeFp64(self._priorities.numel())
        if self._priorities.numel():
            self._tree[torch.arange(self._priorities.numel())] = self._priorities
        self._writes_watch = None  # the state matches the storage's rows as they are now

    def _owner_only_state(self) -> dict[str, Any]:
        """What a spawned copy holds in place of the per-row state only the drawing process keeps."""
        return dict(_priorities=torch.zeros(0, dtype=torch.float64), _tree=None,
                    _cumulative_step_weights=None, _n_stored=0,
                    _writes_watch=None)

    def __getstate__(self) -> dict[str, Any]:
        state = super().__getstate__()
        if get_spawning_popen() is not None:  # sent to a new process, which writes and leaves the scoring to this one
            # Without this process's priorities: torch would share them, and an rb.empty() there would clear them.
            state.update(_spawned_copy=True, **self._owner_only_state())
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if not state.get("_spawned_copy"):  # a copy (deepcopy, unpickled elsewhere) belongs to the process that made it
            self._owner_pid = os.getpid()

    def _empty(self) -> None:
        self._priorities.zero_()
        if self._tree is not None:
            self._tree = SumSegmentTreeFp64(self._priorities.numel())
        self._cumulative_step_weights = None
        self._n_stored = 0

    def dumps(self, path: str | Path) -> None:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        state = self.state_dict()
        tensors = {k: v for k, v in state.items() if isinstance(v, torch.Tensor)}
        torch.save(tensors, path / "sampler_tensors.pt")
        others = {k: v for k, v in state.items() if not isinstance(v, torch.Tensor)}
        (path / "sampler_metadata.json").write_text(json.dumps(others))

    def loads(self, path: str | Path) -> None:
        path = Path(path)
        state = torch.load(path / "sampler_tensors.pt", weights_only=True)
        state.update(json.loads((path / "sampler_metadata.json").read_text()))
        self.load_state_dict(state)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_episodes={self._n_stored})"
