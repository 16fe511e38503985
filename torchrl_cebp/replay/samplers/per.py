"""Prioritized Experience Replay (PER, Schaul et al. 2016) over episode rows."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.samplers import PrioritizedSampler
from torchrl.data.replay_buffers.scheduler import LinearScheduler
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import episode_lengths, valid_steps
from torchrl_cebp.replay.samplers.base import stored_rows


class PERSampler(PrioritizedSampler):
    """TorchRL's segment-tree :class:`~torchrl.data.PrioritizedSampler` with beta annealed 0.4 -> 1.

    Priorities are per transition, ``(|TD error| + eps) ^ alpha``; new
    transitions enter at the highest priority seen, and the padding steps of
    episodes that ended early at probability 0. Feed priorities back after
    each update with ``rb.update_tensordict_priority(batch)`` (the batch holds
    ``"td_error"`` once a TorchRL loss ran on it) or ``rb.update_priority``.
    Beta grows linearly from ``beta`` to ``beta_end`` over ``beta_anneal_draws``
    draws, as in baselines' PER over training, through the TorchRL scheduler
    :meth:`beta_scheduler` returns: step it once per draw.

    Args:
        capacity: storage capacity in transitions (the buffer's, e.g. 1e6).
        alpha: priority exponent (0.6).
        beta: initial IS exponent (0.4).
        beta_end: final IS exponent (1.0).
        beta_anneal_draws: number of draws over which beta is annealed.
        eps: added to |TD error| (1e-6 as in baselines).
        end_key: the flag that ends an episode before its row does.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.samplers import PERSampler
        >>> episodes = TensorDict({"observation": torch.randn(3, 50, 25)}, [3, 50])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * 50, ndim=2),
        ...                             sampler=PERSampler(10 * 50), batch_size=4, dim_extend=0,
        ...                             priority_key="td_error")
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> _ = batch.set("td_error", torch.rand(4))
        >>> rb.update_tensordict_priority(batch)
        >>> scheduler = rb.sampler.beta_scheduler()
        >>> scheduler.step()
        >>> round(float(rb.sampler.beta), 6)  # one of 100,000 steps from 0.4 to 1
        0.400006
    """

    def __init__(
        self,
        capacity: int = 1_000_000,
        alpha: float = 0.6,
        beta: float = 0.4,
        beta_end: float = 1.0,
        beta_anneal_draws: int = 100_000,
        eps: float = 1e-6,
        *,
        end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(int(capacity), alpha=alpha, beta=beta, eps=eps)
        self.beta_end = float(beta_end)
        self.beta_anneal_draws = int(beta_anneal_draws)
        self.end_key = end_key

    def beta_scheduler(self) -> LinearScheduler:
        """TorchRL's linear scheduler taking beta from its current value to ``beta_end`` in ``beta_anneal_draws`` steps."""
        return LinearScheduler(self, "beta", final_value=self.beta_end, num_steps=self.beta_anneal_draws)

    def mark_update(self, index: torch.Tensor | int, *, storage: Storage | None = None) -> None:
        super().mark_update(index, storage=storage)
        if storage is None or getattr(storage, "ndim", 1) != 2:
            return
        rows = stored_rows(index)
        row_length = storage.shape[1]
        padding = ~valid_steps(episode_lengths(storage.get(rows), self.end_key), row_length)
        if padding.any():
            rows_of, steps_of = padding.nonzero(as_tuple=True)
            _upstream.exclude_from_draws(self, rows[rows_of] * row_length + steps_of)

    def state_dict(self) -> dict[str, Any]:
        """Plain tensors and numbers only (TorchRL's own holds C++ trees, which ``weights_only`` loads refuse)."""
        return _upstream.prioritized_state(self)

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        _upstream.load_prioritized_state(self, state_dict)

    def dumps(self, path: str | Path) -> None:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        torch.save(self.state_dict(), path / "per_sampler.pt")

    def loads(self, path: str | Path) -> None:
        self.load_state_dict(torch.load(Path(path) / "per_sampler.pt", weights_only=True))

    def __repr__(self) -> str:
        return (
            f"PERSampler(alpha={self.alpha}, beta={self.beta:.3f} -> {self.beta_end} over "
            f"{self.beta_anneal_draws} draws)"
        )
