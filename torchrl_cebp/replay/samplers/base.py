"""Episode-level prioritised sampling: an episode row by its priority (a sum tree, O(log episodes)), then a step.

The steps after an episode's end flag are padding: priorities ignore them and draws never return them.
"""
from __future__ import annotations

import abc
import inspect
import math
import weakref
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.samplers import Sampler, SumSegmentTreeFp64
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import episode_lengths, shared_length, stored_lengths, valid_steps

FLOAT32_EPS = float(torch.finfo(torch.float32).eps)
# TorchRL's samplers' words for it, so that code catching theirs catches ours.
EMPTY_STORAGE_ERROR = "Cannot sample from an empty storage."
# What dumps() writes into its folder: the state_dict, which torch.load(weights_only=True) reads back.
SAMPLER_STATE_FILE = "sampler_state.pt"


# Where a sampler's state names the kind and arguments of the sampler that saved it.
SAMPLER_KEY = "sampler"


def sampler_identity(sampler: Sampler, *, changing: tuple[str, ...] = ()) -> dict[str, Any]:
    """The sampler's class and the arguments it was built with, as its attributes of the same names hold them.

    A state's priorities are valid only for a sampler of the same kind and arguments (CEBP's temperature, CPER's
    step weights): every state of this package's samplers carries this under ``"sampler"``. The arguments are
    those of the ``__init__`` of each class of the sampler outside TorchRL, whose values are plain (numbers, strings,
    keys); ``changing`` names those that change as it runs (PER's annealed ``beta``).

    Examples:
        >>> from torchrl_cebp.replay.samplers import CPERSampler
        >>> identity = sampler_identity(CPERSampler(lam=5.0))
        >>> identity["kind"], identity["arguments"]["lam"], identity["arguments"]["touch_key"]
        ('CPERSampler', 5.0, ('next', 'touch'))
    """
    arguments: dict[str, Any] = {}
    for cls in type(sampler).__mro__:
        if cls.__module__.startswith("torchrl.") or "__init__" not in cls.__dict__:
            continue  # TorchRL's arguments are its state's own (PER's alpha, beta and eps are in it)
        for name, parameter in inspect.signature(cls.__init__).parameters.items():
            if (name == "self" or name in changing or name in arguments
                    or parameter.kind in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD)):
                continue
            value = getattr(sampler, name, _ABSENT)
            if value is not _ABSENT and _is_plain(value):
                arguments[name] = value
    return {"kind": type(sampler).__qualname__, "arguments": arguments}


def require_same_sampler(sampler: Sampler, state: dict[str, Any], *, changing: tuple[str, ...] = ()) -> None:
    """Refuses a state saved by a sampler of another kind or other arguments (``sampler_identity``), naming both.

    A state without one (TorchRL's own samplers', or saved before states named their sampler) is taken as it is.

    Raises:
        ValueError: the state's sampler differs from ``sampler``.
    """
    saved = state.get(SAMPLER_KEY)
    own = sampler_identity(sampler, changing=changing)
    if saved is not None and saved != own:
        raise ValueError(f"the state was saved by {_described(saved)}, but is loaded into {_described(own)}: its "
                         "priorities hold only for a sampler of the same kind and arguments. Load it into a sampler "
                         "built as the saved one was, or start this sampler empty (a new run)")


_ABSENT = object()  # an argument the sampler keeps under another name (PER's capacity: max_size)


def _described(identity: dict[str, Any]) -> str:
    arguments = ", ".join(f"{name}={value!r}" for name, value in identity["arguments"].items())
    return f"{identity['kind']}({arguments})"


def _is_plain(value: Any) -> bool:
    if isinstance(value, (tuple, list)):
        return all(map(_is_plain, value))
    return value is None or isinstance(value, (bool, int, float, str))


def dump_state(sampler: Sampler, path: str | Path) -> None:
    """The ``dumps`` of this package's samplers: ``sampler.state_dict()`` into a folder (PER keeps TorchRL's)."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    torch.save(sampler.state_dict(), path / SAMPLER_STATE_FILE)


def load_state(sampler: Sampler, path: str | Path) -> None:
    """The ``loads`` of this package's samplers: what :func:`dump_state` wrote."""
    sampler.load_state_dict(torch.load(Path(path) / SAMPLER_STATE_FILE, weights_only=True))


def require_key(episodes: TensorDictBase, key: NestedKey, trailing_shape: tuple[int | None, ...]) -> torch.Tensor:
    """``episodes[key]``, refused unless it is there with shape ``[n, T, *trailing_shape]`` (``None``: any size)."""
    value = episodes.get(key, None)
    if value is None:
        raise KeyError(f"episode data has no key {key!r} (expected shape {_shape_text(trailing_shape)}); "
                       f"present keys: {sorted(map(str, episodes.keys(True, True)))}")
    if value.ndim != 2 + len(trailing_shape) or value.shape[2:] != trailing_shape and any(  # zip() only for wildcards
        want is not None and got != want for got, want in zip(value.shape[2:], trailing_shape)
    ):
        raise ValueError(f"key {key!r} has shape {list(value.shape)}, expected {_shape_text(trailing_shape)}")
    return value


def _shape_text(trailing_shape: tuple[int | None, ...]) -> str:
    # Only built for an error: HER checks its keys on every draw.
    return "[n_episodes, T, " + ", ".join("*" if d is None else str(d) for d in trailing_shape) + "]"


def checked(owner: str, name: str, value: float, *, minimum: float = 0.0, exclusive: bool = False,
            maximum: float = math.inf) -> float:
    """``value`` as a float, refused with a message naming it and the range unless it lies in the range.

    Examples:
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
    """Importance-sampling weights ``(N p)^-beta`` of the drawn episodes over the batch's largest (PER's form)."""
    weights = (n_episodes * probabilities).pow_(-beta)
    return weights.div_(weights.max()) if weights.numel() else weights  # a draw of none (TorchRL's sample(0))


def episode_positions(episodes: TensorDictBase, position_key: NestedKey, next_position_key: NestedKey) -> torch.Tensor:
    """The float64 ``[n, T + 1, 3]`` positions: the one before step 0, then each next position."""
    first = require_key(episodes, position_key, (3,))[:, :1]
    following = require_key(episodes, next_position_key, (3,))
    return torch.cat([first, following], dim=1).double()


def stored_rows(index: torch.Tensor) -> torch.Tensor:
    """The sorted episode rows of a write's ``[n * T, 2]`` index (or of a 1-d index of rows)."""
    index = torch.as_tensor(index)
    rows = (index.select(-1, 0) if index.ndim > 1 else index).flatten()
    # A buffer's index lists each row's steps together: collapsing those runs first leaves one entry a row.
    runs = rows.unique_consecutive()
    return runs if runs.numel() == 1 else torch.unique(runs)


def split_index(index: torch.Tensor | tuple) -> tuple[torch.Tensor, torch.Tensor]:
    """``(rows, steps)`` of a sampled index, a ``(rows, steps)`` tuple or a ``[B, 2]`` tensor."""
    if isinstance(index, tuple):
        return index[0], index[1]
    return index[..., 0], index[..., 1]


@runtime_checkable
class EpisodeSampler(Protocol):
    """What a sampler of whole episodes answers besides TorchRL's :class:`~torchrl.data.replay_buffers.Sampler`.

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
    """Base class: draws an episode row by a per-episode priority, then a valid step of it.

    Subclasses implement :meth:`episode_priority`, and may override :meth:`step_weights` and
    :meth:`importance_weights`. At each write and each draw the sampler scores the rows whose write count changed,
    whichever process wrote them (an episode storage's ``write_counts``; over TorchRL's ``LazyTensorStorage(ndim=2)``
    it counts the writes its buffer tells it of).

    Args:
        end_key (NestedKey, optional): the flag that ends an episode before its row does.
            Defaults to ``("next", "done")``.

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
        self._priorities = torch.zeros(0, dtype=torch.float64)  # the tree's leaves: a draw reads them faster here
        self._cumulative_step_weights: torch.Tensor | None = None
        self._tree: SumSegmentTreeFp64 | None = None
        self._n_stored = 0
        self._seen: torch.Tensor | None = None  # the storage's write counts as last scored (-1: to score)
        self._writes: torch.Tensor | None = None  # the write counts of a storage that keeps none
        self._scored_storage: weakref.ref | None = None  # None: a new, restored or copied sampler takes the next one

    # ---- what subclasses define -------------------------------------------------
    @abc.abstractmethod
    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Priority of each episode of a ``[n, T]`` tensordict (shape ``[n]``, >= 0) from its ``valid`` steps."""

    def step_weights(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor | None:
        """Per-step sampling weights ``[n, T]`` (0 on padding), or ``None`` for uniform valid steps."""
        return None

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor | None:
        """IS weights of the drawn episodes, or ``None`` when the method uses none."""
        return None

    def episode_keys(self) -> dict[NestedKey, tuple[int | None, ...]]:
        """The entries :meth:`episode_priority` and :meth:`step_weights` read, with their per-step shapes."""
        return {}

    def check_episodes(self, episodes: TensorDictBase) -> None:
        """Refuses ``[n, T]`` episodes that lack an entry this sampler reads; episode storages ask before a write."""
        for key, shape in self.episode_keys().items():
            require_key(episodes, key, shape)

    def refit(self, storage: Storage) -> None:
        """Re-ranks the stored episodes from the whole ``storage`` once an epoch (MEP's density model)."""

    # ---- TorchRL sampler interface ----------------------------------------------
    @property
    def n_episodes(self) -> int:
        """Number of episode rows written so far (at most the storage's rows)."""
        return self._n_stored

    def _make_tree(self, storage: Storage) -> None:
        """The priorities' tree for the rows of a storage met for the first time (fixed once it holds data)."""
        n_rows = storage.max_size // storage.shape[1]
        if self._tree is None:
            self._tree = SumSegmentTreeFp64(n_rows)
            self._priorities = torch.zeros(n_rows, dtype=torch.float64)
        elif self._tree.size != n_rows:
            raise ValueError(f"{type(self).__name__} holds priorities for {self._tree.size} episode rows (of another "
                             f"buffer, or loaded from the state of one), but this storage has {n_rows}: use one "
                             "sampler per buffer")

    def mark_update(self, index: torch.Tensor | int, *, storage: Storage | None = None) -> None:
        """Scores the episodes a write just stored, on the buffer's notice after each write.

        Rows that another process wrote since the last look are scored too: their write counts changed.

        Args:
            index (torch.Tensor or int): the written rows: a write's ``[n * T, 2]`` index, or a 1-d index of rows.
            storage (Storage): the buffer's episode storage, from which the priorities are computed.

        Raises:
            RuntimeError: no ``storage``.
            ValueError: ``storage`` is not the one this sampler scores (one sampler per buffer), or not ``ndim=2``.
        """
        if storage is None:
            raise RuntimeError(f"{type(self).__name__} computes priorities from the written episodes and "
                               "needs the storage: use it inside a replay buffer whose writer notifies it.")
        rows, counts = stored_rows(index), self._write_counts(storage)
        if counts is self._writes:
            counts[rows] += 1
            counts[-1] += 2
        self._catch_up(storage, rows)

    def _write_counts(self, storage: Storage) -> torch.Tensor:
        """Each row's write count, then of write starts and ends: the storage's, or this sampler's if it keeps none."""
        if self._scored_storage is None:
            self._scored_storage = weakref.ref(storage)
        elif self._scored_storage() is not storage:  # every write and draw asks here first: refused before either
            raise ValueError(f"{type(self).__name__} scores the episodes of another storage, not of this "
                             f"{type(storage).__name__}: use one sampler per buffer (a new one, or one given a state)")
        counts = getattr(storage, "write_counts", None)
        if counts is not None:
            return counts
        if getattr(storage, "ndim", 1) != 2:
            raise ValueError(f"{type(self).__name__} needs an episode storage with ndim=2 "
                             f"(rows = episodes, columns = steps), got ndim={getattr(storage, 'ndim', 1)}")
        n_rows = storage.max_size // storage.shape[1]
        if self._writes is None or self._writes.numel() != n_rows + 1:
            self._writes = torch.zeros(n_rows + 1, dtype=torch.long)
        return self._writes

    def _catch_up(self, storage: Storage, written: torch.Tensor | None = None) -> None:
        """Scores the rows whose write count changed since they were last scored: only the ``written`` rows when
        theirs is the one write since, none when there was none. While a write runs, or if one ran while
        scoring, the rows are scored at the next look."""
        if self._seen is None and not len(storage):
            return
        counts = self._write_counts(storage)
        if self._seen is None or self._seen.numel() != counts.numel():
            # First meeting: every filled row is new. Restored from a state: the state holds all but the rows
            # written since. A storage of another size is refused.
            stale = slice(0, storage.shape[0]) if self._tree is None else written
            self._make_tree(storage)
            self._seen = counts.clone()
            if stale is not None:
                self._seen[stale] = self._seen[-1] = -1
        writes, seen = int(counts[-1]), int(self._seen[-1])
        if writes == seen or writes % 2:
            return
        if written is not None and writes == seen + 2:
            changed = written
        else:
            changed = (counts[:-1] != self._seen[:-1]).nonzero().squeeze(-1)
        if changed.numel():  # none: a write into other rows (another worker's)
            now = counts.index_select(0, changed)
            self._score_rows(changed, storage)
            if int(self._write_counts(storage)[-1]) != writes:  # read again: a worker's counts are a copy
                return
            self._seen.index_copy_(0, changed, now)
        self._seen[-1] = writes

    def _score_rows(self, rows: torch.Tensor, storage: Storage) -> None:
        # A write is usually one run of consecutive rows (often one row): read it as a view, not a copy.
        first, last = (int(rows),) * 2 if rows.numel() == 1 else (int(rows[0]), int(rows[-1]))
        episodes = storage.get(slice(first, last + 1)) if last - first + 1 == rows.numel() else storage.get(rows)
        self.write_priorities(rows, episodes, stored_lengths(storage, rows, self.end_key))

    def write_priorities(self, rows: torch.Tensor, episodes: TensorDictBase,
                         lengths: torch.Tensor | None = None) -> None:
        """Scores the ``[n, T]`` ``episodes`` stored at ``rows`` (their valid ``lengths`` read from their flags if
        not given)."""
        if lengths is None:
            lengths = episode_lengths(episodes, self.end_key)
        valid = valid_steps(lengths, episodes.shape[1])
        priority = self.episode_priority(episodes, valid).to(torch.float64)
        # One pass for both bounds: a NaN makes both NaN, which fails the first comparison.
        low, high = torch.aminmax(priority) if priority.numel() else (0.0, 0.0)
        if priority.shape != rows.shape or not (float(low) >= 0.0 and float(high) < math.inf):
            raise ValueError(f"{type(self).__name__}.episode_priority must give {rows.numel()} finite "
                             f"non-negative priorities, got {priority}")
        self.set_priorities(rows, priority)
        steps = self.step_weights(episodes, valid)
        if steps is not None:
            if self._cumulative_step_weights is None:
                self._cumulative_step_weights = torch.zeros(self._tree.size, episodes.shape[1], dtype=torch.float64)
            self._cumulative_step_weights[rows] = steps.double().cumsum(-1)
        self._n_stored = max(self._n_stored, int(rows.max()) + 1)

    def priorities(self) -> torch.Tensor:
        """Every row's priority (empty before the first write)."""
        return self._priorities.clone()

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
            raise RuntimeError(f"{type(self).__name__}: every stored episode has priority 0, nothing to draw")
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
        cumulative = self._cumulative_step_weights.index_select(0, rows)
        mass = self._uniform(rows.numel(), 1) * cumulative[:, -1:]
        steps = torch.searchsorted(cumulative, mass, right=True).squeeze(-1)
        return torch.minimum(steps, lengths - 1)

    def probabilities(self, rows: torch.Tensor) -> torch.Tensor:
        """Probability of drawing each of ``rows`` under the current priorities."""
        return self._priorities.index_select(0, rows) / self._tree.query(0, self._tree.size)

    def sample(self, storage: Storage, batch_size: int) -> tuple[tuple, dict]:
        """Draws ``batch_size`` episode rows by their priority, then a valid step of each.

        The rows written since the last look, by any process, are scored first.

        Args:
            storage (Storage): the buffer's episode storage.
            batch_size (int): the number of ``(row, step)`` pairs.

        Returns:
            ``((rows, steps), info)``, where ``info`` holds the drawn rows' IS weights (float32) under
            ``"priority_weight"`` for a sampler that uses them (:meth:`importance_weights`), else nothing.

        Raises:
            RuntimeError: the storage is empty, or every stored episode has priority 0.
        """
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
        """The priorities, the number of rows written and any cumulative step weights, as tensors and numbers that
        ``torch.load(weights_only=True)`` reads, and the sampler's kind and arguments (``sampler_identity``)."""
        state = {"priorities": self.priorities(), "n_stored": self._n_stored, SAMPLER_KEY: sampler_identity(self)}
        if self._cumulative_step_weights is not None:
            state["cumulative_step_weights"] = self._cumulative_step_weights.clone()
        return state

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Restores a :meth:`state_dict`, taken to match the rows of the storage the sampler meets next; rows written
        after that are scored as usual.

        Raises:
            ValueError: the state was saved by a sampler of another kind or other arguments.
        """
        require_same_sampler(self, state_dict)
        # Older states also carry the valid lengths, which the storage keeps: they are left unread.
        priorities = self._priorities = state_dict["priorities"].to(torch.float64).clone()
        self._n_stored = int(state_dict["n_stored"])
        steps = state_dict.get("cumulative_step_weights")
        self._cumulative_step_weights = None if steps is None else steps.clone()
        self._tree = None  # a state saved before any write: the tree is made for the storage it meets
        if priorities.numel():
            self._tree = SumSegmentTreeFp64(priorities.numel())
            self._tree[torch.arange(priorities.numel())] = priorities
        self._seen = self._scored_storage = None  # the state matches the rows of the storage it meets next

    def __getstate__(self) -> dict[str, Any]:
        # A weakref neither pickles nor copies: the copy takes the storage it meets first, its buffer's copy.
        return {**super().__getstate__(), "_scored_storage": None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        # Torch sends every tensor as shared memory: each process scores into its own, and shares only the write
        # counts it keeps for a storage that keeps none.
        self.__dict__.update({name: value.clone() if isinstance(value, torch.Tensor) and name != "_writes" else value
                              for name, value in state.items()})

    def _empty(self) -> None:
        self._priorities.zero_()
        if self._tree is not None:
            self._tree = SumSegmentTreeFp64(self._tree.size)
        self._cumulative_step_weights = None
        self._n_stored = 0

    dumps = dump_state
    loads = load_state

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_episodes={self._n_stored})"
