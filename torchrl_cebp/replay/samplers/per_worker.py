"""Baselines' per-MPI-worker replay, emulated in one buffer: each worker's episodes, sampler and draw apart.

In baselines' HER (OpenAI baselines' ``her``, which the paper's code extends) each of the ``W`` MPI
workers owns a replay buffer of the episodes its own envs collected, computes priorities over it, draws its
own batch and normalises its importance-sampling weights within it (by the batch's largest weight for CEBP, by the smallest priority in its
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

from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.samplers import PrioritizedSampler, Sampler
from torchrl.data.replay_buffers.scheduler import LinearScheduler
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import shared_length, stored_lengths
from torchrl_cebp.replay.samplers.base import EpisodeSampler, dump_state, load_state, split_index


@dataclass(frozen=True)
class WorkerLayout:
    """Which worker owns each episode row: ``episodes_per_worker`` consecutive rows each, dealt out in turn.

    Global row ``g`` belongs to worker ``(g // e) % W`` as its local row ``(g // (e W)) e + g % e``. A buffer that
    writes ``e x W`` episodes per cycle, env ``i`` of the cycle being episode ``i``, thus gives worker ``w`` the
    episodes of its envs ``w e .. w e + e - 1``. With a row count that is not a multiple of ``e x W`` the workers'
    shares differ by up to ``e`` rows, and once the writer wraps around the storage a cycle's envs reach the workers
    shifted; the default capacities (1e6 transitions of 50- or 100-step episodes, 16 envs) are multiples, 70-step
    Slide's 14,286 rows are not.

    Args:
        workers (int): the number of workers ``W``.
        episodes_per_worker (int, optional): each worker's consecutive rows ``e``. Defaults to 1.

    Examples:
        >>> layout = WorkerLayout(workers=8, episodes_per_worker=2)
        >>> layout.rows_of_worker(14286, 0), layout.rows_of_worker(14286, 7)
        (1786, 1784)
        >>> rows = torch.tensor([0, 3, 17])
        >>> workers = layout.worker_of(rows)
        >>> workers.tolist(), layout.global_rows(layout.local_rows(rows), workers).tolist()
        ([0, 1, 0], [0, 3, 17])
    """

    workers: int
    episodes_per_worker: int = 1

    def __post_init__(self) -> None:
        for name in ("workers", "episodes_per_worker"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}={getattr(self, name)}: must be a positive integer")

    @property
    def cycle(self) -> int:
        """Rows per turn of all the workers, ``e x W``."""
        return self.workers * self.episodes_per_worker

    def worker_of(self, rows: torch.Tensor) -> torch.Tensor:
        """The worker owning each of the storage ``rows``."""
        return rows // self.episodes_per_worker % self.workers

    def local_rows(self, rows: torch.Tensor) -> torch.Tensor:
        """Each of the storage ``rows`` as a row of its worker."""
        e = self.episodes_per_worker
        return rows // self.cycle * e + rows % e

    def global_rows(self, local_rows: torch.Tensor, worker: int | torch.Tensor) -> torch.Tensor:
        """The storage rows of ``worker``'s (one, or one per row) ``local_rows``."""
        e = self.episodes_per_worker
        return local_rows // e * self.cycle + worker * e + local_rows % e

    def rows_of_worker(self, rows: int, worker: int) -> int:
        """How many of a storage's first ``rows`` rows are ``worker``'s; worker 0 has the most."""
        full, rest = divmod(rows, self.cycle)
        e = self.episodes_per_worker
        return full * e + min(max(rest - worker * e, 0), e)


class WorkerRows(Storage):
    """Worker ``w``'s episode rows of a ``[rows, T]`` storage, as a read-only TorchRL storage of their own (a view).

    Rows are dealt to the workers by a :class:`WorkerLayout`. Any sampler reading a storage through
    TorchRL's :class:`~torchrl.data.replay_buffers.Storage` interface (``ndim``, ``shape``, ``max_size``,
    ``len``, ``get``, the random draw of :class:`~torchrl.data.RandomSampler`) reads the worker's rows in its own
    numbering; writes go through the whole storage.

    Args:
        storage (Storage): the episode storage (``ndim=2``).
        worker (int): whose rows.
        layout (WorkerLayout): how the rows are dealt out.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> storage = EpisodeStorage(8 * 5)  # 8 rows of 5 steps
        >>> storage.set(torch.arange(4), TensorDict({"x": torch.arange(4.0)[:, None].expand(4, 5)}, [4, 5]))
        >>> worker1 = WorkerRows(storage, worker=1, layout=WorkerLayout(workers=2))
        >>> worker1.shape, worker1.max_size, worker1.get(slice(None))["x"][:, 0].tolist()
        (torch.Size([2, 5]), 20, [1.0, 3.0])
    """

    ndim = 2

    # Storage.__init__ is not called: it sets max_size, which a view reads from the storage it views.
    def __init__(self, storage: Storage, worker: int, layout: WorkerLayout) -> None:
        self.storage, self.worker, self.layout = storage, worker, layout

    @property
    def _rng(self) -> torch.Generator | None:
        """The generator the buffer gave the whole storage: a stock sampler's draws over the view use it."""
        return _upstream.buffer_generator(self.storage)

    @property
    def device(self) -> torch.device:
        return self.storage.device

    def global_rows(self, local_rows: torch.Tensor) -> torch.Tensor:
        """The storage rows of this worker's ``local_rows``."""
        return self.layout.global_rows(local_rows, self.worker)

    def rows_within(self, global_rows: int) -> int:
        """How many of the first ``global_rows`` storage rows are this worker's."""
        return self.layout.rows_of_worker(global_rows, self.worker)

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

    @property
    def end_key(self) -> NestedKey | None:
        """The flag at which the storage cuts its episodes (``None`` for a storage that cuts none)."""
        return getattr(self.storage, "end_key", None)

    def valid_lengths(self, rows: torch.Tensor) -> torch.Tensor:
        """Valid steps of this worker's episodes in ``rows``, as the storage knows them."""
        return stored_lengths(self.storage, self.global_rows(rows), self.end_key)

    def common_length(self) -> int | None:
        """The valid length every episode of the storage shares, else ``None``."""
        return shared_length(self.storage, self.end_key)

    def _rand_given_ndim(self, batch_size: int) -> tuple[torch.Tensor, torch.Tensor]:
        return tuple(torch.randint(size, (batch_size,), generator=self._rng) for size in self.shape)

    def set(self, cursor: Any, data: Any, *, set_cursor: bool = True) -> None:
        raise RuntimeError("WorkerRows is a read-only view of a worker's rows: write into the whole storage")

    def state_dict(self) -> dict[str, Any]:
        return {}  # a view: the whole storage saves the rows

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        if state_dict:
            raise ValueError(f"WorkerRows keeps no state of its own, got {sorted(state_dict)}")

    def _empty(self) -> None:
        raise RuntimeError("WorkerRows is a read-only view of a worker's rows: empty the whole storage")

    def contains(self, item: Any) -> bool:
        raise NotImplementedError("WorkerRows answers no membership: ask the whole storage")

    @property
    def write_counts(self) -> torch.Tensor | None:
        """The storage's write counts of this worker's rows, then of its write starts and ends (``None`` if none).

        Gathered again only after a write: a draw that follows none costs one read."""
        counts = getattr(self.storage, "write_counts", None)
        if counts is None:
            return None
        source, writes, rows, cached = self.__dict__.get("_counts", (None, None, None, None))
        if source is not counts:  # which storage rows are this worker's: fixed with the storage's counts
            rows = self.global_rows(torch.arange(self.rows_within(counts.numel() - 1)))
        if source is not counts or int(counts[-1]) != writes:
            writes = int(counts[-1])  # read first: a write after it renews the gathered rows at the next call
            cached = torch.cat([counts.index_select(0, rows), torch.tensor([writes])])
            self.__dict__["_counts"] = counts, writes, rows, cached
        return cached


class PerWorkerSampler(Sampler):
    """``W`` samplers, one per emulated worker, each over its own episodes: baselines' per-worker replay.

    Put it in place of any episode sampler of this package (or any TorchRL sampler that reaches its
    storage through ``ndim``, ``shape``, ``max_size``, ``len`` and ``get``, as
    :class:`~torchrl.data.PrioritizedSampler` does) in a stock buffer over one episode storage.
    Each worker's sampler sees only that worker's rows (a :class:`WorkerRows` view), so its
    priorities, density model (MEP), segment trees (PER), episode count and importance-sampling
    normalisation are its own. A draw of ``batch_size`` concatenates the ``W`` workers' draws of
    ``batch_size // W``, worker 0 first, with ``"priority_weight"`` normalised by each worker's own sampler.
    Of PERs it is a :class:`PrioritizedPerWorkerSampler` (a TorchRL ``PrioritizedSampler``), so that
    ``rb.update_tensordict_priority(batch)`` feeds each worker's PER; of episode samplers it is an
    :class:`EpisodePerWorkerSampler` (an :class:`~torchrl_cebp.replay.samplers.EpisodeSampler`).

    The loss over such a batch is its plain mean: with equal parts that is the mean of the ``W``
    per-worker means, which baselines' sum of the ``W`` workers' gradients equals up to the factor
    ``W``, which Adam ignores (up to its epsilon).

    Args:
        *samplers (Sampler): one sampler per worker, each a fresh instance (the number of them is ``W``).
        episodes_per_worker (int, optional): consecutive episode rows each worker owns in turn: its envs per
            cycle (baselines' ``rollout_batch_size``, 2). Write ``episodes_per_worker x W`` episodes
            at a time, as the cycles of the trainer do. Defaults to ``1``.

    Raises:
        ValueError: if no sampler is given, or one instance is given twice.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> from torchrl_cebp.replay.samplers import InitialCEBPSampler, PerWorkerSampler
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

    def __new__(cls, *samplers: Sampler, episodes_per_worker: int = 1) -> PerWorkerSampler:
        # What the workers' samplers are, it is too: a PrioritizedSampler of PERs, so that TorchRL's
        # rb.update_tensordict_priority(batch), which feeds only those, reaches them; an EpisodeSampler of episode
        # samplers, which the trainer asks for the draw's probabilities.
        if cls is PerWorkerSampler and samplers:
            if all(isinstance(sampler, PrioritizedSampler) for sampler in samplers):
                cls = PrioritizedPerWorkerSampler
            elif all(isinstance(sampler, EpisodeSampler) for sampler in samplers):
                cls = EpisodePerWorkerSampler
        return super().__new__(cls)

    def __init__(self, *samplers: Sampler, episodes_per_worker: int = 1) -> None:
        if not samplers:
            raise ValueError("PerWorkerSampler needs one sampler per worker, got none")
        if len({id(sampler) for sampler in samplers}) != len(samplers):
            raise ValueError("PerWorkerSampler needs a separate sampler instance for each worker")
        self.samplers = samplers
        self.layout = WorkerLayout(len(samplers), episodes_per_worker)
        self._rng_private: torch.Generator | None = None
        self._views: list[WorkerRows] = []

    @property
    def workers(self) -> int:
        return self.layout.workers

    @property
    def episodes_per_worker(self) -> int:
        return self.layout.episodes_per_worker

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
            views = [WorkerRows(storage, worker, self.layout) for worker in range(self.workers)]
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
        workers, local_rows = self.layout.worker_of(rows), self.layout.local_rows(rows)
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
        self._check_lanes(index)
        for worker, _, local in self._by_worker(index):
            self.samplers[worker].mark_update(local, storage=views[worker])

    def check_episodes(self, episodes: TensorDictBase) -> None:
        """Refuses episodes a worker's sampler cannot score, or a count that does not deal out to the workers whole."""
        if episodes.ndim == 2:
            self._require_whole_cycles(episodes.shape[0])
        for sampler in self.samplers:
            check = getattr(sampler, "check_episodes", None)
            if check is not None:
                check(episodes)

    def _check_lanes(self, index: Any) -> None:
        """The episode count of :meth:`check_episodes`, for a storage that runs no check before a write."""
        rows = torch.as_tensor(index)
        self._require_whole_cycles((rows[..., 0] if rows.ndim > 1 else rows).unique().numel())

    def _require_whole_cycles(self, n_episodes: int) -> None:
        if n_episodes % self.layout.cycle:
            raise ValueError(
                f"PerWorkerSampler deals the episodes of each write to {self.workers} workers, "
                f"{self.episodes_per_worker} each in turn: write a multiple of {self.layout.cycle} episodes at a time "
                f"(one per env), got {n_episodes}; other counts would mix the envs' lanes across workers"
            )

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
        global_rows = self.layout.global_rows(torch.cat(rows), worker)
        return (global_rows, torch.cat(steps)), info

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

    dumps = dump_state
    loads = load_state

    def __repr__(self) -> str:
        return (f"PerWorkerSampler(workers={self.workers}, episodes_per_worker={self.episodes_per_worker}, "
                f"sampler={self.samplers[0]!r})")


class EpisodePerWorkerSampler(PerWorkerSampler):
    """A :class:`PerWorkerSampler` of episode samplers (:class:`EpisodeSampler`), which it becomes by itself.

    An :class:`EpisodeSampler` over the whole storage: its episode count, draw probabilities and refit
    are the workers' together.

    Args:
        *samplers (EpisodeSampler): one episode sampler per worker, as for :class:`PerWorkerSampler`.
        episodes_per_worker (int, optional): as for :class:`PerWorkerSampler`. Defaults to ``1``.

    Examples:
        >>> from torchrl_cebp.replay.samplers import UniformEpisodeSampler
        >>> sampler = PerWorkerSampler(UniformEpisodeSampler(), UniformEpisodeSampler())
        >>> isinstance(sampler, EpisodeSampler), sampler.n_episodes
        (True, 0)
    """

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
            sampler.refit(view)


class PrioritizedPerWorkerSampler(PerWorkerSampler, PrioritizedSampler):
    """A :class:`PerWorkerSampler` of :class:`~torchrl.data.PrioritizedSampler` s (PER), which it becomes by itself.

    A PrioritizedSampler to TorchRL, so that ``rb.update_tensordict_priority(batch)`` feeds the batch's
    priorities to :meth:`PerWorkerSampler.update_priority`, which routes each row to its worker's PER.
    Everything else is :class:`PerWorkerSampler`'s; none of PrioritizedSampler's own state is built.

    Args:
        *samplers (PrioritizedSampler): one PER per worker, as for :class:`PerWorkerSampler`.
        episodes_per_worker (int, optional): as for :class:`PerWorkerSampler`. Defaults to ``1``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> from torchrl_cebp.replay.samplers import PERSampler
        >>> sampler = PerWorkerSampler(PERSampler(4 * 50), PERSampler(4 * 50))
        >>> type(sampler).__name__
        'PrioritizedPerWorkerSampler'
        >>> rb = TensorDictReplayBuffer(storage=EpisodeStorage(8 * 50), sampler=sampler, batch_size=4,
        ...                             dim_extend=0, priority_key="td_error")
        >>> _ = rb.extend(TensorDict({"observation": torch.randn(2, 50, 25)}, [2, 50]))
        >>> batch = rb.sample()
        >>> _ = batch.set("td_error", torch.full((4,), 1e3))
        >>> rb.update_tensordict_priority(batch)
        >>> [float(shard["max_priority"]) for shard in sampler.state_dict()["shards"]]  # the error fed back
        [1000.0, 1000.0]
    """

    @property
    def default_priority(self) -> float:
        """The priority TorchRL gives a batch without priorities: the workers' (one value for all)."""
        return self.samplers[0].default_priority

    @property
    def reduction(self) -> str:
        """How TorchRL reduces a transition's several priorities to one: the workers' (one rule for all)."""
        return self.samplers[0].reduction

    @property
    def beta(self) -> float:
        """The workers' importance-sampling exponent, one value for all, so that one scheduler anneals it."""
        return self.samplers[0].beta

    @beta.setter
    def beta(self, value: float) -> None:
        for sampler in self.samplers:
            sampler.beta = value

    def beta_scheduler(self) -> LinearScheduler:
        """One linear schedule of every worker's beta, from ``beta`` to the workers' ``beta_end`` over their
        ``beta_anneal_draws`` draws (:class:`~torchrl_cebp.replay.samplers.PERSampler`'s)."""
        first = self.samplers[0]
        if not hasattr(first, "beta_end"):
            raise TypeError(f"the workers' {type(first).__name__} has no beta schedule: PERSampler has one")
        return LinearScheduler(self, "beta", final_value=first.beta_end, num_steps=first.beta_anneal_draws)

    __getstate__ = Sampler.__getstate__  # PrioritizedSampler's refuses every copy; the workers' PERs say why
