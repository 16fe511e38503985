"""An episode replay buffer: TorchRL storage of ``[episode, t]`` rows + any sampler + HER."""
from __future__ import annotations

from typing import Literal

import torch
from tensordict import TensorDictBase
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import Sampler

from torchrl_cebp.replay.her import HindsightRelabel, RewardFn
from torchrl_cebp.replay.samplers import PERSampler, UniformEpisodeSampler
from torchrl_cebp.replay.storage import EpisodeMemmapStorage, EpisodeStorage


def episode_storage(
    capacity: int = 1_000_000,
    *,
    kind: Literal["tensor", "memmap"] = "tensor",
    scratch_dir: str | None = None,
    device: torch.device | str = "cpu",
) -> EpisodeStorage | EpisodeMemmapStorage:
    """An episode storage by name: ``"tensor"`` (in memory) or ``"memmap"`` (on disk).

    ``capacity`` is counted in transitions: with 50-step episodes the default
    1e6 is 20,000 episode rows.

    Examples:
        >>> episode_storage(1000).ndim
        2
    """
    if kind == "tensor":
        return EpisodeStorage(capacity, device=device)
    if kind == "memmap":
        return EpisodeMemmapStorage(capacity, scratch_dir=scratch_dir, device=device)
    raise ValueError(f"unknown storage kind {kind!r}; valid kinds: ['memmap', 'tensor']")


class EpisodeReplayBuffer(TensorDictReplayBuffer):
    """A :class:`~torchrl.data.TensorDictReplayBuffer` over episode rows with a lean draw.

    Behaves as its parent (any sampler, writer, transform, ``sample_unit``),
    but :meth:`sample` skips the generic machinery a training loop does not
    use (prefetch queues, generation tracking, per-entry conversions of the
    sample info), which is most of the cost of a 256-transition draw. With
    prefetch enabled it falls back to the parent's path.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay import EpisodeReplayBuffer, EpisodeStorage
        >>> from torchrl_cebp.samplers import UniformEpisodeSampler
        >>> rb = EpisodeReplayBuffer(storage=EpisodeStorage(10 * 50), sampler=UniformEpisodeSampler(),
        ...                          batch_size=8, dim_extend=0)
        >>> _ = rb.extend(TensorDict({"observation": torch.randn(2, 50, 25)}, [2, 50]))
        >>> rb.n_episodes, rb.episode_length
        (2, 50)
        >>> rb.sample()["index"].shape
        torch.Size([8, 2])
    """

    @property
    def episode_length(self) -> int:
        """Steps per stored episode (0 before the first write)."""
        return self._storage.shape[1] if self._storage.initialized else 0

    @property
    def n_episodes(self) -> int:
        """Episodes currently stored."""
        return len(self._storage) // self.episode_length if self.episode_length else 0

    def sample(self, batch_size: int | None = None, return_info: bool = False) -> TensorDictBase:
        if self._prefetch or self._writer.tracks_generations:
            return super().sample(batch_size, return_info=return_info)
        if batch_size is None:
            batch_size = self._batch_size
        with self._replay_lock, self._write_lock:
            index, info = self._sampler.sample(self._storage, batch_size)
            if self._sample_unit is not None:
                index, info = self._sample_unit.expand(index, info, self._storage)
            data = self._storage.get(index)
        data.set("index", torch.stack(index, -1) if isinstance(index, tuple) else index)
        for key, value in info.items():
            data.set(key, value)
        if self._transform is not None and len(self._transform):
            data = self._transform(data)
        return (data, info) if return_info else data


def make_replay_buffer(
    sampler: Sampler | None = None,
    *,
    reward_fn: RewardFn,
    capacity: int = 1_000_000,
    batch_size: int = 256,
    future_p: float = 0.8,
    strategy: Literal["future", "final", "episode"] = "future",
    storage: Literal["tensor", "memmap"] = "tensor",
    scratch_dir: str | None = None,
    device: torch.device | str = "cpu",
) -> EpisodeReplayBuffer:
    """Wires an episode storage, a sampler (uniform HER by default) and HER relabelling.

    ``rb.extend(episodes)`` takes a tensordict of shape ``[n_episodes, T]``;
    ``rb.sample()`` returns ``[batch_size]`` transitions with relabelled goals
    and rewards, ``"index"`` (``[B, 2]``: episode row, step) and, for samplers
    with importance-sampling weights, ``"priority_weight"``. With a
    :class:`~torchrl_cebp.samplers.PERSampler`, ``rb.update_tensordict_priority(batch)``
    feeds ``batch["td_error"]`` back.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay import make_replay_buffer
        >>> from torchrl_cebp.samplers import CEBPSampler
        >>> reward = lambda ag, g: -(torch.linalg.vector_norm(ag - g, dim=-1, keepdim=True) > 0.05).float()
        >>> n, T = 4, 50
        >>> step = {"observation": torch.rand(n, T, 25), "achieved_goal": torch.rand(n, T, 3),
        ...         "desired_goal": torch.rand(n, T, 3), "touch": torch.rand(n, T, 2)}
        >>> episodes = TensorDict({**step, "action": torch.rand(n, T, 4),
        ...     "next": {**step, "reward": torch.zeros(n, T, 1)}}, [n, T])
        >>> rb = make_replay_buffer(CEBPSampler("push"), reward_fn=reward, capacity=100 * T, batch_size=32)
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> batch["index"].shape, batch["priority_weight"].shape
        (torch.Size([32, 2]), torch.Size([32]))
    """
    sampler = UniformEpisodeSampler() if sampler is None else sampler
    if isinstance(sampler, PERSampler) and sampler.max_size != capacity:
        raise ValueError(
            f"PERSampler capacity ({sampler.max_size}) must equal the buffer capacity ({capacity})"
        )
    return EpisodeReplayBuffer(
        storage=episode_storage(capacity, kind=storage, scratch_dir=scratch_dir, device=device),
        sampler=sampler,
        sample_unit=HindsightRelabel(reward_fn, future_p=future_p, strategy=strategy),
        batch_size=batch_size,
        dim_extend=0,
        priority_key="td_error",
    )
