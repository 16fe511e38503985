"""Prioritized Experience Replay (PER, Schaul et al. 2016) over episode rows."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.samplers import PrioritizedSampler
from torchrl.data.replay_buffers.scheduler import LinearScheduler
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import shared_length, stored_lengths, valid_steps
from torchrl_cebp.replay.samplers.base import SAMPLER_KEY, checked, require_same_sampler, sampler_identity, stored_rows

# The argument that changes as the sampler runs: its state's beta is the annealed one.
ANNEALED = ("beta",)
# Written beside TorchRL's files by PERSampler.dumps.
SCHEDULER_FILE = "beta_scheduler.json"


class PERSampler(PrioritizedSampler):
    """TorchRL's segment-tree :class:`~torchrl.data.PrioritizedSampler` over the transitions of episode rows.

    Priorities are per transition (the padding steps of episodes that ended early at 0); feed TD errors back with
    ``rb.update_tensordict_priority(batch)``. Beta grows linearly from ``beta`` to ``beta_end``, one step of
    :meth:`beta_scheduler` per draw. The formula is on the :doc:`samplers page </samplers>`; the state and dumps are
    TorchRL's sampler's (:meth:`state_dict`, :meth:`dumps`).

    Args:
        capacity (int, optional): storage capacity in transitions, the buffer's. Defaults to ``1_000_000``.
        alpha (float, optional): priority exponent. Defaults to ``0.6``.
        beta (float, optional): initial IS exponent. Defaults to ``0.4``.
        beta_end (float, optional): final IS exponent. Defaults to ``1.0``.
        beta_anneal_draws (int, optional): draws over which beta is annealed. Defaults to ``100_000``.
        eps (float, optional): added to ``|TD error|``. Defaults to ``1e-6``, as in baselines.
        end_key (NestedKey, optional): the flag that ends an episode before its row. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import PERSampler
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * 50, ndim=2), sampler=PERSampler(10 * 50),
        ...                             batch_size=4, dim_extend=0, priority_key="td_error")
        >>> _ = rb.extend(TensorDict({"observation": torch.randn(3, 50, 25)}, [3, 50]))
        >>> batch = rb.sample().set("td_error", torch.rand(4))
        >>> rb.update_tensordict_priority(batch)
        >>> rb.sampler.beta_scheduler().step()
        >>> round(float(rb.sampler.beta), 6)  # one of 100,000 steps from 0.4 to 1
        0.400006
    """

    def __init__(
        self, capacity: int = 1_000_000, alpha: float = 0.6, beta: float = 0.4, beta_end: float = 1.0,
        beta_anneal_draws: int = 100_000, eps: float = 1e-6, *, end_key: NestedKey = ("next", "done"),
    ) -> None:
        capacity = int(checked("PERSampler", "capacity", capacity, minimum=1))
        alpha, beta = checked("PERSampler", "alpha", alpha), checked("PERSampler", "beta", beta)
        super().__init__(capacity, alpha=alpha, beta=beta, eps=checked("PERSampler", "eps", eps, exclusive=True))
        self.beta_end = checked("PERSampler", "beta_end", beta_end)
        self.beta_anneal_draws = int(checked("PERSampler", "beta_anneal_draws", beta_anneal_draws, minimum=1))
        self.end_key = end_key
        self._beta_scheduler = self._new_beta_scheduler()

    def _new_beta_scheduler(self) -> LinearScheduler:
        return LinearScheduler(self, "beta", final_value=self.beta_end, num_steps=self.beta_anneal_draws)

    def beta_scheduler(self) -> LinearScheduler:
        """The sampler's one TorchRL linear scheduler of beta, whose step count its state (and the buffer's) holds."""
        return self._beta_scheduler

    def mark_update(self, index: torch.Tensor | int, *, storage: Storage | None = None) -> None:
        """Gives the written transitions TorchRL's default priority (the largest so far), then keeps the padding
        steps after an episode's end out of the draws.

        Args:
            index (torch.Tensor or int): the written transitions, as the buffer's writer gives them.
            storage (Storage, optional): the buffer's storage; an episode storage (``ndim=2``) tells the padding.

        Raises:
            ValueError: the storage holds more transitions than the sampler (its capacity rounded up to whole
                episodes): build the sampler with the storage's ``max_size``.
        """
        super().mark_update(index, storage=storage)
        if storage is None or getattr(storage, "ndim", 1) != 2:
            return
        row_length = storage.shape[1]
        if storage.max_size > self.max_size:  # TorchRL rounds a 2-D storage up to whole rows on its first write
            raise ValueError(f"the PERSampler holds {self.max_size} transitions, but its storage holds "
                             f"{storage.max_size} ({storage.max_size // row_length} episodes of {row_length} steps, "
                             f"the capacity rounded up to whole episodes): build it with capacity={storage.max_size}")
        if shared_length(storage, self.end_key) == row_length:  # every stored episode whole: no padding to exclude
            return
        rows = stored_rows(index)
        padding = ~valid_steps(stored_lengths(storage, rows, self.end_key), row_length)
        if padding.any():
            rows_of, steps_of = padding.nonzero(as_tuple=True)
            _upstream.exclude_from_draws(self, rows[rows_of] * row_length + steps_of)

    def state_dict(self) -> dict[str, Any]:
        """TorchRL's sampler's state as plain tensors and numbers, which ``torch.load(weights_only=True)`` reads.

        TorchRL's own holds C++ trees; give one of its samplers ``PrioritizedSampler.state_dict(per_sampler)``. It
        also names the sampler's kind and arguments but the annealed ``beta`` (``sampler_identity``).
        """
        return {**_upstream.prioritized_state(self), "beta_scheduler": self._beta_scheduler.state_dict(),
                SAMPLER_KEY: sampler_identity(self, changing=ANNEALED)}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Loads this class's state, or a TorchRL :class:`~torchrl.data.PrioritizedSampler`'s, of the same capacity.

        Raises:
            ValueError: the state holds priorities for another number of transitions, or was saved by a sampler of
                another kind or other arguments.
        """
        require_same_sampler(self, state_dict, changing=ANNEALED)
        # None in a TorchRL sampler's state, nor in ours from before the scheduler was part of it.
        scheduler_state = state_dict.get("beta_scheduler")
        if "_sum_tree" in state_dict:  # TorchRL's: its C++ trees (ours holds their values as tensors)
            state_dict = _upstream.prioritized_state_of(state_dict)
        saved_capacity = state_dict["sum_tree"].numel()
        if saved_capacity != self.max_size:
            raise ValueError(f"the saved PER state holds priorities for {saved_capacity} transitions, this "
                             f"PERSampler for {self.max_size}: build it with capacity={saved_capacity} to load it")
        _upstream.load_prioritized_state(self, state_dict)
        if scheduler_state is not None:
            self._beta_scheduler.load_state_dict(scheduler_state)

    def dumps(self, path: str | Path) -> None:
        """TorchRL's files (trees as memory maps, numbers as JSON), which either sampler loads, and the beta
        scheduler's state beside them."""
        super().dumps(path)
        (Path(path) / SCHEDULER_FILE).write_text(json.dumps(self._beta_scheduler.state_dict()))

    def loads(self, path: str | Path) -> None:
        """Loads what :meth:`dumps` wrote, or a TorchRL :class:`~torchrl.data.PrioritizedSampler`'s dump (which has no
        beta schedule: the schedule keeps its step).

        Raises:
            ValueError: the dump holds priorities for another number of transitions.
        """
        # TorchRL's reader, into a sampler of its own: its loads() fails on a sampler that already holds priorities.
        saved = PrioritizedSampler(self.max_size, alpha=self.alpha, beta=self.beta)
        saved.loads(path)
        state = PrioritizedSampler.state_dict(saved)
        scheduler = Path(path) / SCHEDULER_FILE
        if scheduler.is_file():  # a dump of TorchRL's own sampler has none
            state["beta_scheduler"] = json.loads(scheduler.read_text())
        self.load_state_dict(state)

    # TorchRL's __getstate__ refuses to send the sampler to another process; the scheduler holds a module
    # (its numpy backend), which pickle refuses, so a copy carries the scheduler's state instead.
    def __getstate__(self) -> dict[str, Any]:
        state = dict(super().__getstate__())
        state["_beta_scheduler"] = self._beta_scheduler.state_dict()
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        scheduler_state = state.pop("_beta_scheduler")
        self.__dict__.update(state)
        self._beta_scheduler = self._new_beta_scheduler()
        self._beta_scheduler.load_state_dict(scheduler_state)

    def __repr__(self) -> str:
        return (f"PERSampler(alpha={self.alpha}, beta={self.beta:.3f} -> {self.beta_end} over "
                f"{self.beta_anneal_draws} draws)")
