"""Prioritized Experience Replay (PER, Schaul et al. 2016) over episode rows."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from torchrl.data.replay_buffers.samplers import PrioritizedSampler
from torchrl.data.replay_buffers.storages import Storage


class PERSampler(PrioritizedSampler):
    """TorchRL's segment-tree :class:`~torchrl.data.PrioritizedSampler` with beta annealed 0.4 -> 1.

    Priorities are per transition, ``(|TD error| + eps) ^ alpha``; new
    transitions enter at the highest priority seen. Feed priorities back after
    each update with ``rb.update_tensordict_priority(batch)`` (the batch holds
    ``"td_error"`` once a TorchRL loss ran on it) or ``rb.update_priority``.
    Beta grows linearly from ``beta`` to ``beta_end`` over ``beta_anneal_draws``
    calls to :meth:`sample`, as in baselines' PER over training.

    Args:
        capacity: storage capacity in transitions (the buffer's, e.g. 1e6).
        alpha: priority exponent (0.6).
        beta: initial IS exponent (0.4).
        beta_end: final IS exponent (1.0).
        beta_anneal_draws: number of draws over which beta is annealed.
        eps: added to |TD error| (1e-6 as in baselines).

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
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__(int(capacity), alpha=alpha, beta=beta, eps=eps)
        self.beta_start = float(beta)
        self.beta_end = float(beta_end)
        self.beta_anneal_draws = int(beta_anneal_draws)
        self.draws = 0
        self._rng = generator

    def sample(self, storage: Storage, batch_size: int) -> tuple[Any, dict]:
        progress = min(1.0, self.draws / max(1, self.beta_anneal_draws))
        self.beta = self.beta_start + progress * (self.beta_end - self.beta_start)
        self.draws += 1
        return super().sample(storage, batch_size)

    def state_dict(self) -> dict[str, Any]:
        """Plain tensors and numbers only (TorchRL's own holds C++ trees, which ``weights_only`` loads refuse)."""
        every = torch.arange(self._max_capacity)
        max_value, max_index = self._max_priority
        return {
            "alpha": self._alpha,
            "beta": self._beta,
            "eps": self._eps,
            "max_priority": None if max_value is None else torch.as_tensor(max_value),
            "max_priority_index": None if max_index is None else torch.as_tensor(max_index),
            "sum_tree": torch.as_tensor(self._sum_tree[every]),
            "min_tree": torch.as_tensor(self._min_tree[every]),
            "draws": self.draws,
        }

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self._alpha = state_dict["alpha"]
        self._beta = state_dict["beta"]
        self._eps = state_dict["eps"]
        self._init()
        every = torch.arange(self._max_capacity)
        self._sum_tree[every] = state_dict["sum_tree"]
        self._min_tree[every] = state_dict["min_tree"]
        self._max_priority = (state_dict["max_priority"], state_dict["max_priority_index"])
        self.draws = int(state_dict["draws"])

    def dumps(self, path: str | Path) -> None:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        torch.save(self.state_dict(), path / "per_sampler.pt")

    def loads(self, path: str | Path) -> None:
        self.load_state_dict(torch.load(Path(path) / "per_sampler.pt", weights_only=True))

    def __repr__(self) -> str:
        return (
            f"PERSampler(alpha={self.alpha}, beta={self.beta:.3f} -> {self.beta_end} over "
            f"{self.beta_anneal_draws} draws, draws={self.draws})"
        )
