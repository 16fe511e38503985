"""Per-epoch CSV log."""

from __future__ import annotations

import csv
import functools
import subprocess
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.record.loggers import Logger, get_logger

from torchrl_cebp.replay.episodes import episode_lengths, next_key

CSV_NAME = "progress.csv"
# Where the per-epoch rows go besides the CSV, through TorchRL's loggers.
LOGGERS = ("none", "tensorboard", "wandb", "mlflow")


def make_logger(kind: str, run_dir: str | Path) -> Logger | None:
    """A TorchRL logger writing under ``run_dir/logs`` (``None`` for ``"none"``).

    ``tensorboard`` needs the ``tensorboard`` package, ``wandb`` and ``mlflow`` theirs
    (``pip install torchrl-cebp[loggers]``); set ``WANDB_MODE=offline`` to log W&B without a network.

    Args:
        kind (str): one of ``"none"``, ``"tensorboard"``, ``"wandb"``, ``"mlflow"``.
        run_dir (str or Path): the run's folder; its name is the experiment's.

    Raises:
        ValueError: an unknown ``kind``.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     make_logger("none", d) is None
        True
    """
    if kind not in LOGGERS:
        raise ValueError(f"unknown logger {kind!r}; valid loggers: {list(LOGGERS)}")
    if kind == "none":
        return None
    run_dir = Path(run_dir)
    extra = {"wandb_kwargs": {"project": "torchrl-cebp"}} if kind == "wandb" else {}
    return get_logger(kind, logger_name=str(run_dir / "logs"), experiment_name=run_dir.name, **extra)


# What a run executes: the package (its configs included) and its entry point. Edits anywhere else (the docs, or the result
# rows that scripts/sync_results.sh commits while a sweep runs) leave a row's code clean.
RUN_SOURCES = ("torchrl_cebp", "train.py", "pyproject.toml")


@functools.cache
def code_version(checkout: str | Path | None = None) -> str:
    """The git commit of the package's checkout, or ``unknown`` outside git.

    ``+dirty`` is appended when the files a run executes (:data:`RUN_SOURCES`) differ from that commit.
    Read once per process (and ``checkout``): the runs of an in-process sweep keep running the code the
    process loaded, whatever later commits move the checkout's HEAD to.

    Args:
        checkout (str or Path, optional): the git checkout; ``None`` is the one the package lives in.
            Defaults to ``None``.

    Example:
        >>> len(code_version()) > 0
        True
    """
    root = Path(checkout) if checkout is not None else Path(__file__).resolve().parents[2]

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=root, capture_output=True, text=True, timeout=10, check=True
        ).stdout.strip()

    try:
        commit = git("rev-parse", "--short=12", "HEAD")
        changed = git("status", "--porcelain", "--", *RUN_SOURCES)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{commit}+dirty" if changed else commit


class EpochCsv:
    """Appends one row per epoch to a CSV file; the columns are fixed by the first row.

    Rows are flushed at once, so the file is complete up to the last finished epoch.
    When resuming, rows of epochs at or after ``start_epoch`` (written after the last
    checkpoint) are dropped first.

    Args:
        path (str or Path): the CSV file.
        start_epoch (int, optional): the first epoch this run writes; ``0`` starts a new file.
            Defaults to ``0``.

    Examples:
        >>> import tempfile, pathlib
        >>> with tempfile.TemporaryDirectory() as d:
        ...     log = EpochCsv(pathlib.Path(d) / "progress.csv")
        ...     log.write({"epoch": 0, "test_success": 0.5})
        ...     log.write({"epoch": 1, "test_success": 0.75})
        ...     resumed = EpochCsv(log.path, start_epoch=1)
        ...     resumed.write({"epoch": 1, "test_success": 0.75, "load_avg": 2.0})
        ...     resumed.path.read_text().splitlines()
        ['epoch,test_success,load_avg', '0,0.5,', '1,0.75,2.0']
    """

    def __init__(self, path: str | Path, start_epoch: int = 0) -> None:
        self.path = Path(path)
        self._fields: list[str] | None = None
        if start_epoch > 0 and self.path.exists():
            with self.path.open(newline="") as f:
                reader = csv.DictReader(f)
                self._fields = list(reader.fieldnames or [])
                kept = [row for row in reader if int(row["epoch"]) < start_epoch]
            self._rewrite(kept)
        else:
            self.path.unlink(missing_ok=True)

    def _rewrite(self, rows: list[dict[str, Any]]) -> None:
        with self.path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self._fields)
            writer.writeheader()
            writer.writerows(rows)

    def write(self, row: dict[str, Any]) -> None:
        """Appends ``row``; columns it adds are added to the header, empty in earlier rows.

        Args:
            row (dict): column name to value.
        """
        if self._fields is None:
            self._fields = list(row)
            self._rewrite([])
        elif set(row) - set(self._fields):
            # A run resumed by newer code that logs more columns: earlier rows get them empty.
            with self.path.open(newline="") as f:
                kept = list(csv.DictReader(f))
            self._fields += [key for key in row if key not in self._fields]
            self._rewrite(kept)
        with self.path.open("a", newline="") as f:
            csv.DictWriter(f, fieldnames=self._fields).writerow(row)


class EpochLog:
    """Where an epoch's row goes: ``run_dir/progress.csv`` and the configured TorchRL logger.

    Every CSV row names the code's commit and the instruction set torch's CPU kernels dispatched to (``AVX512``,
    ``AVX2``, ...) it ran on.

    Args:
        run_dir (str or Path): the run's folder.
        start_epoch (int): the first epoch this run writes (see :class:`EpochCsv`).
        logger (str): the TorchRL logger (:func:`make_logger`).
        labels (dict, optional): text columns written in every CSV row and never logged as scalars.
            Defaults to ``None``.

    Example:
        >>> import tempfile, pathlib
        >>> with tempfile.TemporaryDirectory() as d:
        ...     log = EpochLog(d, start_epoch=0, logger="none")
        ...     log.write(0, {"test_success": 0.5})
        ...     log.csv_path.read_text().splitlines()[0]
        'epoch,test_success,code_commit,cpu_capability'
    """

    def __init__(self, run_dir: str | Path, start_epoch: int, logger: str, labels: dict[str, str] | None = None) -> None:
        self.csv_path = Path(run_dir) / CSV_NAME
        self._csv = EpochCsv(self.csv_path, start_epoch)
        self._logger = make_logger(logger, run_dir)
        # Text columns that say what ran (e.g. the replay layout): in every CSV row, never logged as scalars.
        # Float rounding differs between CPU kernel sets, so one seed diverges across machines as two seeds would.
        self._labels = {
            **(labels or {}),
            "code_commit": code_version(),
            "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        }

    def write(self, epoch: int, row: dict[str, float]) -> None:
        """Writes ``row`` for ``epoch`` to the CSV and its scalars to the logger.

        Args:
            epoch (int): the epoch.
            row (dict): metric name to value.
        """
        self._csv.write({"epoch": epoch, **row, **self._labels})
        if self._logger is not None:
            for key, value in row.items():
                self._logger.log_scalar(key, value, step=epoch)


def exploration_stats(
    first_achieved: torch.Tensor, last_achieved: torch.Tensor, success_radius: float, cell: float = 0.02
) -> dict[str, float]:
    """How far a set of episodes explored, from their achieved goals (the object's position) at start and end.

    - ``explore_moved_share``: the share of episodes whose object ended more than ``success_radius`` from where
      it started, i.e. moved far enough that the episode, relabelled, teaches something about moving it;
    - ``explore_goal_entropy_bits``: the Shannon entropy, in bits, of the episodes' final achieved goals binned
      on a grid of ``cell`` metres; 0 when every object ends in one cell, ``log2(n)`` when each ends in its own.

    Args:
        first_achieved (torch.Tensor): ``[n, goal_dim]`` achieved goals before each episode's first action.
        last_achieved (torch.Tensor): ``[n, goal_dim]`` achieved goals after each episode's last valid step.
        success_radius (float): the task's success distance (the env's ``distance_threshold``).
        cell (float, optional): the grid's cell size in metres. Defaults to ``0.02``.

    Example:
        >>> start = torch.zeros(4, 3)
        >>> end = torch.tensor([[0.0, 0, 0], [0.1, 0, 0], [0.0, 0.1, 0], [0.0, 0.1, 0]])
        >>> exploration_stats(start, end, success_radius=0.05)
        {'explore_moved_share': 0.75, 'explore_goal_entropy_bits': 1.5}
    """
    if first_achieved.shape[0] == 0:
        return {}
    moved = (last_achieved - first_achieved).norm(dim=-1) > success_radius
    _, counts = torch.floor(last_achieved.double() / cell).long().unique(dim=0, return_counts=True)
    shares = counts.double() / counts.sum()
    return {
        "explore_moved_share": moved.double().mean().item(),
        "explore_goal_entropy_bits": (-(shares * shares.log2()).sum()).item() + 0.0,  # + 0.0: -0.0 for one cell
    }


class ExplorationLog:
    """Collects an epoch's episodes' first and last achieved goals and gives :func:`exploration_stats` of them.

    Args:
        success_radius (float): the task's success distance (the env's ``distance_threshold``).
        cell (float, optional): the entropy's grid cell in metres. Defaults to ``0.02``.
        achieved_goal_key (NestedKey, optional): the achieved goal at the root; its ``"next"`` entry is read at
            each episode's last valid step. Defaults to ``"achieved_goal"``.
        end_key (NestedKey, optional): the flag that ends an episode before its row does.
            Defaults to ``("next", "done")``.

    Example:
        >>> from torchrl_cebp.envs import make_env
        >>> env = make_env("push", seed=0, num_envs=2)
        >>> log = ExplorationLog(env.distance_threshold)
        >>> log.update(env.rollout(50))
        >>> sorted(log.compute())
        ['explore_goal_entropy_bits', 'explore_moved_share']
        >>> log.compute()  # compute() starts the next epoch
        {}
        >>> env.close()
    """

    def __init__(self, success_radius: float, cell: float = 0.02, achieved_goal_key: NestedKey = "achieved_goal",
                 end_key: NestedKey = ("next", "done")) -> None:
        self.success_radius, self.cell, self.end_key = success_radius, cell, end_key
        self.achieved_goal_key, self.next_achieved_goal_key = achieved_goal_key, next_key(achieved_goal_key)
        self._first: list[torch.Tensor] = []
        self._last: list[torch.Tensor] = []

    def update(self, episodes: TensorDictBase) -> None:
        """Adds ``[n, T]`` episodes (steps after an episode's end flag are padding and ignored).

        Args:
            episodes (TensorDictBase): ``[n, T]`` episodes.
        """
        last_step = episode_lengths(episodes, self.end_key) - 1
        self._first.append(episodes.get(self.achieved_goal_key)[:, 0])
        next_achieved = episodes.get(self.next_achieved_goal_key)
        self._last.append(next_achieved[torch.arange(next_achieved.shape[0]), last_step])

    def compute(self) -> dict[str, float]:
        """:func:`exploration_stats` of the episodes added since the last call (``{}`` for none), and a fresh start."""
        if not self._first:
            return {}
        first, last = torch.cat(self._first), torch.cat(self._last)
        self._first, self._last = [], []
        return exploration_stats(first, last, self.success_radius, self.cell)
