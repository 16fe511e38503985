"""Baselines' per-MPI-worker replay, emulated in one buffer: each worker's episodes, sampler and draw apart.

In baselines' HER (ORIGINAL_CODE.md §3) each of the ``W`` MPI workers owns a replay buffer of the
episodes its own envs collected, computes priorities over it, draws its own batch and normalises its
importance-sampling weights within it (by the batch's largest weight for CEBP, by the smallest priority in its
own trees for PER); the workers' gradients are then summed. For uniform HER one merged buffer drawing
``W x batch`` is the same distribution; for a prioritised sampler it is not (one merged batch puts its
weight scale on its single least likely sample, and turns the weights on once ``W x 256`` episodes are
stored in all rather than 256 per worker).

Why not TorchRL's ``ReplayBufferEnsemble`` / ``SamplerEnsemble``: the ensemble keeps one buffer per
member, and in TorchRL 0.14.1 its routed ``extend`` flattens the written data to single transitions
(``data.reshape(-1)``), which an episode storage refuses; its reads go through ``StorageEnsemble``
and a ``TensorDict`` index (``buffer_ids``, ``index``), so a member buffer's sample unit (HER's
relabelling of the drawn ``(episode, step)`` pairs) never runs, and the priority update of a stock
buffer cannot route its index. A sampler over the one episode storage keeps the stock buffer, HER,
transforms, the ``[B, 2]`` index and the checkpoints exactly as they are.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.data.replay_buffers.samplers import Sampler
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp.replay.samplers.base import split_index
from torchrl_cebp.replay.storage import RowWrites, RowWriteWatch


def storage_rows(
    local_rows: torch.Tensor, worker: int | torch.Tensor, workers: int, episodes_per_worker: int
) -> torch.Tensor:
    """The storage rows of ``worker``'s (one, or one per row) ``local_rows`` (see :class:`WorkerRows`)."""
    e = episodes_per_worker
    return local_rows // e * (e * workers) + worker * e + local_rows % e


class WorkerRows:
    """Worker ``w``'s episode rows of a ``[rows, T]`` storage, as a storage of their own (a view, no copy).

    Rows are dealt out in turn, ``episodes_per_worker`` consecutive rows each: global row ``g``
    belongs to worker ``(g // e) % W`` as its local row ``(g // (e W)) e + g % e``. A buffer that
    writes ``e x W`` episodes per cycle, env ``i`` of the cycle being episode ``i``, thus gives worker
    ``w`` the episodes of its envs ``w e .. w e + e - 1``. With a row count that is not a multiple of
    ``e x W`` the workers' shares differ by up to ``e`` rows, and once the writer wraps around the
    storage a cycle's envs reach the workers shifted; the default capacities (1e6 transitions of 50-
    or 100-step episodes, 16 envs) are multiples, 70-step Slide's 14,286 rows are not. It answers
    what a sampler asks of an episode storage (``ndim``, ``shape`` and ``max_size`` of the filled and
    the whole local rows, ``len``, ``get``) in local rows.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> storage = EpisodeStorage(8 * 5)  # 8 rows of 5 steps
        >>> storage.set(torch.arange(4), TensorDict({"x": torch.arange(4.0)[:, None].expand(4, 5)}, [4, 5]))
        >>> worker1 = WorkerRows(storage, worker=1, workers=2, episodes_per_worker=1)
        >>> worker1.shape, worker1.max_size, worker1.get(slice(None))["x"][:, 0].tolist()
        (torch.Size([2, 5]), 20, [1.0, 3.0])
    """

    ndim = 2

    def __init__(self, storage: Storage, worker: int, workers: int, episodes_per_worker: int) -> None:
        self.storage = storage
        self.worker, self.workers, self.episodes_per_worker = worker, workers, episodes_per_worker
        self._row_writes: WorkerRowWrites | None = None

    @property
    def row_writes(self) -> WorkerRowWrites | None:
        """The storage's shared write counts of this worker's rows (``None`` if it keeps none), always the same
        object: through it the worker's sampler learns of the rows another process wrote, as over a whole storage."""
        writes = getattr(self.storage, "row_writes", None)
        if writes is None:
            return None
        if self._row_writes is None or self._row_writes.writes is not writes:
            every_row = torch.arange(self.rows_within(self.storage.max_size // self.storage.shape[1]))
            self._row_writes = WorkerRowWrites(writes, self.global_rows(every_row))
        return self._row_writes

    def global_rows(self, local_rows: torch.Tensor) -> torch.Tensor:
        """The storage rows of this worker's ``local_rows``."""
        return storage_rows(local_rows, self.worker, self.workers, self.episodes_per_worker)

    def rows_within(self, global_rows: int) -> int:
        """How many of the first ``global_rows`` storage rows are this worker's."""
        return rows_of_worker(global_rows, self.worker, self.workers, self.episodes_per_worker)

    @property
    def shape(self) -> torch.Size:
        return torch.Size([self.rows_within(self.storage.shape[0]), self.storage.shape[1]])

    @property
    def max_size(self) -> int:
        row_length = self.storage.shape[1]
        return self.rows_within(self.storage.max_size // row_length) * row_length

    def __len__(self) -> int:
        return self.shape.numel()

    def get(self, index: slice | torch.Tensor | tuple) -> TensorDictBase:
        if isinstance(index, slice):
            return self.storage.get(self.global_rows(torch.arange(self.shape[0])[index]))
        if isinstance(index, tuple):
            return self.storage.get((self.global_rows(torch.as_tensor(index[0])), *index[1:]))
        return self.storage.get(self.global_rows(torch.as_tensor(index)))


def rows_of_worker(rows: int, worker: int, workers: int, episodes_per_worker: int) -> int:
    """How many of a storage's first ``rows`` rows are ``worker``'s (see :class:`WorkerRows`); worker 0 has the most.

    Example:
        >>> rows_of_worker(14286, 0, 8, 2), rows_of_worker(14286, 7, 8, 2)
        (1786, 1784)
    """
    full, rest = divmod(rows, workers * episodes_per_worker)
    return full * episodes_per_worker + min(max(rest - worker * episodes_per_worker, 0), episodes_per_worker)


class WorkerRowWrites:
    """A worker's rows of a storage's :class:`~torchrl_cebp.replay.storage.RowWrites`, read through (never copied).

    What a :class:`~torchrl_cebp.replay.storage.RowWriteWatch` reads: ``per_row`` (in the worker's local rows)
    and ``total``.
    """

    def __init__(self, writes: RowWrites, rows: torch.Tensor) -> None:
        self.writes, self.rows = writes, rows

    @property
    def per_row(self) -> torch.Tensor:
        return self.writes.per_row.index_select(0, self.rows)

    @property
    def total(self) -> torch.Tensor:
        return self.writes.total

    def watch(self) -> RowWriteWatch:
        return RowWriteWatch(self)


class PerWorkerSampler(Sampler):
    """``W`` samplers, one per emulated worker, each over its own episodes: baselines' per-worker replay.

    Put it in place of any episode sampler of this package (or any TorchRL sampler that reaches its
    storage through ``ndim``, ``shape``, ``max_size``, ``len`` and ``get``, as
    :class:`~torchrl.data.PrioritizedSampler` does) in a stock buffer over one episode storage.
    Each worker's sampler sees only that worker's rows (a :class:`WorkerRows` view), so its
    priorities, density model (MEP), segment trees (PER), episode count and importance-sampling
    normalisation are its own. A draw of ``batch_size`` concatenates the ``W`` workers' draws of
    ``batch_size // W``, worker 0 first, with ``"priority_weight"`` normalised by each worker's own sampler.
    Feed TD errors back to PER shards with :func:`~torchrl_cebp.replay.update_td_priorities`
    (``rb.update_priority``): TorchRL's ``rb.update_tensordict_priority`` skips any sampler that is
    not a :class:`~torchrl.data.PrioritizedSampler`, this one included.

    The loss over such a batch is its plain mean: with equal parts that is the mean of the ``W``
    per-worker means, which baselines' sum of the ``W`` workers' gradients equals up to the factor
    ``W``, which Adam ignores (up to its epsilon).

    Args:
        *samplers: one sampler per worker, each a fresh instance (the number of them is ``W``).
        episodes_per_worker (int): consecutive episode rows each worker owns in turn: its envs per
            cycle (baselines' ``rollout_batch_size``, 2). Write ``episodes_per_worker x W`` episodes
            at a time, as the cycles of the trainer do.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> from torchrl_cebp.samplers import InitialCEBPSampler, PerWorkerSampler
        >>> n, T = 8, 50
        >>> episodes = TensorDict({"achieved_goal": torch.rand(n, T, 3), "touch": torch.rand(n, T, 2),
        ...     "observation": torch.rand(n, T, 25),
        ...     "next": {"achieved_goal": torch.rand(n, T, 3), "observation": torch.rand(n, T, 25)}}, [n, T])
        >>> sampler = PerWorkerSampler(*[InitialCEBPSampler(touch_key="touch") for _ in range(4)],
        ...                            episodes_per_worker=2)
        >>> rb = TensorDictReplayBuffer(storage=EpisodeStorage(16 * T), sampler=sampler, batch_size=8, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> rows = rb.sample()["index"][:, 0]
        >>> (rows // 2).tolist() == [0, 0, 1, 1, 2, 2, 3, 3]  # two draws from each worker's two episodes
        True
    """

    def __init__(self, *samplers: Sampler, episodes_per_worker: int = 1) -> None:
        if not samplers:
            raise ValueError("PerWorkerSampler needs one sampler per worker, got none")
        if len({id(sampler) for sampler in samplers}) != len(samplers):
            raise ValueError("PerWorkerSampler needs a separate sampler instance for each worker")
        if episodes_per_worker < 1:
            raise ValueError(f"episodes_per_worker must be a positive integer, got {episodes_per_worker}")
        self.samplers = samplers
        self.episodes_per_worker = episodes_per_worker
        self._rng_private: torch.Generator | None = None
        self._views: list[WorkerRows] = []

    @property
    def workers(self) -> int:
        return len(self.samplers)

    # One generator drives every worker's draws, in worker order, as SamplerEnsemble shares its own.
    @property
    def _rng(self) -> torch.Generator | None:
        return self._rng_private

    @_rng.setter
    def _rng(self, value: torch.Generator | None) -> None:
        self._rng_private = value
        for sampler in self.samplers:
            sampler._rng = value

    def worker_views(self, storage: Storage) -> list[WorkerRows]:
        """Each worker's rows of ``storage``, as the storages its sampler sees."""
        if not self._views or self._views[0].storage is not storage:
            if getattr(storage, "ndim", 1) != 2:
                raise ValueError(
                    f"PerWorkerSampler needs an episode storage with ndim=2, got ndim={getattr(storage, 'ndim', 1)}"
                )
            views = [WorkerRows(storage, worker, self.workers, self.episodes_per_worker) for worker in range(self.workers)]
            for view, sampler in zip(views, self.samplers):
                # A sampler sized by capacity (PER's trees) must cover its worker's rows.
                capacity = getattr(sampler, "max_size", None)
                if capacity is not None and capacity < view.max_size:
                    raise ValueError(
                        f"worker {view.worker}'s {type(sampler).__name__} holds {capacity} transitions, but the "
                        f"worker owns {view.max_size} of the storage's {storage.max_size}"
                    )
            self._views = views
        return self._views

    def _by_worker(self, index: Any) -> list[tuple[int, torch.Tensor, Any]]:
        """Splits a ``[k, 2]`` / ``(rows, steps)`` / rows index by worker: ``(worker, positions, local index)``."""
        if isinstance(index, tuple):
            rows = torch.as_tensor(index[0])
        else:
            index = torch.as_tensor(index)
            rows = index[..., 0] if index.ndim > 1 else index
        e = self.episodes_per_worker
        workers = rows // e % self.workers
        local_rows = rows // (e * self.workers) * e + rows % e
        parts = []
        for worker in workers.unique().tolist():
            positions = (workers == worker).nonzero().squeeze(-1)
            if isinstance(index, tuple):
                local = (local_rows[positions], *(part[positions] for part in index[1:]))
            elif index.ndim > 1:
                local = index[positions].clone()
                local[..., 0] = local_rows[positions]
            else:
                local = local_rows[positions]
            parts.append((worker, positions, local))
        return parts

    # ---- TorchRL sampler interface ----------------------------------------------
    def extend(self, index: torch.Tensor | tuple) -> None:
        for worker, _, local in self._by_worker(index):
            self.samplers[worker].extend(local)

    def add(self, index: int | torch.Tensor) -> None:
        self.extend(torch.as_tensor(index).unsqueeze(0))

    def mark_update(self, index: torch.Tensor | int, *, storage: Storage | None = None) -> None:
        if storage is None:
            raise RuntimeError(
                "PerWorkerSampler routes each written episode to its worker's sampler and needs the storage: "
                "use it inside a replay buffer whose writer notifies it."
            )
        views = self.worker_views(storage)
        for worker, _, local in self._by_worker(index):
            self.samplers[worker].mark_update(local, storage=views[worker])

    def update_priority(
        self, index: torch.Tensor, priority: float | torch.Tensor, *, storage: Storage | None = None
    ) -> None:
        priority = torch.as_tensor(priority)
        for worker, positions, local in self._by_worker(index):
            part = priority[positions] if priority.numel() > 1 else priority
            view = None if storage is None else self.worker_views(storage)[worker]
            self.samplers[worker].update_priority(local, part, storage=view)

    def sample(self, storage: Storage, batch_size: int) -> tuple[tuple[torch.Tensor, torch.Tensor], dict]:
        if batch_size % self.workers:
            raise ValueError(
                f"PerWorkerSampler draws batch_size // workers from each worker: batch_size={batch_size} must be "
                f"a multiple of workers={self.workers}"
            )
        views = self.worker_views(storage)
        # The last worker owns the fewest of the filled rows: if it has one, every worker has.
        if views[-1].rows_within(storage.shape[0]) == 0:
            raise RuntimeError(
                f"PerWorkerSampler: a worker holds no episodes yet: write {self.episodes_per_worker * self.workers} "
                f"episodes at a time, {self.episodes_per_worker} per worker"
            )
        rows, steps, weights = [], [], []
        for view, sampler in zip(views, self.samplers):
            index, info = sampler.sample(view, batch_size // self.workers)
            local_rows, local_steps = split_index(index)
            rows.append(local_rows)
            steps.append(local_steps)
            if "priority_weight" in info:
                weights.append(torch.as_tensor(info["priority_weight"]))
        info = {"priority_weight": torch.cat(weights)} if weights else {}
        # Every worker's local rows to storage rows in one go.
        worker = torch.arange(self.workers).repeat_interleave(batch_size // self.workers)
        global_rows = storage_rows(torch.cat(rows), worker, self.workers, self.episodes_per_worker)
        return (global_rows, torch.cat(steps)), info

    # ---- what the trainer reads ---------------------------------------------------
    @property
    def n_episodes(self) -> int:
        """Episodes stored across the workers."""
        return sum(sampler.n_episodes for sampler in self.samplers)

    def probabilities(self, rows: torch.Tensor) -> torch.Tensor:
        """Probability that one draw of the whole batch takes each of ``rows`` (each worker fills ``1/W`` of it)."""
        probabilities = torch.empty(rows.shape, dtype=torch.float64)
        for worker, positions, local in self._by_worker(rows):
            probabilities[positions] = self.samplers[worker].probabilities(local).double() / self.workers
        return probabilities

    def refit(self, storage: Storage) -> None:
        """Each worker's once-an-epoch re-ranking over its own episodes (MEP's density model)."""
        for view, sampler in zip(self.worker_views(storage), self.samplers):
            refit = getattr(sampler, "refit", None)
            if refit is not None:
                refit(view)

    @property
    def beta(self) -> float:
        """The workers' importance-sampling exponent (PER's), one value for all, so one scheduler anneals it."""
        return self.samplers[0].beta

    @beta.setter
    def beta(self, value: float) -> None:
        for sampler in self.samplers:
            sampler.beta = value

    # ---- state --------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return {
            "workers": self.workers,
            "episodes_per_worker": self.episodes_per_worker,
            "shards": [sampler.state_dict() for sampler in self.samplers],
        }

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self._check_layout(state_dict["workers"], state_dict["episodes_per_worker"])
        for sampler, state in zip(self.samplers, state_dict["shards"]):
            sampler.load_state_dict(state)

    def _check_layout(self, workers: int, episodes_per_worker: int) -> None:
        if (workers, episodes_per_worker) != (self.workers, self.episodes_per_worker):
            raise ValueError(
                f"the saved replay has {workers} workers of {episodes_per_worker} episodes per cycle; this "
                f"PerWorkerSampler has {self.workers} of {self.episodes_per_worker}"
            )

    def _empty(self) -> None:
        for sampler in self.samplers:
            sampler._empty()

    def dumps(self, path: str | Path) -> None:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        layout = {"workers": self.workers, "episodes_per_worker": self.episodes_per_worker}
        (path / "per_worker.json").write_text(json.dumps(layout))
        for worker, sampler in enumerate(self.samplers):
            sampler.dumps(path / f"worker{worker}")

    def loads(self, path: str | Path) -> None:
        path = Path(path)
        layout = json.loads((path / "per_worker.json").read_text())
        self._check_layout(layout["workers"], layout["episodes_per_worker"])
        for worker, sampler in enumerate(self.samplers):
            sampler.loads(path / f"worker{worker}")

    def __repr__(self) -> str:
        return (f"PerWorkerSampler(workers={self.workers}, episodes_per_worker={self.episodes_per_worker}, "
                f"sampler={self.samplers[0]!r})")


def worker_sampler(sampler: Sampler) -> Sampler:
    """The sampler of one worker: ``sampler`` itself unless it is a :class:`PerWorkerSampler` (then its first worker's).

    Example:
        >>> from torchrl_cebp.samplers import PERSampler
        >>> worker_sampler(PerWorkerSampler(PERSampler(100), PERSampler(100)))
        PERSampler(alpha=0.6, beta=0.400 -> 1.0 over 100000 draws)
    """
    return sampler.samplers[0] if isinstance(sampler, PerWorkerSampler) else sampler
