"""Storage of whole episodes as rows of a TorchRL tensor storage."""
from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.data import LazyMemmapStorage, LazyTensorStorage


class _EpisodeRows:
    """Shared behaviour of the episode storages: fixed episode length, fast transition gathers."""

    ndim: int
    _storage: TensorDictBase

    def _check_episode_length(self, data: Any) -> None:
        if not isinstance(data, TensorDictBase):
            return
        if data.ndim < 2:
            raise ValueError(
                f"episode storages take whole episodes shaped [n_episodes, T], got batch shape {list(data.shape)}"
            )
        if self.initialized and data.shape[1] != self._storage.shape[1]:
            raise ValueError(
                f"episodes of {data.shape[1]} steps cannot go into a storage of "
                f"{self._storage.shape[1]}-step episodes"
            )

    def set(self, cursor: Any, data: Any, *, set_cursor: bool = True) -> None:
        self._check_episode_length(data)
        super().set(cursor, data, set_cursor=set_cursor)

    def _flat_rows(self) -> TensorDictBase:
        # A [rows * T] view of the storage, rebuilt only when the storage tensors are replaced.
        if getattr(self, "_flat_source", None) is not self._storage:
            self._flat_view = self._storage.view(-1)
            self._flat_source = self._storage
        return self._flat_view

    def get(self, index: Any) -> Any:
        if (
            isinstance(index, tuple)
            and len(index) == 2
            and all(isinstance(i, torch.Tensor) and i.ndim == 1 for i in index)
            and self.initialized
        ):
            # (episode, step) pairs: one index_select per leaf on a flat view is several
            # times faster than 2-D advanced indexing of the (possibly sliced) storage.
            flat = index[0] * self._storage.shape[1] + index[1]
            return self._flat_rows()._fast_apply(
                lambda leaf: leaf.index_select(0, flat), batch_size=flat.shape
            )
        return super().get(index)


class EpisodeStorage(_EpisodeRows, LazyTensorStorage):
    """In-memory TorchRL storage of episodes as ``[episode, t]`` rows; ``capacity`` in transitions.

    A :class:`~torchrl.data.LazyTensorStorage` with ``ndim=2`` whose writes
    must be whole episodes of one fixed length, and whose reads of
    ``(episode, step)`` index pairs gather transitions with one flat
    ``index_select`` per entry. With a round-robin writer (the default of every
    TorchRL buffer) the oldest episode is overwritten first.

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

    def __init__(self, capacity: int = 1_000_000, *, device: torch.device | str = "cpu") -> None:
        super().__init__(int(capacity), ndim=2, device=device)


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
    ) -> None:
        super().__init__(int(capacity), ndim=2, scratch_dir=scratch_dir, device=device)
