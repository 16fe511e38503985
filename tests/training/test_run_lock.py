import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.tiny_run import TINY, config, copy_run, rows
from torchrl_cebp.training import RunFolderInUseError, RunFolderLock, train
from torchrl_cebp.training.checkpoint import CHECKPOINT_NAME
from torchrl_cebp.training.run_lock import LOCK_NAME


def _train_command(run_dir: Path, *overrides: str) -> list[str]:
    # The packaged entry point, as an installed copy runs it.
    return [sys.executable, "-m", "torchrl_cebp.train", *TINY, "resume=true", f"hydra.run.dir={run_dir}", *overrides]


def _wait_for(condition, what: str, timeout: float = 240.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what}: not within {timeout:.0f} s")
        time.sleep(0.2)


def _holder_pid(run_dir: Path) -> int | None:
    try:
        return int((run_dir / LOCK_NAME).read_text().split('"pid": ')[1].split(",")[0])
    except (OSError, IndexError, ValueError):
        return None


def test_a_second_process_is_refused_and_a_killed_holders_folder_is_taken_over_at_once(tmp_path):
    run_dir = tmp_path / "dup"
    first = subprocess.Popen(_train_command(run_dir, "epochs=400"), cwd=tmp_path, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: _holder_pid(run_dir) == first.pid or first.poll() is not None, "the first run's lock")
        second = subprocess.run(_train_command(run_dir, "epochs=400"), cwd=tmp_path, capture_output=True, text=True,
                                timeout=300)
        assert first.poll() is None, "the first run ended before the second tried its folder"
        assert second.returncode == 1 and "Traceback" not in second.stderr, second.stderr
        assert (f"error: {run_dir} is in use by another training process (pid {first.pid} on {socket.gethostname()}"
                in second.stderr)
        assert "per-epoch results" not in second.stdout
        _wait_for(lambda: (run_dir / CHECKPOINT_NAME).exists(), "the first run's first checkpoint")
    finally:
        first.send_signal(signal.SIGKILL)  # kill -9: no cleanup of any kind
        first.wait()
    killed_at = len(rows(run_dir / "progress.csv"))
    resumed = subprocess.run(_train_command(run_dir, f"epochs={killed_at + 2}"), cwd=tmp_path, capture_output=True,
                             text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    epochs = [int(row["epoch"]) for row in rows(run_dir / "progress.csv")]
    assert epochs == list(range(killed_at + 2)), "every epoch once, in order"


def test_a_refused_process_writes_nothing_in_the_folder(tiny_run, tmp_path):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    # Only files other than the lock itself: a process that reads its own lock file closes it, and drops the lock.
    before = {path: path.read_bytes() for path in run_dir.rglob("*") if path.is_file() and path.name != LOCK_NAME}
    with RunFolderLock(run_dir):
        refused = subprocess.run(_train_command(run_dir, "epochs=4", "sampler=per"), cwd=tmp_path,
                                 capture_output=True, text=True, timeout=300)
    assert refused.returncode == 1, refused.stderr
    assert f"(pid {os.getpid()} on {socket.gethostname()}, since " in refused.stderr
    after = {path: path.read_bytes() for path in run_dir.rglob("*") if path.is_file() and path.name != LOCK_NAME}
    assert after == before  # .hydra/ included: Hydra writes it only once the lock is held


@pytest.mark.slow  # a sweep of two real runs
def test_a_sweep_runs_its_free_jobs_and_names_the_refused_one(tmp_path):
    locked = tmp_path / "push-standard/her/default/seed1"
    with RunFolderLock(locked):
        sweep = subprocess.run(
            [sys.executable, "-m", "torchrl_cebp.train", "-m", *TINY, "epochs=1", "seed=0,1", "hydra/launcher=basic",
             f"hydra.sweep.dir={tmp_path}"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert sweep.returncode == 1
    assert f"refused: {locked} is in use by another training process (pid {os.getpid()}" in sweep.stderr
    assert "Error executing job with overrides" in sweep.stderr and "'seed=1'" in sweep.stderr
    assert "Traceback" not in sweep.stderr
    assert [row["epoch"] for row in rows(tmp_path / "push-standard/her/default/seed0/progress.csv")] == ["0"]
    assert not (locked / "progress.csv").exists()


def test_train_holds_the_folder_for_the_whole_run_and_nests_within_one_process(tmp_path):
    with RunFolderLock(tmp_path) as outer:  # as train.py holds it while it writes Hydra's config, then trains
        train(config("epochs=1"), tmp_path)
        other = subprocess.run([sys.executable, "-c", "import sys; from torchrl_cebp.training import RunFolderLock; "
                                "RunFolderLock(sys.argv[1]).acquire()", str(tmp_path)], capture_output=True, text=True)
        assert "RunFolderInUseError" in other.stderr, "train's release must not drop the outer hold"
        with pytest.raises(RuntimeError, match="already held"):
            outer.acquire()
    with RunFolderLock(tmp_path):  # released: free for the next run
        pass


def test_the_library_refuses_a_folder_another_process_trains_in(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from torchrl_cebp.training import RunFolderLock;"
                               " RunFolderLock(sys.argv[1]).acquire(); print('held', flush=True); time.sleep(120)",
                               str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(RunFolderInUseError, match=rf"pid {holder.pid} on "):
            train(config("epochs=1"), tmp_path)
        assert sorted(path.name for path in tmp_path.iterdir()) == [LOCK_NAME]
    finally:
        holder.kill()
        holder.wait()
