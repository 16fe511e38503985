"""Every private attribute of TorchRL or tensordict the package reaches, in one place.

Each use below has no public equivalent in TorchRL 0.14.1 / tensordict 0.14.3 (pinned in
pyproject.toml). ``tests/test_upstream.py`` pins each one, so an upstream change fails there,
by name, before it can change a draw silently. (The samplers also implement ``Sampler._empty``,
the abstract hook TorchRL's ``Sampler`` requires of every subclass.)
"""
from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data.replay_buffers.samplers import PrioritizedSampler, Sampler
from torchrl.data.replay_buffers.storages import Storage, TensorStorage
from torchrl.data.replay_buffers.writers import RoundRobinWriter


def buffer_generator(storage: Storage) -> torch.Generator | None:
    """The generator a buffer was given (``generator=`` or ``set_rng``).

    ``ReplayBuffer.set_rng`` hands it to its storage, sampler and writer as ``_rng``, with no
    public getter; a sample unit only sees the storage.

    Args:
        storage (Storage): a buffer's storage.
    """
    return getattr(storage, "_rng", None)


def sampler_generator(sampler: Sampler) -> torch.Generator | None:
    """The generator a buffer handed its sampler (``generator=`` or ``set_rng``); ``None``: torch's global RNG.

    ``ReplayBuffer`` always writes it to ``sampler._rng`` (``None`` when the buffer has no generator),
    and a ``Sampler`` subclass has no public getter for it.

    Args:
        sampler (Sampler): a buffer's sampler.
    """
    return getattr(sampler, "_rng", None)


def give_sampler_generator(sampler: Sampler, generator: torch.Generator | None) -> None:
    """Hands ``sampler`` a generator as ``ReplayBuffer`` does (``sampler._rng``, which has no public setter).

    :class:`~torchrl_cebp.replay.samplers.PerWorkerSampler` passes its buffer's generator on to every worker's sampler.
    """
    sampler._rng = generator


class StorageView:
    """A storage view (of ``self.storage``, in its own ``shape``) that TorchRL's ``RandomSampler`` can draw from.

    ``RandomSampler`` draws through ``storage._rand_given_ndim`` (TorchRL's base ``Storage`` has it for ``ndim=1``
    only), with ``storage._rng``: ``ReplayBuffer.set_rng`` gives the generator to the whole storage, not to a view.
    """

    @property
    def _rng(self) -> torch.Generator | None:
        return buffer_generator(self.storage)

    def _rand_given_ndim(self, batch_size: int) -> tuple[torch.Tensor, ...]:
        return tuple(torch.randint(size, (batch_size,), generator=self._rng) for size in self.shape)


# The key under which ``TensorStorage.state_dict`` keeps its stored tensordict's state; the episode storage
# saves only the filled rows there, so that a checkpoint grows with the stored episodes.
STORAGE_STATE_KEY = "_storage"
# The key under which ``ReplayBuffer.state_dict`` keeps its storage's state (a checkpoint's ``"replay"``).
BUFFER_STORAGE_KEY = "_storage"


def round_robin_position(buffer_state: dict[str, Any]) -> tuple[int, int]:
    """The next row a ``ReplayBuffer.state_dict``'s round-robin writer fills, and how many rows it has written.

    The buffer keeps its writer's state under ``"_writer"``, and ``RoundRobinWriter`` names both numbers
    privately; reading a saved buffer's episodes in the order they came needs them.

    Args:
        buffer_state (dict): a ``ReplayBuffer.state_dict()``.
    """
    writer = buffer_state["_writer"]
    return int(writer["_cursor"]), int(writer["_write_count"])


def unchecked_tensordict(source: dict, batch_size: torch.Size, device: torch.device | None) -> TensorDict:
    """A TensorDict over entries already known to fit ``batch_size``, without the per-entry checks.

    ``TensorDict(...)`` validates every leaf; the episode storage's fast read builds one per draw
    from views it laid out itself, and the checks cost as much as the read. Nested dicts in
    ``source`` become nested TensorDicts of the same batch size and device.

    Args:
        source (dict): the entries.
        batch_size (torch.Size): their common leading shape.
        device (torch.device or None): their device.
    """
    return TensorDict._new_unsafe(source=source, batch_size=batch_size, device=device)


def prioritized_state(sampler: PrioritizedSampler) -> dict[str, Any]:
    """A ``PrioritizedSampler``'s state as plain tensors and numbers.

    Its own ``state_dict`` holds the C++ segment trees, which ``torch.load(weights_only=True)``
    refuses; the trees' values and the running maximum are only reachable privately.

    Args:
        sampler (PrioritizedSampler): the sampler.
    """
    return _plain_prioritized(sampler.alpha, sampler.beta, sampler._eps, sampler._max_priority,
                              sampler._sum_tree, sampler._min_tree, sampler.max_size)


def prioritized_state_of(torchrl_state: dict[str, Any]) -> dict[str, Any]:
    """A TorchRL ``PrioritizedSampler.state_dict()`` in :func:`prioritized_state`'s form.

    TorchRL's state names its entries after the sampler's private attributes, and holds the C++ trees.

    Args:
        torchrl_state (dict): a ``PrioritizedSampler.state_dict()``.
    """
    return _plain_prioritized(torchrl_state["_alpha"], torchrl_state["_beta"], torchrl_state["_eps"],
                              torchrl_state["_max_priority"], torchrl_state["_sum_tree"], torchrl_state["_min_tree"],
                              torchrl_state["_sum_tree"].size)


def _plain_prioritized(alpha, beta, eps, max_priority, sum_tree, min_tree, size: int) -> dict[str, Any]:
    every = torch.arange(size)
    max_value, max_index = max_priority
    return {
        # Plain floats: a TorchRL scheduler leaves numpy scalars, which weights_only loads refuse.
        "alpha": float(alpha),
        "beta": float(beta),
        "eps": float(eps),
        # Copies, here and on load: a state shares no tensor with the sampler it came from or went into.
        "max_priority": None if max_value is None else torch.as_tensor(max_value).clone(),
        "max_priority_index": None if max_index is None else torch.as_tensor(max_index).long().clone(),
        "sum_tree": torch.as_tensor(sum_tree[every]),
        "min_tree": torch.as_tensor(min_tree[every]),
    }


def load_prioritized_state(sampler: PrioritizedSampler, state: dict[str, Any]) -> None:
    """Restores what :func:`prioritized_state` saved.

    ``eps``, the trees and the running maximum have no public setter; ``_init()`` empties the trees
    (the exponent is set first, while they are empty, so that its setter has nothing to re-transform).

    Args:
        sampler (PrioritizedSampler): restored in place; its ``max_size`` must be the saved one.
        state (dict): a :func:`prioritized_state`.
    """
    sampler._init()
    sampler.alpha = state["alpha"]
    sampler.beta = state["beta"]
    sampler._eps = state["eps"]
    every = torch.arange(sampler.max_size)
    sampler._sum_tree[every] = state["sum_tree"]
    sampler._min_tree[every] = state["min_tree"]
    saved_maximum = (state["max_priority"], state["max_priority_index"])
    sampler._max_priority = tuple(None if v is None else v.clone() for v in saved_maximum)


def exclude_from_draws(sampler: PrioritizedSampler, index: torch.Tensor) -> None:
    """Gives flat transitions ``index`` probability exactly 0.

    ``update_priority`` stores ``(p + eps) ** alpha``, which is never 0; padding steps of
    variable-length episodes must never be drawn.

    Args:
        sampler (PrioritizedSampler): the sampler.
        index (torch.Tensor): flat transition indices.
    """
    sampler._sum_tree[index] = torch.zeros(index.shape)
    sampler._min_tree[index] = torch.full(index.shape, float("inf"))


def stored_tensordict(storage: TensorStorage) -> TensorDictBase:
    """The tensordict a ``TensorStorage`` keeps its rows in (``storage._storage``).

    :class:`~torchrl_cebp.replay.EpisodeStorage` re-lays it out once, one block per dtype, so that
    a draw reads one contiguous run of memory per transition; TorchRL offers no hook to choose it.
    HER reads its goals through it too: ``storage.get(slice(None))`` is the same view, but costs
    about a third of a whole draw.

    Args:
        storage (TensorStorage): the storage.
    """
    return storage._storage


def replace_stored_tensordict(storage: TensorStorage, data: TensorDictBase) -> None:
    """Makes ``data`` the tensordict the storage reads and writes.

    Args:
        storage (TensorStorage): the storage.
        data (TensorDictBase): same keys, shapes and dtypes as the storage's tensordict.
    """
    storage._storage = data


def record_write(storage: TensorStorage, cursor: torch.Tensor, data: TensorDictBase, set_cursor: bool) -> None:
    """Records a write of ``data`` at ``cursor`` as ``TensorStorage.set`` does: its last cursor, length and revision.

    :class:`~torchrl_cebp.replay.EpisodeStorage` copies a write's rows itself, one block per dtype; TorchRL's own
    ``set`` of no entry would record the same at five times the cost (a quarter of a write), and has no public
    method that records without writing.
    """
    if set_cursor:
        storage._set_last_cursor(cursor)
        storage._get_new_len(data, cursor)
    storage._bump_mutation_revision()


def attached_buffers(storage: Storage) -> list[Any]:
    """The replay buffers reading ``storage`` (``storage.attach`` has no public getter).

    The episode storage checks a write against their samplers' needs, and names their ``dim_extend``
    in its errors, before any row changes: after the write, a sampler that cannot score it would leave
    rows stored that it never draws.

    Args:
        storage (Storage): the storage.
    """
    return list(storage._attached_entities_iter())


def rewind_writers(storage: Storage, rows: torch.Tensor) -> None:
    """Moves the round-robin writers of ``storage``'s buffers back to ``rows[0]``, before a write of ``rows``.

    ``RoundRobinWriter.extend`` moves its cursor and write count (no public setter) before the storage stores
    the write; after a write the storage refused, the next one must go where the refused one would have, or the
    rows in between would count as stored without ever being written.
    """
    for buffer in attached_buffers(storage):
        writer = buffer.writer
        if isinstance(writer, RoundRobinWriter):
            restore_writer_position(writer, (int(rows[0]), writer_position(writer)[1] - rows.numel()))


def writer_position(writer: RoundRobinWriter) -> tuple[Any, Any]:
    """A round-robin writer's cursor and write count (no public getter), to restore after a refused write.

    Args:
        writer (RoundRobinWriter): the writer.
    """
    return writer._cursor, writer._write_count


def restore_writer_position(writer: RoundRobinWriter, position: tuple[Any, Any]) -> None:
    """Sets a round-robin writer's cursor and write count (no public setter), as :func:`writer_position` read them.

    Args:
        writer (RoundRobinWriter): the writer.
        position (tuple): its cursor and write count.
    """
    writer._cursor, writer._write_count = position
