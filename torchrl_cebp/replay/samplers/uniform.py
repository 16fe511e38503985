"""The HER baseline: episodes and steps drawn uniformly."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.samplers.base import EpisodePrioritySampler


class UniformEpisodeSampler(EpisodePrioritySampler):
    """Uniform episode, then uniform valid step: what HER replays, and keeps no priorities to do it.

    With episodes of one length this is TorchRL's :class:`~torchrl.data.RandomSampler` over an ``ndim=2`` storage,
    which unlike this also draws the padding after an episode that ended early.

    Args:
        end_key (NestedKey, optional): the flag that ends an episode; no step after it is drawn.
            Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * 50, ndim=2),
        ...                             sampler=UniformEpisodeSampler(), batch_size=4, dim_extend=0)
        >>> _ = rb.extend(TensorDict({"observation": torch.randn(3, 50, 25)}, [3, 50]))
        >>> rb.sample()["index"].shape
        torch.Size([4, 2])
    """

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Priority 1 for every episode, ``[n]``. Draws never read it: :meth:`draw_episodes` needs no priorities."""
        return torch.ones(episodes.shape[0], dtype=torch.float64)

    def _catch_up(self, storage: Storage, written: torch.Tensor | None = None) -> None:
        # Equal priorities: only how many rows are filled changes, whichever process filled them. Read after a write
        # only: a storage's shape (a worker view's above all) costs more than the rest of a draw.
        if self._seen is None and not len(storage):
            return
        writes = int(self._write_counts(storage)[-1])
        if writes != self._seen:  # here the total of write starts and ends, not each row's count
            self._n_stored, self._seen = storage.shape[0], writes

    def draw_episodes(self, batch_size: int) -> torch.Tensor:
        """``batch_size`` episode rows drawn uniformly from the filled ones, with the sampler's generator."""
        return torch.randint(self._n_stored, (batch_size,), generator=_upstream.sampler_generator(self))

    def probabilities(self, rows: torch.Tensor) -> torch.Tensor:
        """``1 / N`` for each of ``rows``, ``N`` the filled rows: the probability that one draw takes it."""
        return torch.full(rows.shape, 1.0 / self._n_stored, dtype=torch.float64)
