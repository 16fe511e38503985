"""Filters a queue of training runs, one line of ``train.py`` overrides each, to those not yet committed.

A run is committed when ``docs/results/comparison/<its run folder>/progress.csv`` holds all its epochs. On a new
machine ``runs/`` is gone, so ``resume=true`` would repeat such a run from epoch 0 (bit for bit on the same CPU, within
float noise on another); this filter skips it instead, and names each skipped run on stderr. Lines pass through
unchanged, in order.

With ``--plan`` it runs nothing and passes nothing: it prints each queued run's epochs done and left, and how long the
rest would take, from the median epoch time of its nearest relatives: this machine's, in ``runs/``, or else the
committed ones of other machines, scaled to this machine's pace. Done means all committed, or
finished in ``runs/`` and resumable there: a run committed in part but absent from ``runs/`` (a new machine) restarts
from epoch 0, and a run killed between its CSV row and its checkpoint counts one epoch it will redo.

    printf '%s\n' "+comparison=push_standard sampler=her seed=0" | python scripts/pending_runs.py
    printf '%s\n' "+comparison=push_standard sampler=her seed=0" | python scripts/pending_runs.py --plan --jobs 2
"""

import argparse
import csv
import statistics
import sys
from pathlib import Path

from hydra.core.hydra_config import HydraConfig

from torchrl_cebp.training.config import compose_config

REPO = Path(__file__).resolve().parents[1]
COMMITTED = REPO / "docs" / "results" / "comparison"
RUNS = REPO / "runs"


def run_folder_and_epochs(overrides: list[str]) -> tuple[Path, int]:
    """The run folder under ``runs/`` that ``train.py <overrides>`` writes, and its number of epochs."""
    cfg = compose_config(*overrides, return_hydra_config=True)
    HydraConfig.instance().set_config(cfg)  # the folder's name reads hydra:runtime.choices
    return Path(cfg.hydra.run.dir).relative_to("runs"), int(cfg.epochs)


def committed_epochs(folder: Path, root: Path = COMMITTED) -> int:
    """How many epochs the committed ``progress.csv`` of a run folder holds (0 when there is none)."""
    progress = root / folder / "progress.csv"
    if not progress.is_file():
        return 0
    with progress.open() as rows:
        return max(sum(1 for _ in rows) - 1, 0)


def relatives(folder: Path) -> list[str]:
    """Glob patterns of a run's relatives, nearest first: its configuration's seeds, then the configurations whose
    names share ever shorter ``-``-separated prefixes with its own (``paper-per_worker-beta0``: ``paper-per_worker*``,
    then ``paper*``), then the sampler's, then the task's. A run folder is ``task/sampler/configuration/seed``."""
    configuration = folder.parent
    parts = configuration.name.split("-")
    prefixes = ["-".join(parts[:n]) + "*" for n in range(len(parts) - 1, 0, -1)]
    return [f"{configuration}/*/progress.csv",
            *(f"{configuration.parent}/{prefix}/*/progress.csv" for prefix in prefixes),
            f"{configuration.parent}/*/*/progress.csv", f"{folder.parts[0]}/**/progress.csv"]


def epoch_seconds(progress: Path) -> list[float]:
    """The ``epoch_s`` of each epoch a ``progress.csv`` holds."""
    with progress.open() as rows:
        return [float(row["epoch_s"]) for row in csv.DictReader(rows) if row.get("epoch_s")]


def tier_seconds(pattern: str, root: Path, skip: frozenset[Path] = frozenset()) -> list[float]:
    """The ``epoch_s`` of every epoch under ``root`` in run folders matching a :func:`relatives` pattern, but ``skip``."""
    return [s for path in sorted(root.glob(pattern)) if path.parent.relative_to(root) not in skip
            for s in epoch_seconds(path)]


def median_epoch_seconds(folder: Path, root: Path, skip: frozenset[Path] = frozenset()) -> float | None:
    """The median ``epoch_s`` over the epochs under ``root`` of a run's nearest :func:`relatives` that have any."""
    for pattern in relatives(folder):
        if seconds := tier_seconds(pattern, root, skip):
            return statistics.median(seconds)
    return None


def live_folders(runs: Path) -> frozenset[Path]:
    """The run folders with epochs in ``runs/``: this machine's, committed copies or not."""
    return frozenset(path.parent.relative_to(runs) for path in runs.glob("**/progress.csv"))


def machine_pace(committed: Path, runs: Path, here: frozenset[Path]) -> float | None:
    """How long this machine's epochs take against other machines': the median, over the runs in ``runs/`` (``here``,
    the :func:`live_folders`), of their median ``epoch_s`` there over that of their nearest committed relatives not
    in ``runs/`` (None without either)."""
    ratios = []
    for folder in here:
        elsewhere = median_epoch_seconds(folder, committed, skip=here)
        if elsewhere and (seconds := epoch_seconds(runs / folder / "progress.csv")):
            ratios.append(statistics.median(seconds) / elsewhere)
    return statistics.median(ratios) if ratios else None


def price(folder: Path, committed: Path, runs: Path, here: frozenset[Path], pace: float | None) -> float | None:
    """A run's seconds per epoch, from its nearest relatives: this machine's epochs in ``runs/`` where that tier has
    any, else the committed ones of other machines (not in ``here``, the :func:`live_folders`) scaled by
    :func:`machine_pace` (None when no tier has any)."""
    for pattern in relatives(folder):
        if seconds := tier_seconds(pattern, runs):
            return statistics.median(seconds)
        if seconds := tier_seconds(pattern, committed, skip=here):
            return statistics.median(seconds) * (1.0 if pace is None else pace)
    return None


def print_plan(queue: list[tuple[Path, int]], committed: Path, runs: Path, jobs: int) -> None:
    """Each run's epochs done and left, and the hours the rest takes at ``jobs`` runs at a time."""
    width = max((len(str(folder)) for folder, _ in queue), default=0)
    here = live_folders(runs)
    pace = machine_pace(committed, runs, here)
    epochs_left = seconds_left = 0.0
    unpriced = []
    for folder, epochs in queue:
        all_committed = committed_epochs(folder, committed) >= epochs
        done = epochs if all_committed else min(committed_epochs(folder, runs), epochs)
        left = epochs - done
        seconds = price(folder, committed, runs, here, pace)
        if left and seconds is None:
            unpriced.append(str(folder))
        epochs_left += left
        seconds_left += left * (seconds or 0.0)
        print(f"{str(folder):<{width}}  {done:>3} of {epochs:>3} epochs done  {left:>3} left")
    at = "" if pace is None else f"; other machines' times {pace:.2f}, this machine's pace against theirs"
    print(f"{int(epochs_left)} run-epochs left; about {seconds_left / 3600 / jobs:.1f} hours at {jobs} run(s) at a time "
          f"(each at the median epoch time of its nearest relatives{at})")
    if unpriced:
        print(f"no relative to price them, so not in the hours: {', '.join(unpriced)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--committed", type=Path, default=COMMITTED, help="the committed run folders (default: %(default)s)")
    parser.add_argument("--plan", action="store_true", help="print what is left of the queue and its hours; run nothing")
    parser.add_argument("--runs", type=Path, default=RUNS, help="the live run folders, for --plan (default: %(default)s)")
    parser.add_argument("--jobs", type=int, default=1, help="runs at a time, for --plan's hours (default: %(default)s)")
    args = parser.parse_args()
    if args.jobs < 1:
        parser.error(f"--jobs must be at least 1, not {args.jobs}")
    plan = []
    for line in sys.stdin:
        if not line.strip():
            continue
        folder, epochs = run_folder_and_epochs(line.split())
        if args.plan:
            plan.append((folder, epochs))
            continue
        done = committed_epochs(folder, args.committed)
        if done >= epochs:
            print(f"[pending] skipped, {done} of {epochs} epochs committed: {folder}", file=sys.stderr)
        else:
            print(line.rstrip("\n"), flush=True)
    if args.plan:
        print_plan(plan, args.committed, args.runs, args.jobs)


if __name__ == "__main__":
    main()
