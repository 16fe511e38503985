"""Baselines' per-MPI-worker replay in one stock buffer (why, and why not ``ReplayBufferEnsemble``: docs/replay.md)."""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.samplers import PrioritizedSampler, Sampler
from torchrl.data.replay_buffers.scheduler import LinearScheduler
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import stored_lengths
from torchrl_cebp.replay.samplers.base import (EMPTY_STORAGE_ERROR, EpisodeSampler, dump_state, load_state, split_index,
                                               stored_rows)


@dataclass(frozen=True)
class WorkerLayout:
    """Which worker owns each episode row: ``episodes_per_worker`` consecutive rows each, dealt out in turn.

    A buffer that writes ``e x W`` episodes per cycle thus gives worker ``w`` those of its envs ``w e .. w e + e - 1``.
    With a row count that is not a multiple of ``e x W`` (70-step Slide's 14,286 rows) the workers' shares differ by up
    to ``e`` rows, and once the writer wraps around the storage a cycle's envs reach the workers shifted.

    Args:
        workers (int): the number of workers ``W``.
        episodes_per_worker (int, optional): each worker's consecutive rows ``e``. Defaults to 1.

    Examples:
        >>> layout = WorkerLayout(workers=8, episodes_per_worker=2)
        >>> layout.worker_of(torch.tensor([0, 3, 17])).tolist(), layout.rows_of_worker(14286, 7)
        ([0, 1, 0], 1784)
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
        return rows // self.cycle * self.episodes_per_worker + rows % self.episodes_per_worker

    def global_rows(self, local_rows: torch.Tensor, worker: int | torch.Tensor) -> torch.Tensor:
        """The storage rows of ``worker``'s (one, or one per row) ``local_rows``."""
        e = self.episodes_per_worker
        # q e + r -> q (e W) + r as one division and two adds (a division costs three adds): a draw maps all its rows.
        rows = torch.add(local_rows, local_rows // e, alpha=self.cycle - e)
        return rows.add_(worker, alpha=e) if isinstance(worker, torch.Tensor) else rows.add_(worker * e)

    def rows_of_worker(self, rows: int, worker: int) -> int:
        """How many of a storage's first ``rows`` rows are ``worker``'s; worker 0 has the most."""
        full, rest = divmod(rows, self.cycle)
        e = self.episodes_per_worker
        return full * e + min(max(rest - worker * e, 0), e)


class WorkerRows(_upstream.StorageView, Storage):
    """Worker ``w``'s episode rows of a ``[rows, T]`` storage, as a read-only TorchRL storage of their own (a view).

    A sampler reading it through TorchRL's :class:`~torchrl.data.replay_buffers.Storage` interface (``shape``,
    ``max_size``, ``len``, ``get``, :class:`~torchrl.data.RandomSampler`'s draw) sees the worker's rows as its own.

    Args:
        storage (Storage): the episode storage (``ndim=2``).
        worker (int): whose rows.
        layout (WorkerLayout): how the rows are dealt out.

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> storage = EpisodeStorage(8 * 5)  # 8 rows of 5 steps
        >>> storage.set(torch.arange(4), TensorDict({"x": torch.arange(4.0)[:, None].expand(4, 5)}, [4, 5]))
        >>> worker1 = WorkerRows(storage, worker=1, layout=WorkerLayout(workers=2))
        >>> worker1.shape, worker1.max_size, worker1.get(slice(None))["x"][:, 0].tolist()
        (torch.Size([2, 5]), 20, [1.0, 3.0])
    """

    ndim = 2  #: Rows are episodes and columns their steps, as in the viewed storage.

    # Storage.__init__ is not called: it sets max_size, which a view reads from the storage it views.
    def __init__(self, storage: Storage, worker: int, layout: WorkerLayout) -> None:
        self.storage, self.worker, self.layout = storage, worker, layout
        #: The viewed storage's episode-end flag, ``None`` if it keeps none.
        self.end_key: NestedKey | None = getattr(storage, "end_key", None)
        self._gathered: tuple | None = None  # the counts, their total (a view), and write_counts until a write

    @property
    def device(self) -> torch.device:
        """The viewed storage's device."""
        return self.storage.device

    def global_rows(self, local_rows: torch.Tensor) -> torch.Tensor:
        """The storage rows of this worker's ``local_rows``."""
        return self.layout.global_rows(local_rows, self.worker)

    @property
    def shape(self) -> torch.Size:
        """The worker's ``(rows, T)``, its share of the storage's filled rows and the row length."""
        rows, steps = self.storage.shape  # read once: TorchRL's PER asks a view's shape or length 5 times a draw
        return torch.Size((self.layout.rows_of_worker(rows, self.worker), steps))

    @property
    def max_size(self) -> int:
        """This worker's share of the storage's capacity in transitions, its rows of all the storage's times ``T``."""
        row_length = self.storage.shape[1]
        return self.layout.rows_of_worker(self.storage.max_size // row_length, self.worker) * row_length

    def __len__(self) -> int:
        rows, steps = self.storage.shape  # as shape does, without building a torch.Size: TorchRL's PER asks 4 times
        return self.layout.rows_of_worker(rows, self.worker) * steps

    def get(self, index: slice | torch.Tensor | tuple) -> TensorDictBase:
        """Reads this worker's rows from the storage.

        Args:
            index (slice, torch.Tensor or tuple): the worker's own rows (a slice of its filled rows, or a tensor of
                them), or a ``(rows, steps, ...)`` tuple of which only the rows are the worker's.
        """
        if isinstance(index, slice):
            index = torch.arange(self.shape[0])[index]
        if isinstance(index, tuple):
            return self.storage.get((self.global_rows(torch.as_tensor(index[0])), *index[1:]))
        return self.storage.get(self.global_rows(torch.as_tensor(index)))

    def valid_lengths(self, rows: torch.Tensor) -> torch.Tensor:
        """Valid steps of this worker's episodes in ``rows``, as the storage knows them."""
        return stored_lengths(self.storage, self.global_rows(rows), self.end_key)

    def common_length(self) -> int | None:
        """The valid length every episode of the storage shares, else ``None`` (always, if it keeps no lengths)."""
        common_length = getattr(self.storage, "common_length", None)
        return None if common_length is None else common_length()

    def set(self, *args: Any, **kwargs: Any) -> None:
        """Refuses every write: a worker's rows are written, and emptied, through the whole storage.

        Raises:
            RuntimeError: always.
        """
        raise RuntimeError("WorkerRows is a read-only view of a worker's rows: write into, or empty, the whole storage")

    _empty = set

    def state_dict(self) -> dict[str, Any]:
        """An empty state: the whole storage saves the rows."""
        return {}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Accepts the empty state of :meth:`state_dict`.

        Raises:
            ValueError: a state that holds anything.
        """
        if state_dict:
            raise ValueError(f"WorkerRows keeps no state of its own, got {sorted(state_dict)}")

    def contains(self, item: Any) -> bool:
        """Not answered by a view.

        Raises:
            NotImplementedError: always: ask the whole storage.
        """
        raise NotImplementedError("WorkerRows answers no membership: ask the whole storage")

    @property
    def write_counts(self) -> torch.Tensor | None:
        """The storage's write counts of this worker's rows, then of its write starts and ends (``None`` if none)."""
        counts = getattr(self.storage, "write_counts", None)
        if counts is None:
            return None
        # The total is kept as a 0-d view: int() of it costs a third of int(counts[-1]), and every draw reads it.
        if self._gathered is None or self._gathered[0] is not counts:
            self._gathered = counts, counts[-1], None, None
        _, total, seen, gathered = self._gathered
        writes = int(total)  # read first: a write during the gather renews it at the next call
        if writes != seen:
            rows = self.global_rows(torch.arange(self.layout.rows_of_worker(counts.numel() - 1, self.worker)))
            gathered = torch.cat([counts.index_select(0, rows), torch.tensor([writes])])
            self._gathered = counts, total, writes, gathered
        return gathered


class PerWorkerSampler(Sampler):
    """``W`` samplers, one per emulated worker, each over its own episodes: baselines' per-worker replay.

    It wraps any episode sampler of this package, or TorchRL's :class:`~torchrl.data.PrioritizedSampler`, each
    over its worker's :class:`WorkerRows`, so its priorities, episode count and IS weights' normalisation are its own.
    A draw of ``batch_size`` concatenates the workers' draws of ``batch_size // W``, worker 0 first. Built from PERs
    it is a :class:`PrioritizedPerWorkerSampler`, from episode samplers an :class:`EpisodePerWorkerSampler`.

    Args:
        *samplers (Sampler): one fresh sampler instance per worker; their number is ``W``.
        episodes_per_worker (int, optional): consecutive episode rows each worker owns in turn, its envs per cycle
            (baselines' ``rollout_batch_size``): write ``episodes_per_worker x W`` episodes at a time.
            Defaults to ``1``.

    Raises:
        ValueError: if no sampler is given, or one instance is given twice.

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import EpisodeStorage
        >>> from torchrl_cebp.replay.samplers import UniformEpisodeSampler
        >>> sampler = PerWorkerSampler(*[UniformEpisodeSampler() for _ in range(4)], episodes_per_worker=2)
        >>> rb = TensorDictReplayBuffer(storage=EpisodeStorage(16 * 50), sampler=sampler, batch_size=8, dim_extend=0)
        >>> _ = rb.extend(TensorDict({"observation": torch.rand(8, 50, 25)}, [8, 50]))
        >>> (rb.sample()["index"][:, 0] // 2).tolist()  # two draws from each worker's two episodes
        [0, 0, 1, 1, 2, 2, 3, 3]
    """

    def __new__(cls, *samplers: Sampler, episodes_per_worker: int = 1) -> PerWorkerSampler:
        # What the workers' samplers are, it is too: a PrioritizedSampler, which alone TorchRL's
        # rb.update_tensordict_priority(batch) feeds; an EpisodeSampler, which the trainer asks for probabilities.
        if cls is PerWorkerSampler and samplers:
            if all(isinstance(sampler, PrioritizedSampler) for sampler in samplers):
                cls = PrioritizedPerWorkerSampler
            elif all(isinstance(sampler, EpisodeSampler) for sampler in samplers):
                cls = EpisodePerWorkerSampler
        return super().__new__(cls)

    def __init__(self, *samplers: Sampler, episodes_per_worker: int = 1) -> None:
        if not samplers or len({id(sampler) for sampler in samplers}) != len(samplers):
            raise ValueError("PerWorkerSampler needs a separate sampler instance for each worker (at least one)")
        self.samplers = samplers
        self.layout = WorkerLayout(len(samplers), episodes_per_worker)
        self._views: list[WorkerRows] = []

    # One generator drives every worker's draws, in worker order, as SamplerEnsemble shares its own.
    @property
    def _rng(self) -> torch.Generator | None:
        return _upstream.sampler_generator(self.samplers[0])

    @_rng.setter
    def _rng(self, value: torch.Generator | None) -> None:
        for sampler in self.samplers:
            _upstream.give_sampler_generator(sampler, value)

    def worker_views(self, storage: Storage) -> list[WorkerRows]:
        """Each worker's rows of ``storage``, as the storages its sampler sees."""
        if self._views and self._views[0].storage is storage:
            return self._views
        if self._views:  # its workers' samplers hold the priorities of the other storage's rows
            raise ValueError(f"PerWorkerSampler deals out the rows of another storage, not of this "
                             f"{type(storage).__name__}: use one sampler per buffer (a new one, or one given a state)")
        ndim = getattr(storage, "ndim", 1)
        if ndim != 2:
            raise ValueError(f"PerWorkerSampler needs an episode storage with ndim=2, got ndim={ndim}")
        layout, row_length = self.layout, storage.shape[1]
        if storage.max_size // row_length < layout.cycle:  # a write deals out whole cycles: one must fit
            raise ValueError(f"PerWorkerSampler's {layout.workers} workers of episodes_per_worker="
                             f"{layout.episodes_per_worker} take {layout.cycle} episode rows a write, but the storage "
                             f"has {storage.max_size // row_length}: give it a capacity of at least "
                             f"{layout.cycle * row_length} transitions")
        views = [WorkerRows(storage, worker, self.layout) for worker in range(self.layout.workers)]
        for view, sampler in zip(views, self.samplers):
            if getattr(sampler, "max_size", view.max_size) < view.max_size:  # a sampler sized by capacity (PER)
                raise ValueError(f"worker {view.worker}'s {type(sampler).__name__} holds {sampler.max_size} "
                                 f"transitions, but the worker owns {view.max_size} of the storage's "
                                 f"{storage.max_size}")
        self._views = views
        return views

    def _by_worker(self, index: Any) -> list[tuple[int, torch.Tensor, Any]]:
        """Splits a ``(rows, steps)`` / ``[k, 2]`` / rows index by worker: ``(worker, positions, local index)``."""
        stacked = None if isinstance(index, tuple) else torch.as_tensor(index)
        columns = index if stacked is None else stacked.unbind(-1) if stacked.ndim > 1 else (stacked,)
        rows = torch.as_tensor(columns[0])
        workers, local_rows = self.layout.worker_of(rows), self.layout.local_rows(rows)
        parts = []
        for worker in workers.unique().tolist():
            positions = (workers == worker).nonzero().squeeze(-1)
            local = (local_rows[positions], *(column[positions] for column in columns[1:]))
            if stacked is not None:  # back to the form it came in
                local = torch.stack(local, -1) if stacked.ndim > 1 else local[0]
            parts.append((worker, positions, local))
        return parts

    def extend(self, index: torch.Tensor | tuple) -> None:
        """Passes the buffer's notice of a write's ``index`` on to each worker's sampler, in that worker's own rows
        (a PER forgets its largest priority if the write overwrote it)."""
        for worker, _, local in self._by_worker(index):
            self.samplers[worker].extend(local)

    def add(self, index: int | torch.Tensor) -> None:
        """As :meth:`extend`, for the buffer's notice of a one-element write."""
        self.extend(torch.as_tensor(index).unsqueeze(0))

    def mark_update(self, index: torch.Tensor | int, *, storage: Storage | None = None) -> None:
        """Routes a write's rows to their workers' samplers, each with its worker's :class:`WorkerRows` of ``storage``.

        Args:
            index (torch.Tensor or int): the written rows, as the buffer's writer gives them.
            storage (Storage): the buffer's episode storage.

        Raises:
            RuntimeError: no ``storage``.
            ValueError: the write's episodes are not a multiple of ``episodes_per_worker x W``, or this sampler
                cannot deal out ``storage`` (another storage than its own, not ``ndim=2``, or too small for a write).
        """
        if storage is None:
            raise RuntimeError("PerWorkerSampler routes each written episode to its worker's sampler and needs the "
                               "storage: use it inside a replay buffer whose writer notifies it.")
        views = self.worker_views(storage)
        self._require_whole_cycles(stored_rows(index).numel())  # for a storage that runs no check_episodes
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

    def _require_whole_cycles(self, n_episodes: int) -> None:
        if n_episodes % self.layout.cycle:
            raise ValueError(f"PerWorkerSampler deals the episodes of each write to {self.layout.workers} workers, "
                             f"{self.layout.episodes_per_worker} each in turn: write a multiple of {self.layout.cycle} "
                             f"episodes at a time (one per env), got {n_episodes}; other counts would mix the envs' "
                             "lanes across workers")

    def update_priority(self, index: Any, priority: float | torch.Tensor, *, storage: Storage | None = None) -> None:
        """Routes new priorities (TD errors, from ``rb.update_tensordict_priority``) to each transition's worker's
        sampler, in that worker's own rows.

        Args:
            index (Any): the transitions, as the buffer's draw gave them: ``(rows, steps)``, ``[k, 2]`` or rows.
            priority (float or torch.Tensor): one priority for all, or one per transition.
            storage (Storage, optional): the buffer's storage, of which each worker's sampler gets its view.
        """
        priority = torch.as_tensor(priority)
        for worker, positions, local in self._by_worker(index):
            part = priority[positions] if priority.numel() > 1 else priority
            view = None if storage is None else self.worker_views(storage)[worker]
            self.samplers[worker].update_priority(local, part, storage=view)

    def sample(self, storage: Storage, batch_size: int) -> tuple[tuple[torch.Tensor, torch.Tensor], dict]:
        """Draws ``batch_size // W`` transitions from each worker's sampler over its own rows, worker 0 first.

        Args:
            storage (Storage): the buffer's episode storage.
            batch_size (int): the number of transitions, a multiple of ``W``.

        Returns:
            ``((rows, steps), info)`` as storage rows, and ``info`` holding the workers' IS weights under
            ``"priority_weight"`` (each normalised by its own worker's sampler) if their samplers give any.

        Raises:
            ValueError: ``batch_size`` is not a multiple of ``W``.
            RuntimeError: the storage is empty, or a worker holds no episode yet.
        """
        workers = self.layout.workers
        if batch_size % workers:
            raise ValueError(f"PerWorkerSampler draws batch_size // workers from each worker: batch_size={batch_size} "
                             f"must be a multiple of workers={workers}")
        if not len(storage):  # TorchRL's words, which its samplers raise on an empty storage
            raise RuntimeError(EMPTY_STORAGE_ERROR)
        views = self.worker_views(storage)
        # The last worker owns the fewest of the filled rows: if it has one, every worker has.
        if not self.layout.rows_of_worker(storage.shape[0], workers - 1):
            raise RuntimeError(f"PerWorkerSampler: a worker holds no episodes yet: write {self.layout.cycle} "
                               f"episodes at a time, {self.layout.episodes_per_worker} per worker")
        draws = [sampler.sample(view, batch_size // workers) for view, sampler in zip(views, self.samplers)]
        rows, steps = zip(*(split_index(index) for index, _ in draws))
        weights = [torch.as_tensor(info["priority_weight"]) for _, info in draws if "priority_weight" in info]
        worker = torch.arange(workers).repeat_interleave(batch_size // workers)
        rows = self.layout.global_rows(torch.cat(rows), worker)
        return (rows, torch.cat(steps)), ({"priority_weight": torch.cat(weights)} if weights else {})

    def state_dict(self) -> dict[str, Any]:
        """The layout (``workers``, ``episodes_per_worker``) and each worker's sampler's state (``shards``)."""
        return {**asdict(self.layout), "shards": [sampler.state_dict() for sampler in self.samplers]}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Loads a :meth:`state_dict` into the workers' samplers; the sampler then deals out the next storage it meets.

        Raises:
            ValueError: the state's layout differs (another number of workers or of episodes per worker).
        """
        saved, layout = WorkerLayout(state_dict["workers"], state_dict["episodes_per_worker"]), self.layout
        if saved != layout:
            raise ValueError(f"the saved replay has {saved.workers} workers of {saved.episodes_per_worker} episodes "
                             f"per cycle; this PerWorkerSampler has {layout.workers} of {layout.episodes_per_worker}")
        for sampler, state in zip(self.samplers, state_dict["shards"]):
            sampler.load_state_dict(state)
        self._views = []  # as its workers' samplers, it takes the next storage it meets

    def _empty(self) -> None:
        for sampler in self.samplers:
            sampler._empty()

    dumps = dump_state
    loads = load_state

    def __getstate__(self) -> dict[str, Any]:
        # Not PrioritizedSampler's, which refuses copies. A copy views the storage it meets: TorchRL copies no view.
        return {**Sampler.__getstate__(self), "_views": []}

    def __repr__(self) -> str:
        return (f"PerWorkerSampler(workers={self.layout.workers}, "
                f"episodes_per_worker={self.layout.episodes_per_worker}, sampler={self.samplers[0]!r})")


class EpisodePerWorkerSampler(PerWorkerSampler):
    """A :class:`PerWorkerSampler` of episode samplers, which it becomes by itself: an :class:`EpisodeSampler` too.

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
            probabilities[positions] = self.samplers[worker].probabilities(local).double() / self.layout.workers
        return probabilities

    def refit(self, storage: Storage) -> None:
        """Each worker's once-an-epoch re-ranking over its own episodes (MEP's density model)."""
        for view, sampler in zip(self.worker_views(storage), self.samplers):
            sampler.refit(view)


class PrioritizedPerWorkerSampler(PerWorkerSampler, PrioritizedSampler):
    """A :class:`PerWorkerSampler` of :class:`~torchrl.data.PrioritizedSampler` s (PER), which it becomes by itself.

    A PrioritizedSampler to TorchRL, so that ``rb.update_tensordict_priority(batch)`` routes each row's priority to
    its worker's PER (:meth:`PerWorkerSampler.update_priority`). None of PrioritizedSampler's own state is built:
    each of its public attributes answers for the workers' PERs (``max_size``: their sum; ``alpha``, ``beta``,
    ``device``: the value they share).

    Args:
        *samplers (PrioritizedSampler): one PER per worker, as for :class:`PerWorkerSampler`.
        episodes_per_worker (int, optional): as for :class:`PerWorkerSampler`. Defaults to ``1``.

    Examples:
        >>> from torchrl_cebp.replay.samplers import PERSampler
        >>> sampler = PerWorkerSampler(PERSampler(4 * 50), PERSampler(4 * 50))
        >>> type(sampler).__name__, isinstance(sampler, PrioritizedSampler), sampler.max_size, sampler.alpha
        ('PrioritizedPerWorkerSampler', True, 400, 0.6)
    """

    @property
    def max_size(self) -> int:
        """The transitions the workers' PERs hold priorities for, all together."""
        return sum(sampler.max_size for sampler in self.samplers)

    @property
    def device(self) -> torch.device:
        """Where the workers' PERs keep their priorities (worker 0's: a buffer's are on one device)."""
        return self.samplers[0].device

    @property
    def alpha(self) -> float:
        """The workers' priority exponent, one value for all."""
        return self.samplers[0].alpha

    @alpha.setter
    def alpha(self, value: float) -> None:
        for sampler in self.samplers:
            sampler.alpha = value

    @property
    def default_priority(self) -> float:
        """The workers' priority (one value for all) that TorchRL gives transitions written without one."""
        return self.samplers[0].default_priority

    @property
    def reduction(self) -> str:
        """The workers' rule (one for all) by which TorchRL reduces a transition's several priorities to one."""
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
        """Worker 0's TorchRL linear schedule of beta, whose step its state keeps; every worker draws with its beta."""
        first = self.samplers[0]
        if not hasattr(first, "beta_scheduler"):
            raise TypeError(f"the workers' {type(first).__name__} has no beta schedule: PERSampler has one")
        return first.beta_scheduler()

    def sample(self, storage: Storage, batch_size: int) -> tuple[tuple[torch.Tensor, torch.Tensor], dict]:
        """As :meth:`PerWorkerSampler.sample`, every worker drawing with worker 0's beta, the one its schedule steps."""
        self.beta = self.samplers[0].beta  # the schedule steps worker 0's
        return super().sample(storage, batch_size)
