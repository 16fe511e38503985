"""Storage of whole episodes as rows of a TorchRL tensor storage."""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from multiprocessing.context import get_spawning_popen
from typing import Any, NamedTuple

import torch
from tensordict import TensorDict, TensorDictBase, is_non_tensor
from tensordict.utils import NestedKey
from torchrl.data import LazyMemmapStorage, LazyTensorStorage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import common_length, end_flags, episode_lengths, lengths_of_ends, require_time_at

# What a write of frames instead of episode rows needs.
ASSEMBLE_FRAMES = (
    "a batch of frames (a collector's) needs its episodes assembled, "
    "e.g. TensorDictReplayBuffer(..., writer=EpisodeWriter(env.max_episode_steps), dim_extend=0)"
)


def episode_rows(capacity: int, episode_steps: int) -> int:
    """Rows an episode storage holds for episodes of a given length.

    ``ceil(capacity / T)``: TorchRL's ``LazyTensorStorage`` with ``ndim=2`` rounds up to whole rows, and raises its
    ``max_size`` to match.

    Args:
        capacity (int): the storage size in transitions.
        episode_steps (int): ``T``, the steps of each episode row.

    Example:
        >>> episode_rows(1_000_000, 50), episode_rows(1_000_000, 70)
        (20000, 14286)
    """
    return -(capacity // -episode_steps)


class _EpisodeRows:
    """Writes must be whole episodes of one fixed length; each row's valid length and write count are kept.

    The lengths and :attr:`write_counts` are memory every process holding the storage shares (torch shares
    every CPU tensor it sends to a spawned process). A reader that finds the last count even and unchanged
    across its reads read one version of each row: writes take turns (TorchRL's cursor is one per buffer).
    """

    end_key: NestedKey = ("next", "done")
    _stored_keys: tuple[TensorDictBase, dict[tuple[str, ...], set[str]]] | None = None  # stored tensordict, its names
    _lengths: torch.Tensor | None = None  # per row; a row not written yet counts as whole
    _short_rows: torch.Tensor | None = None  # rows whose episode ends before the row does: while none, all share T
    _write_counts: torch.Tensor | None = None  # [rows + 1], from the first write on

    @property
    def write_counts(self) -> torch.Tensor | None:
        """Each row's write count, then the count of write starts and ends (odd while one runs); ``None`` if empty."""
        if self._lengths is None and self.initialized:
            self._read_lengths_if_unknown()
        return self._write_counts

    def valid_lengths(self, rows: torch.Tensor) -> torch.Tensor:
        """Valid steps of the episodes stored in ``rows``."""
        self._read_lengths_if_unknown()
        return self._lengths.index_select(0, rows)

    def common_length(self) -> int | None:
        """The valid length every row shares (the row length unless episodes end early), else ``None``."""
        if self._lengths is None:
            self._read_lengths_if_unknown()
        # A full pass only while every episode ends early: while some do and others not, none is common.
        short = int(self._short_rows)
        if not short:
            return self._steps
        return common_length(self._lengths) if short == self._lengths.numel() else None

    def _read_lengths_if_unknown(self) -> None:
        if self._lengths is None:  # first write, or restored from a checkpoint: read them from the flags once
            stored = _upstream.stored_tensordict(self)
            rows, row_length = stored.shape[:2]
            if self._write_counts is None:
                self._write_counts = torch.zeros(rows + 1, dtype=torch.long)
            # Only the filled rows are read: the others were never written, so their memory is never touched.
            self._lengths = torch.full((rows,), row_length, dtype=torch.long)
            self._short_rows = torch.zeros((), dtype=torch.long)
            filled = self.shape[0]
            self._set_lengths(torch.arange(filled), episode_lengths(stored[:filled], self.end_key))

    @property
    def _steps(self) -> int:
        """The row length (TorchRL's ``shape`` recomputes the filled rows on every call)."""
        return _upstream.stored_tensordict(self).shape[1]

    def _set_lengths(self, rows: torch.Tensor, lengths: torch.Tensor) -> None:
        row_length = self._steps
        if not int(self._short_rows) and bool((lengths == row_length).all()):
            return  # whole episodes over whole ones: nothing changes (the usual write)
        self._lengths[rows] = lengths
        # Counted again, not by difference: a write of more episodes than rows repeats rows, and only its last lands.
        self._short_rows.copy_(torch.count_nonzero(self._lengths < row_length))

    def set(self, cursor: Any, data: Any, *, set_cursor: bool = True) -> None:
        """Writes whole episodes into the rows ``cursor``, as TorchRL's storage does, and keeps each row's valid length
        and write count.

        Every check runs before any row changes, so that a refused write stores nothing (and rewinds the buffer's
        writer, if the write came from its ``extend``: a direct ``set`` moved none): the data must be ``[n, T]`` episodes of the storage's row length with one end flag each at most,
        hold every stored entry and no other, and pass the buffer's sampler's ``check_episodes``. Data that is not a
        tensordict goes to TorchRL's storage unchecked.

        Args:
            cursor (Any): the rows, as the buffer's writer gives them.
            data (Any): the episodes.
            set_cursor (bool, optional): TorchRL's flag, passed on. Defaults to ``True``.

        Raises:
            ValueError: rows that are not single episodes of the storage's length, or that the sampler refuses.
            KeyError: a write that lacks a stored entry or adds one, or lacks an entry the sampler reads.
            TypeError: a first write that holds entries other than tensors.
        """
        if not isinstance(data, TensorDictBase):
            return self._store(cursor, data, set_cursor, whole=False)
        known, counting = self._lengths is not None, False
        try:  # every check before any row changes (the store's of shapes too): a refused write stores nothing
            whole, lengths = self._check_rows(data)
            for buffer in _upstream.attached_buffers(self):
                check = getattr(buffer.sampler, "check_episodes", None)
                if check is not None:
                    check(data)
            if known:
                rows = cursor.reshape(-1) if isinstance(cursor, torch.Tensor) else (
                    torch.arange(self.max_size // self._steps)[cursor].reshape(-1))
                self._write_counts[-1].add_(1)  # odd while the rows change (add_: no copy back, as += makes)
                counting = True
            self._store(cursor, data, set_cursor, whole=whole)
            if known:
                self._set_lengths(rows, lengths)
        except Exception:
            if set_cursor and _written_by_round_robin_writer(cursor, data):
                _upstream.rewind_writers(self, cursor.reshape(-1))
            raise
        finally:
            if counting:
                self._write_counts[rows] += 1  # a row written twice in one write counts once: still a change
                self._write_counts[-1].add_(1)
        if not known:  # the first write: every filled row from its flags, each counted written
            self._read_lengths_if_unknown()
            self._count_written(slice(0, self.shape[0]))

    def _store(self, cursor: Any, data: Any, set_cursor: bool, *, whole: bool) -> None:
        """Writes ``data`` at ``cursor`` (``whole``: it holds every stored entry) as TorchRL's storage does."""
        super().set(cursor, data, set_cursor=set_cursor)

    def _check_rows(self, data: TensorDictBase) -> tuple[bool, torch.Tensor]:
        """Refuses a write whose rows cannot each be one episode of the storage's length; returns whether it holds
        every stored entry, and its episodes' valid lengths."""
        if data.ndim != 2:
            raise ValueError(f"episode storages take whole episodes shaped [n_episodes, T], got batch shape "
                             f"{list(data.shape)}: {ASSEMBLE_FRAMES}")
        require_time_at(data, 1, lambda: [buffer.dim_extend for buffer in _upstream.attached_buffers(self)])
        whole = self.initialized and self._check_keys(data)
        if not self.initialized and (objects := [k for k in data.keys(True) if is_non_tensor(data.get(k))]):
            raise TypeError(f"an episode storage keeps tensors only: exclude {sorted(map(str, objects))} before "
                            "writing")
        ends = end_flags(data, self.end_key)
        counts = None if ends is None else ends.sum(-1)
        if counts is not None and counts.numel() and int(counts.max()) > 1:
            crowded = int(counts.argmax())
            raise ValueError(f"row {crowded} of the batch of shape {list(data.shape)} holds {int(counts[crowded])} "
                             f"episode ends ({self.end_key!r} flags), but a row is one episode: {ASSEMBLE_FRAMES}")
        if self.initialized and data.shape[1] != self._steps:
            raise ValueError(f"episodes of {data.shape[1]} steps cannot go into a storage of {self._steps}-step "
                             "episodes")
        lengths = torch.full(data.shape[:1], data.shape[1], dtype=torch.long) if ends is None else lengths_of_ends(ends)
        return whole, lengths

    def _check_keys(self, data: TensorDictBase) -> bool:
        """Refuses a write that lacks a stored entry (its rows would keep the entry's old memory) or holds a new one (a
        draw reads the blocks laid out for the first write's entries); returns whether it holds every stored one."""
        stored = _upstream.stored_tensordict(self)
        if self._stored_keys is None or self._stored_keys[0] is not stored:
            self._stored_keys = stored, _names_by_node(stored.keys(True, True))
        # Each node's names (no nested iteration: it costs more than the write). TorchRL's writers add "index" to some
        # writes only, and its collectors add their "collector" ids to those after the first (they share only an
        # initialised storage): a write may hold either without storing it.
        nodes, whole, missing, new = self._stored_keys[1], True, [], []
        for path, names in nodes.items():
            present = _names_at(data, path)
            if present != names:
                whole = whole and names <= present
                missing += [(*path, n) for n in names - present - {"index"} if (*path, n) not in nodes]
                new += [(*path, n) for n in present - names - {"index", "collector"}]
        if missing or new:
            problems = [f"lacks {sorted(missing)}"] * bool(missing) + [f"adds {sorted(new)}"] * bool(new)
            raise KeyError(f"a write into an episode storage must hold every stored entry and no other: it "
                           f"{' and '.join(problems)}")
        return whole

    def state_dict(self) -> dict[str, Any]:
        """The storage's state with its filled rows only, so that a checkpoint grows with the stored episodes."""
        state = super().state_dict()
        if self.initialized:
            filled_rows = self.shape[0]
            state[_upstream.STORAGE_STATE_KEY] = self.get(slice(0, filled_rows)).apply(torch.clone).state_dict()
            state["rows"] = self.max_size // self.shape[1]
        return state

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Loads a :meth:`state_dict`, or a TorchRL storage's state (which holds every row), then counts every row
        written once, so that a sampler that meets the storage again scores it.

        Raises:
            ValueError: the state holds another number of episode rows: build the storage with its capacity.
        """
        if state_dict.get("initialized"):
            saved = TensorDict().load_state_dict(state_dict[_upstream.STORAGE_STATE_KEY], strict=False)
            # Our states keep the filled rows and the row count; TorchRL's (and older ones) every row.
            rows = state_dict.get("rows", saved.shape[0])
            self._adopt_saved_rows(rows, saved.shape[1])
            if "rows" in state_dict:  # the filled rows, back into a storage of the full capacity
                # Empty, not zeros: the unfilled rows' memory stays untouched until written.
                full = saved.apply(lambda t: torch.empty((rows, *t.shape[1:]), dtype=t.dtype),
                                   batch_size=[rows, *saved.shape[1:]])
                if memmap := isinstance(self, LazyMemmapStorage):  # into files in its scratch_dir, as a first write
                    full = self._memmap_into_scratch_dir(full)
                full[: saved.shape[0]] = saved
                state_dict = {**state_dict, _upstream.STORAGE_STATE_KEY: full.state_dict()}
                # TorchRL loads into a stored tensordict by reference (a memmap one: in place, into its own files),
                # where into none it clones every row (all of the capacity's memory); ``full`` is this storage's own.
                _upstream.replace_stored_tensordict(self, full if memmap else TensorDict())
        super().load_state_dict(state_dict)
        self._after_load()

    def _memmap_into_scratch_dir(self, data: TensorDictBase) -> TensorDictBase:
        # As TorchRL's first write into a LazyMemmapStorage: files already in the folder (another storage's, which may
        # be live) are refused unless existsok, not shared, so that two storages never read and write one file. A
        # written storage's files are its own (its first write refused any others), and it lays them out again.
        try:
            return data.memmap_like(prefix=self.scratch_dir, existsok=self.existsok or self.initialized)
        except RuntimeError as error:
            if "already exists" not in str(error):
                raise
            raise RuntimeError(f"scratch_dir {self.scratch_dir} already holds memory-mapped files ({error}): another "
                               "storage's, which would share them; give each storage a scratch_dir of its own") from None

    def loads(self, path: Any) -> None:
        """Loads what TorchRL's ``dumps`` wrote into ``path``, as :meth:`load_state_dict` loads a state.

        Raises:
            ValueError: the dump holds another number of episode rows: build the storage with its capacity.
        """
        saved_shape = TensorDict.load_memmap(path).shape  # memory-mapped: reading the shape loads no data
        if len(saved_shape) >= 2:
            self._adopt_saved_rows(saved_shape[0], saved_shape[1])
        super().loads(path)
        self._after_load()

    def _after_load(self) -> None:
        """Counts every row written once, so that a sampler meeting the storage again rescores it; reads the
        lengths now, not at the first write or draw, so that a process the storage is sent to shares them."""
        self._lengths = None
        self._count_written(slice(0, -1))
        if self.initialized:
            self._read_lengths_if_unknown()

    def _count_written(self, rows: slice) -> None:
        """Counts one write of ``rows`` (all of them, on a load: a sampler that meets the storage again scores it)."""
        if self._write_counts is not None:
            self._write_counts[rows] += 1
            self._write_counts[-1] += 2

    def _adopt_saved_rows(self, rows: int, row_length: int) -> None:
        """Takes the saved storage's whole-row size, as its first write did (TorchRL's loads keep the unrounded
        ``max_size``); refuses one of another number of rows: TorchRL would fail on the copy, or adopt its size."""
        own_rows = episode_rows(self.max_size, row_length)
        if rows != own_rows:
            raise ValueError(f"the saved buffer holds {rows} episodes of {row_length} steps (capacity "
                             f"{rows * row_length} transitions), this one {own_rows} (capacity {self.max_size}): "
                             f"build the buffer with capacity={rows * row_length} to load it")
        self.max_size = rows * row_length


class _Layout(NamedTuple):
    """What a draw reads the transition-major blocks with, for the stored tensordict ``source`` it replaced."""

    source: TensorDictBase
    blocks: list[tuple[torch.Tensor, list[int]]]  # per dtype: ``[rows * T, width]`` and its entries' widths
    # Per dtype: ``[rows, T, width]``, its keys as items() has them, and their per-step shapes and dtype.
    row_blocks: list[tuple[torch.Tensor, list[NestedKey], list[tuple[torch.Size, torch.dtype]]]]
    plan: list[tuple]  # how the gathered columns nest (_read_plan)
    n_nodes: int
    row_length: int  # TorchRL's storage.shape recomputes the filled rows on every read (~10% of a draw of 256)


@dataclass(frozen=True)
class _Field:
    path: tuple[str, ...]  # the entry's key
    dtype: torch.dtype
    start: int  # its columns in its dtype's block
    stop: int
    shape: torch.Size  # per transition


def _is_pair_index(index: Any) -> bool:
    # Spelled out rather than all(...) over the pair: a generator costs a microsecond per draw.
    return (isinstance(index, tuple) and len(index) == 2 and isinstance(index[0], torch.Tensor)
            and isinstance(index[1], torch.Tensor) and index[0].ndim == 1 and index[1].ndim == 1)


class EpisodeStorage(_EpisodeRows, LazyTensorStorage):
    """In-memory TorchRL storage of episodes as ``[episode, t]`` rows: a ``LazyTensorStorage(ndim=2)`` for episodes.

    Its writes must be whole episodes of one length (:class:`~torchrl_cebp.replay.EpisodeWriter` assembles
    them from a collector's frames); an episode may end before its row does, at its first ``end_key`` flag
    (:meth:`valid_lengths`). All entries of one dtype share one ``[rows, T, features]`` block, so a draw of
    ``(episode, step)`` pairs reads one run of memory per transition and dtype, not one cache miss per entry.

    Args:
        capacity (int, optional): the storage size in transitions (see :func:`episode_rows` for the rows it
            makes). Defaults to ``1_000_000``.

    Keyword Args:
        device (torch.device or str, optional): where the storage keeps its data. Defaults to ``"cpu"``.
        end_key (NestedKey, optional): the flag at whose first ``True`` an episode ends before its row does.
            Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> rb = TensorDictReplayBuffer(storage=EpisodeStorage(3 * 50), dim_extend=0, batch_size=4)
        >>> _ = rb.extend(TensorDict({"observation": torch.randn(5, 50, 25)}, [5, 50]))
        >>> rb.storage.shape  # 3 rows kept: the last 2 episodes overwrote the first 2
        torch.Size([3, 50])
    """

    def __init__(
        self, capacity: int = 1_000_000, *, device: torch.device | str = "cpu", end_key: NestedKey = ("next", "done")
    ) -> None:
        super().__init__(int(capacity), ndim=2, device=device)
        self.end_key = end_key
        self._laid_out: _Layout | None = None  # made at the first write, again when the storage is replaced

    def _after_load(self) -> None:
        super()._after_load()
        if self.initialized:  # the blocks too: laid out in one process only, the other would write elsewhere
            self._layout()

    def _store(self, cursor: Any, data: Any, set_cursor: bool, *, whole: bool) -> None:
        # Whole rows of the stored entries, no other: one copy per dtype block, where TorchRL's write copies each
        # entry apart (the most of a write's time). Laid out at the first write, not the first draw, so
        # that a process the storage is sent to writes into the same blocks.
        if not (whole and isinstance(cursor, torch.Tensor) and cursor.ndim == 1 and type(data) is TensorDict):
            super()._store(cursor, data, set_cursor, whole=whole)
            if isinstance(data, TensorDictBase):
                self._layout()
            return
        layout = self._layout()
        # One pass over the entries costs a third of a get each; no reshape of entries already [n, T, width].
        rows, entries = [], dict(data.items(True, True))
        for block, keys, kinds in layout.row_blocks:
            values = list(map(entries.__getitem__, keys))
            if [(value.shape[2:], value.dtype) for value in values] != kinds:
                # TorchRL's storage refuses these too; the block's copy would reshape or cast them without a word.
                key, value, (shape, _) = next((k, v, kind) for k, v, kind in zip(keys, values, kinds)
                                              if (v.shape[2:], v.dtype) != kind)
                raise ValueError(f"entry {key!r} has {value.dtype} values of shape {list(value.shape[2:])} per step, "
                                 f"but the storage holds {block.dtype} of {list(shape)}: a write keeps each entry's "
                                 "shape and dtype")
            parts = [value if value.ndim == 3 else value.reshape(*data.shape, -1) for value in values]
            rows.append((block, parts[0] if len(parts) == 1 else torch.cat(parts, dim=-1)))
        _upstream.record_write(self, cursor, data, set_cursor)
        for block, values in rows:
            block.index_copy_(0, cursor.to(block.device), values.to(block.device, block.dtype))

    def __getstate__(self) -> dict[str, Any]:
        state = super().__getstate__()
        if get_spawning_popen() is None:
            # A copy (deepcopy, pickle) copies each entry apart from the blocks it was a view of: the copy lays
            # its entries out again. Sent to a spawned process, both stay views of the same shared memory.
            state = {**state, "_laid_out": None}
        return state

    def _layout(self) -> _Layout:
        if self._laid_out is None or self._laid_out.source is not _upstream.stored_tensordict(self):
            storage = _upstream.stored_tensordict(self)
            fields, widths = [], {}
            for key, leaf in storage.items(True, True):
                width = leaf[0, 0].numel()
                start = widths.get(leaf.dtype, 0)
                path = (key,) if isinstance(key, str) else tuple(key)
                fields.append(_Field(path, leaf.dtype, start, start + width, leaf.shape[2:]))
                widths[leaf.dtype] = start + width
            rows, steps = storage.shape
            blocks = {
                dtype: torch.empty(rows, steps, width, dtype=dtype, device=storage.device)
                for dtype, width in widths.items()
            }
            packed = TensorDict(batch_size=storage.shape, device=storage.device)
            filled = self.shape[0]  # only these are copied: the rest of the blocks' memory stays untouched
            for field in fields:
                view = blocks[field.dtype][..., field.start : field.stop]  # no reshape for a vector entry
                view = view if len(field.shape) == 1 else _reshaped(view, field.shape)
                view[:filled].copy_(storage.get(field.path)[:filled])
                packed.set(field.path, view)
            _upstream.replace_stored_tensordict(self, packed)
            self._laid_out = _Layout(
                packed, [(block.flatten(0, 1), [f.stop - f.start for f in fields if f.dtype == dtype])
                         for dtype, block in blocks.items()],
                [(block, [f.path[0] if len(f.path) == 1 else f.path for f in fields if f.dtype == dtype],
                  [(f.shape, dtype) for f in fields if f.dtype == dtype]) for dtype, block in blocks.items()],
                *_read_plan(fields), steps)
        return self._laid_out

    def get(self, index: Any) -> Any:
        """Reads stored transitions or rows: ``(rows, steps)`` tensors with one gather per dtype block, a slice of
        consecutive rows as views of the blocks, and any other index as TorchRL's storage reads it.

        Raises:
            IndexError: a pair's row outside the filled rows or step outside the rows' ``T`` steps (negative ones
                count from the end).
        """
        if self.initialized and _is_pair_index(index):
            _, blocks, _, plan, n_nodes, row_length = self._layout()
            rows, steps = index
            low, high = map(int, torch.aminmax(steps)) if steps.numel() else (0, 0)  # ints: compared faster
            if low < -row_length or high >= row_length:  # the flat read below would take a neighbouring row's step
                raise IndexError(f"step {high if high >= row_length else low} is outside rows of {row_length} steps")
            steps = steps if low >= 0 else steps % row_length  # a negative step counts from the end, as TorchRL's
            # Rows count among the filled ones, as TorchRL's read of its filled rows does: a negative row from the
            # last filled one, and none past it (the blocks hold the unfilled rows' old memory there).
            filled = -(len(self) // -row_length)
            low, high = map(int, torch.aminmax(rows)) if rows.numel() else (0, 0)
            if low < -filled or high >= filled:
                raise IndexError(f"row {high if high >= filled else low} is outside the {filled} filled rows")
            rows = rows if low >= 0 else rows % filled
            flat = torch.add(steps, rows, alpha=row_length)
            # One gather per dtype block; one split cuts out all of its entries (a slice each costs twice), called
            # as split_with_sizes: Tensor.split's Python wrapper costs as much again.
            columns = [c for block, widths in blocks for c in block.index_select(0, flat).split_with_sizes(widths, 1)]
            return self._assembled(columns, plan, n_nodes, flat.shape)
        if self.initialized and isinstance(index, slice) and index.step in (None, 1):
            # Consecutive rows (what a sampler reads after a write) as views of the blocks, without TorchRL's
            # per-entry indexing of the stored tensordict.
            _, blocks, row_blocks, plan, n_nodes, steps = self._layout()
            first, stop, _ = index.indices(self.shape[0])
            stop = max(stop, first)
            columns = [c for (block, _, _), (_, widths) in zip(row_blocks, blocks)
                       for c in block[first:stop].split_with_sizes(widths, -1)]
            return self._assembled(columns, plan, n_nodes, torch.Size([stop - first, steps]))
        return super().get(index)

    def _assembled(self, columns: list[torch.Tensor], plan: list[tuple], n_nodes: int,
                   batch_size: torch.Size) -> TensorDictBase:
        """The tensordict of the stored entries from their gathered ``columns``, nested as :func:`_read_plan` says."""
        nodes: list[dict] = [{} for _ in range(n_nodes)]
        for node, name, child, column, shape in plan:
            if child is not None:
                nodes[node][name] = nodes[child]
            else:
                value = columns[column]
                nodes[node][name] = value if shape is None else _reshaped(value, shape)
        return _upstream.unchecked_tensordict(nodes[0], batch_size, self.device)


def _written_by_round_robin_writer(cursor: Any, data: TensorDictBase) -> bool:
    """Whether a write comes from a TorchRL round-robin writer's ``extend``, which moved its cursor before it: that
    writer gives each written row its ``"index"``, the cursor; a direct ``storage.set`` moved none, so none rewinds."""
    index = data.get("index", None)
    return (isinstance(cursor, torch.Tensor) and cursor.ndim == 1 and cursor.numel() > 0 and index is not None
            and index.shape[:1] == cursor.shape and torch.equal(index.reshape(cursor.numel(), -1)[:, 0], cursor))


def _names_by_node(keys: Iterable[NestedKey]) -> dict[tuple[str, ...], set[str]]:
    """The names under each node of a tensordict with these leaf ``keys`` (``()`` for the root)."""
    nodes: dict[tuple[str, ...], set[str]] = {(): set()}
    for key in keys:
        path = (key,) if isinstance(key, str) else tuple(key)
        for depth in range(len(path)):
            nodes.setdefault(path[:depth], set()).add(path[depth])
    return nodes


def _names_at(data: TensorDictBase, path: tuple[str, ...]) -> set[str]:
    node = data if not path else data.get(path, None)
    return set() if not isinstance(node, TensorDictBase) else set(node.keys())


def _reshaped(columns: torch.Tensor, shape: torch.Size) -> torch.Tensor:
    return columns.unflatten(-1, shape) if shape else columns.squeeze(-1)


def _read_plan(fields: list[_Field]) -> tuple[list[tuple], int]:
    """How :meth:`EpisodeStorage.get` nests the gathered columns: ``(node, name, child, column, shape)`` steps
    (``child``: a sub-node's index; ``column``: a leaf's among the blocks' split columns), and the node count."""
    by_dtype: dict[torch.dtype, list[_Field]] = {}
    for field in fields:
        by_dtype.setdefault(field.dtype, []).append(field)
    column_of = {id(field): i for i, field in enumerate(f for group in by_dtype.values() for f in group)}
    nodes: dict[tuple[str, ...], int] = {(): 0}
    plan: list[tuple] = []
    for field in fields:
        *parents, name = field.path
        for depth in range(1, len(parents) + 1):
            path = tuple(parents[:depth])
            if path not in nodes:
                nodes[path] = len(nodes)
                plan.append((nodes[path[:-1]], path[-1], nodes[path], None, None))
        shape = None if len(field.shape) == 1 else field.shape
        plan.append((nodes[tuple(parents)], name, None, column_of[id(field)], shape))
    return plan, len(nodes)


class EpisodeMemmapStorage(_EpisodeRows, LazyMemmapStorage):
    """The memory-mapped twin of :class:`EpisodeStorage`, for buffers larger than RAM.

    Args:
        capacity (int, optional): as for :class:`EpisodeStorage`. Defaults to ``1_000_000``.

    Keyword Args:
        scratch_dir (str, optional): the folder of the memory-mapped files. Defaults to ``None`` (temporary files).
        device (torch.device or str, optional): as for :class:`EpisodeStorage`. Defaults to ``"cpu"``.
        end_key (NestedKey, optional): as for :class:`EpisodeStorage`. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch, tempfile
        >>> from tensordict import TensorDict
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import EpisodeMemmapStorage
        >>> storage = EpisodeMemmapStorage(4 * 50, scratch_dir=tempfile.mkdtemp())
        >>> rb = TensorDictReplayBuffer(storage=storage, dim_extend=0, batch_size=4)
        >>> _ = rb.extend(TensorDict({"observation": torch.randn(2, 50, 25)}, [2, 50]))
        >>> rb.sample()["observation"].shape
        torch.Size([4, 25])
    """

    def __init__(
        self, capacity: int = 1_000_000, *, scratch_dir: str | None = None, device: torch.device | str = "cpu",
        end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(int(capacity), ndim=2, scratch_dir=scratch_dir, device=device)
        self.end_key = end_key
