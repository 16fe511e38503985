"""The HER baseline: episodes and steps drawn uniformly."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase

from torchrl_cebp import _upstream
from torchrl_cebp.replay.samplers.base import EpisodePrioritySampler


class UniformEpisodeSampler(EpisodePrioritySampler):
    """Uniform episode, then uniform step: what HER (Andrychowicz et al.) replays.

    With episodes of one length this is the distribution TorchRL's
    :class:`~torchrl.data.RandomSampler` draws over an ``ndim=2`` storage (every
    stored transition equally likely). It stays because episodes may end early:
    ``RandomSampler`` would draw their padding steps, this never does.

    Args:
        end_key (NestedKey, optional): the flag that ends an episode; no step after it is drawn.
            Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import UniformEpisodeSampler
        >>> episodes = TensorDict({"observation": torch.randn(3, 50, 25)}, [3, 50])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * 50, ndim=2),
        ...                             sampler=UniformEpisodeSampler(), batch_size=4, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> rb.sample()["index"].shape
        torch.Size([4, 2])
    """

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        return torch.ones(episodes.shape[0], dtype=torch.float64)

    def draw_episodes(self, batch_size: int) -> torch.Tensor:
        # Equal priorities: a plain randint is the same distribution without the tree walk.
        return torch.randint(self._n_stored, (batch_size,), generator=_upstream.sampler_generator(self))
