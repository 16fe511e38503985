"""An episode replay buffer: a stock TorchRL buffer over ``[episode, t]`` rows, any sampler, HER."""
from __future__ import annotations

import time
from typing import Literal

import torch
from tensordict import TensorDictBase
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import Sampler
from torchrl.data.replay_buffers.writers import Writer
from torchrl.envs import Transform

from torchrl_cebp.replay.her import HindsightRelabel
from torchrl_cebp.replay.samplers import PERSampler, UniformEpisodeSampler
from torchrl_cebp.replay.storage import EpisodeMemmapStorage, EpisodeStorage


class EpisodeReplayBuffer(TensorDictReplayBuffer):
    """A :class:`~torchrl.data.TensorDictReplayBuffer` whose draws read one version of each drawn episode.

    A draw during which another process wrote into the shared episode storage (its ``write_counts``) is drawn
    again, so that the priority, valid length and data of each drawn transition come from one write. A write seen
    running for ``write_timeout_s`` (30 s) of redraws raises a ``RuntimeError``: its process died.

    Args:
        **kwargs: the arguments of :class:`~torchrl.data.TensorDictReplayBuffer`, unchanged.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> rb = EpisodeReplayBuffer(storage=EpisodeStorage(4 * 50), dim_extend=0, batch_size=8)
        >>> _ = rb.extend(TensorDict({"observation": torch.randn(2, 50, 25)}, [2, 50]))
        >>> rb.sample()["observation"].shape
        torch.Size([8, 25])
    """

    # A write takes milliseconds: an odd total that stays this long is a write whose process died. Bounded by time,
    # not by a count of redraws, so that a writer that keeps writing (the total keeps changing) is never refused.
    write_timeout_s: float = 30.0

    def _sample(self, batch_size: int) -> tuple[TensorDictBase, dict]:
        # TorchRL's private hook, the one place that sees a whole draw, prefetched or not (tests/test_upstream.py).
        running, since = None, 0.0
        while True:
            counts = getattr(self._storage, "write_counts", None)
            if counts is None:
                return super()._sample(batch_size)
            writes = int(counts[-1])
            data, info = super()._sample(batch_size)
            after = int(counts[-1])
            if writes % 2 == 0 and after == writes:
                return data, info
            if after % 2 and after != running:  # a write runs: timed from its first sight
                running, since = after, time.monotonic()
            elif after % 2 and time.monotonic() - since > self.write_timeout_s:
                raise RuntimeError(f"the storage's write count total stayed odd ({after}) for over "
                                   f"{self.write_timeout_s} s of redraws: a write into it never finished, a writing "
                                   "process probably died mid-write, and the rows it wrote may be torn. The count "
                                   "stays so in this storage: to recover, build a new storage and buffer and load "
                                   "them from a checkpoint (load_state_dict), or refill them.")


def make_replay_buffer(
    sampler: Sampler | None,
    her: HindsightRelabel,
    *,
    capacity: int = 1_000_000,
    batch_size: int = 256,
    storage: Literal["tensor", "memmap"] = "tensor",
    scratch_dir: str | None = None,
    device: torch.device | str = "cpu",
    transform: Transform | None = None,
    generator: torch.Generator | None = None,
    writer: Writer | None = None,
    prefetch: int | None = None,
    pin_memory: bool = False,
    shared: bool = False,
) -> EpisodeReplayBuffer:
    """An :class:`EpisodeReplayBuffer` over an episode storage, a sampler and HER.

    ``rb.extend(episodes)`` takes ``[n_episodes, T]`` rows (a collector's frames with
    ``writer=EpisodeWriter(T)``); ``rb.sample()`` returns ``[batch_size]`` relabelled transitions with their
    ``"index"`` (``[B, 2]``: row, step) and, for samplers with importance-sampling weights, ``"priority_weight"``.
    With PER, ``rb.update_tensordict_priority(batch)`` feeds ``batch["td_error"]`` back.

    Args:
        sampler (Sampler or None): draws episode rows and steps; ``None`` draws uniformly.
        her (HindsightRelabel): relabels the goals and rewards of each drawn batch.

    Keyword Args:
        capacity (int, optional): the storage size in transitions; a PERSampler's ``max_size`` must equal it.
            Defaults to ``1_000_000``.
        batch_size (int, optional): transitions per ``rb.sample()``. Defaults to ``256``.
        storage (str, optional): ``"tensor"`` (an :class:`~torchrl_cebp.replay.EpisodeStorage`, in memory) or
            ``"memmap"`` (an :class:`~torchrl_cebp.replay.EpisodeMemmapStorage`, on disk). Defaults to ``"tensor"``.
        scratch_dir (str, optional): the folder of a ``"memmap"`` storage's files. Defaults to ``None`` (temporary).
        device (torch.device or str, optional): where the storage keeps its data. Defaults to ``"cpu"``.
        transform (Transform, optional): applied to each relabelled batch. Defaults to ``None``.
        generator (torch.Generator, optional): drives every random draw of a sample, the sampler's and HER's.
            Defaults to ``None`` (torch's default generator).
        writer, prefetch, pin_memory, shared: as for :class:`~torchrl.data.ReplayBuffer`.

    Raises:
        ValueError: if a PERSampler's ``max_size`` is not ``capacity``, or ``storage`` is not a known kind.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay import HindsightRelabel, make_replay_buffer
        >>> from torchrl_cebp.replay.samplers import CEBPSampler
        >>> reward = lambda ag, g: -(torch.linalg.vector_norm(ag - g, dim=-1, keepdim=True) > 0.05).float()
        >>> step = {"achieved_goal": torch.rand(4, 50, 3), "desired_goal": torch.rand(4, 50, 3)}
        >>> rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(reward), capacity=100 * 50, batch_size=32)
        >>> _ = rb.extend(TensorDict({**step, "next": {**step, "touch": torch.rand(4, 50, 2)}}, [4, 50]))
        >>> batch = rb.sample()
        >>> batch["index"].shape, batch["priority_weight"].shape
        (torch.Size([32, 2]), torch.Size([32]))
    """
    if storage not in ("tensor", "memmap"):
        raise ValueError(f"unknown storage kind {storage!r}; valid kinds: ['memmap', 'tensor']")
    sampler = UniformEpisodeSampler() if sampler is None else sampler
    if isinstance(sampler, PERSampler) and sampler.max_size != capacity:
        raise ValueError(f"PERSampler capacity ({sampler.max_size}) must equal the buffer capacity ({capacity})")
    return EpisodeReplayBuffer(
        storage=EpisodeStorage(capacity, device=device) if storage == "tensor" else
        EpisodeMemmapStorage(capacity, scratch_dir=scratch_dir, device=device),
        sampler=sampler, sample_unit=her, collate_fn=her.collate, transform=transform, batch_size=batch_size,
        dim_extend=0, priority_key="td_error",  # the TD-error entry the trainer's loss writes, which PER ranks by
        generator=generator, writer=writer, prefetch=prefetch, pin_memory=pin_memory, shared=shared,
    )
