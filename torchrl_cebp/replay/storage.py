"""Storage of whole episodes as rows of a TorchRL tensor storage."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import LazyMemmapStorage, LazyTensorStorage

from torchrl_cebp.replay import _upstream
from torchrl_cebp.replay.episodes import common_length, episode_lengths


class _EpisodeRows:
    """Writes must be whole episodes of one fixed length (the storage's second dimension).

    Each row's valid length (up to its first ``end_key`` flag) is kept on write, so that HER
    reads it per draw instead of scanning the flags.
    """

    end_key: NestedKey = ("next", "done")
    _lengths: torch.Tensor | None = None
    _common_length: int | None = None

    def valid_lengths(self, rows: torch.Tensor) -> torch.Tensor:
        """Valid steps of the episodes stored in ``rows``."""
        self._read_lengths_if_unknown()
        return self._lengths.index_select(0, rows)

    def common_length(self) -> int | None:
        """The valid length every row shares (the row length unless episodes end early), else ``None``.

        Lets a draw skip the per-row lengths in the usual case of episodes that all run a fixed length.
        """
        self._read_lengths_if_unknown()
        return self._common_length

    def _read_lengths_if_unknown(self) -> None:
        if self._lengths is None:  # restored from a checkpoint: read them from the flags once
            self._lengths = episode_lengths(_upstream.stored_tensordict(self), self.end_key)
            # Unwritten rows hold no end flag, so they count as full rows: one check covers the filled ones.
            self._common_length = common_length(self._lengths)

    def set(self, cursor: Any, data: Any, *, set_cursor: bool = True) -> None:
        if isinstance(data, TensorDictBase):
            if data.ndim < 2:
                raise ValueError(
                    "episode storages take whole episodes shaped [n_episodes, T], "
                    f"got batch shape {list(data.shape)}"
                )
            if self.initialized and data.shape[1] != self.shape[1]:
                raise ValueError(
                    f"episodes of {data.shape[1]} steps cannot go into a storage of "
                    f"{self.shape[1]}-step episodes"
                )
        super().set(cursor, data, set_cursor=set_cursor)
        if isinstance(data, TensorDictBase):
            if self._lengths is None:  # first write, or first since a restore: every row from its flags
                self._read_lengths_if_unknown()
            else:
                # self.shape counts the filled rows only; the lengths cover every row.
                n_rows = self._lengths.numel()
                self._lengths[torch.arange(n_rows)[cursor]] = episode_lengths(data, self.end_key)
                self._common_length = common_length(self._lengths)

    def state_dict(self) -> dict[str, Any]:
        """The storage's state with its filled rows only, so that a checkpoint grows with the stored episodes."""
        state = super().state_dict()
        if self.initialized:
            filled_rows = self.shape[0]
            state["_storage"] = self.get(slice(0, filled_rows)).apply(torch.clone).state_dict()
            state["rows"] = self.max_size // self.shape[1]
        return state

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        rows = state_dict.get("rows")
        if rows is not None:  # the filled rows, back into a storage of the full capacity
            filled = TensorDict().load_state_dict(state_dict["_storage"], strict=False)
            full = filled.apply(lambda t: torch.zeros((rows, *t.shape[1:]), dtype=t.dtype),
                                batch_size=[rows, *filled.shape[1:]])
            full[: filled.shape[0]] = filled
            state_dict = {**state_dict, "_storage": full.state_dict()}
        super().load_state_dict(state_dict)
        self._lengths = None

    def loads(self, path: Any) -> None:
        super().loads(path)
        self._lengths = None


@dataclass(frozen=True)
class _Field:
    key: NestedKey
    dtype: torch.dtype
    start: int
    stop: int
    shape: torch.Size  # per-transition shape

    @property
    def path(self) -> tuple[str, ...]:
        return (self.key,) if isinstance(self.key, str) else tuple(self.key)

    def from_columns(self, columns: torch.Tensor) -> torch.Tensor:
        """The entry from its ``[B, width]`` columns (a view; no reshape for vector entries)."""
        if len(self.shape) == 1:
            return columns
        return columns.unflatten(-1, self.shape) if self.shape else columns.squeeze(-1)


def _is_pair_index(index: Any) -> bool:
    return (
        isinstance(index, tuple)
        and len(index) == 2
        and all(isinstance(i, torch.Tensor) and i.ndim == 1 for i in index)
    )


class EpisodeStorage(_EpisodeRows, LazyTensorStorage):
    """In-memory TorchRL storage of episodes as ``[episode, t]`` rows; ``capacity`` in transitions.

    A :class:`~torchrl.data.LazyTensorStorage` with ``ndim=2`` whose writes
    must be whole episodes of one fixed length; an episode may end before its
    row does, at its first ``end_key`` flag (:meth:`valid_lengths`). Its entries are laid out
    transition-major: all entries of one dtype share one ``[rows, T, features]``
    block, and each entry is a view into it. Drawing ``(episode, step)`` pairs
    then reads one contiguous run of memory per transition and dtype instead of
    one cache miss per entry, which is what makes a batch of 256 from 1M
    transitions cheap. With a round-robin writer (the default of every TorchRL
    buffer) the oldest episode is overwritten first.

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
        self,
        capacity: int = 1_000_000,
        *,
        device: torch.device | str = "cpu",
        end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(int(capacity), ndim=2, device=device)
        self.end_key = end_key
        self._layout_source: TensorDictBase | None = None

    def _layout(self) -> tuple[dict[torch.dtype, torch.Tensor], list[_Field]]:
        """The dtype blocks and where each entry sits in them; (re)built when the storage is replaced."""
        if self._layout_source is not _upstream.stored_tensordict(self):
            storage = _upstream.stored_tensordict(self)
            fields, widths = [], {}
            for key, leaf in storage.items(True, True):
                width = leaf[0, 0].numel()
                start = widths.get(leaf.dtype, 0)
                fields.append(_Field(key, leaf.dtype, start, start + width, leaf.shape[2:]))
                widths[leaf.dtype] = start + width
            rows, steps = storage.shape
            blocks = {
                dtype: torch.empty(rows, steps, width, dtype=dtype, device=storage.device)
                for dtype, width in widths.items()
            }
            packed = TensorDict(batch_size=storage.shape, device=storage.device)
            for field in fields:
                view = field.from_columns(blocks[field.dtype][..., field.start : field.stop])
                view.copy_(storage.get(field.key))
                packed.set(field.key, view)
            _upstream.replace_stored_tensordict(self, packed)
            self._layout_source = packed
            self._blocks = {dtype: block.flatten(0, 1) for dtype, block in blocks.items()}
            self._fields = fields
            self._row_length = steps  # storage.shape is recomputed on every read (~10% of a draw of 256)
        return self._blocks, self._fields

    def get(self, index: Any) -> Any:
        if not (self.initialized and _is_pair_index(index)):
            return super().get(index)
        blocks, fields = self._layout()
        flat = index[0] * self._row_length + index[1]
        gathered = {dtype: block.index_select(0, flat) for dtype, block in blocks.items()}
        tree: dict = {}
        for field in fields:
            *parents, name = field.path
            node = tree
            for parent in parents:
                node = node.setdefault(parent, {})
            node[name] = field.from_columns(gathered[field.dtype][:, field.start : field.stop])
        return _assemble(tree, flat.shape, self.device)


def _assemble(tree: dict, batch_size: torch.Size, device: torch.device | None) -> TensorDict:
    source = {
        name: _assemble(value, batch_size, device) if isinstance(value, dict) else value
        for name, value in tree.items()
    }
    return _upstream.unchecked_tensordict(source, batch_size, device)


class EpisodeMemmapStorage(_EpisodeRows, LazyMemmapStorage):
    """The memory-mapped twin of :class:`EpisodeStorage`, for buffers larger than RAM.

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
        self,
        capacity: int = 1_000_000,
        *,
        scratch_dir: str | None = None,
        device: torch.device | str = "cpu",
        end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(int(capacity), ndim=2, scratch_dir=scratch_dir, device=device)
        self.end_key = end_key
