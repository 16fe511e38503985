"""One writer per run folder: a training process holds an exclusive lock on its folder for as long as it runs.

The lock is a POSIX record lock (``fcntl.lockf``) on the folder's ``run.lock``. The operating system drops it when its
process ends in any way, ``kill -9`` included, so a crash leaves no stale lock and ``resume=true`` takes the folder
over at once. A record lock belongs to the process, not to a file descriptor: the env processes a collector forks do
not inherit it, so a killed trainer's orphaned workers never keep its folder locked. The price of that kind of lock: a
process that itself opens and closes ``run.lock`` while holding it (copying its own live run folder, say) drops it.
"""

from __future__ import annotations

import datetime
import fcntl
import json
import os
import socket
from pathlib import Path
from types import TracebackType

LOCK_NAME = "run.lock"


class RunFolderInUseError(RuntimeError):
    """Another process holds the run folder's lock: this one must not write there."""


class RunFolderLock:
    """The exclusive lock of a run folder, held from :meth:`acquire` (or ``with``) to :meth:`release`.

    A second process that asks for a held folder's lock is refused at once with :class:`RunFolderInUseError`, whose
    message names the folder and the holder's pid, host and start time. Within one process the lock nests: a folder
    already held by this process is held again (``train.py`` holds it while it writes Hydra's config, then
    :func:`~torchrl_cebp.training.train` holds it while it trains) and released by the outermost release.

    Args:
        run_dir (str or Path): the run's folder; created if missing.

    Example:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as run_dir:
        ...     with RunFolderLock(run_dir) as lock:  # another process asking now raises RunFolderInUseError
        ...         with RunFolderLock(run_dir):      # this one may hold it again
        ...             pass
        ...         lock.path.name
        'run.lock'
    """

    # Folders this process holds, by resolved path: the open lock file and how many holds are nested in it.
    _held: dict[Path, tuple[int, int]] = {}

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)
        self._key: Path | None = None

    @property
    def path(self) -> Path:
        """The lock file, ``run_dir/run.lock``."""
        return self.run_dir / LOCK_NAME

    def acquire(self) -> None:
        """Takes the folder's lock, or raises at once if another process holds it.

        Raises:
            RunFolderInUseError: another process holds the lock.
            RuntimeError: this lock object already holds it.
        """
        if self._key is not None:
            raise RuntimeError(f"this lock of {self.run_dir} is already held: release it first")
        self.run_dir.mkdir(parents=True, exist_ok=True)
        key = self.path.resolve()
        if key in self._held:
            fd, depth = self._held[key]
            self._held[key] = (fd, depth + 1)
            self._key = key
            return
        fd = os.open(key, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise RunFolderInUseError(
                f"{self.run_dir} is in use by another training process ({self._holder()}): a run folder has one "
                "writer. Wait for that run to end (resume=true then continues it), stop it, or choose another folder "
                "(hydra.run.dir=...)"
            ) from None
        # The holder's identity, for the refusal a second process words. Not needed for the lock itself.
        holder = {"pid": os.getpid(), "host": socket.gethostname(),
                  "since": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(holder).encode(), 0)
        self._held[key] = (fd, 1)
        self._key = key

    def release(self) -> None:
        """Releases this hold; the outermost release of the process unlocks the folder (its lock file stays)."""
        if self._key is None:
            return
        fd, depth = self._held[self._key]
        if depth > 1:
            self._held[self._key] = (fd, depth - 1)
        else:
            del self._held[self._key]
            os.close(fd)  # closing the process's descriptor of the file drops its record lock
        self._key = None

    def _holder(self) -> str:
        try:
            holder = json.loads(self.path.read_text())
            return f"pid {holder['pid']} on {holder['host']}, since {holder['since']}"
        except (OSError, ValueError, KeyError, TypeError):  # written a moment after the lock is taken
            return "holder unknown"

    def __enter__(self) -> RunFolderLock:
        self.acquire()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.release()
