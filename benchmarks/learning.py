"""It learns: DDPG+HER with uniform (HER) and CEBP replay on FetchPush at the paper's scale.

Trains each sampler with ``preset=paper`` (8 workers emulated: 16 episodes per cycle, updates of
2048) on the standard goal space, then prints the test-success curve per epoch, the first epoch
reaching 0.5 and 0.9, and the wall time. Runs are resumable: run the same command again and each
run continues after its last finished epoch (finished runs are only read).

    python benchmarks/learning.py                                  # her and cebp, seed 0, 20 epochs, one after the other
    python benchmarks/learning.py --parallel --epochs 15           # both at once, one core each
    python benchmarks/learning.py --report-only                    # print what the runs hold so far
"""
from __future__ import annotations

import argparse
import csv
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
THRESHOLDS = (0.5, 0.9)


def run_command(sampler: str, seed: int, epochs: int, out: Path, extra: list[str]) -> list[str]:
    return [
        sys.executable, str(REPO / "train.py"), "preset=paper", "env=push", f"sampler={sampler}",
        f"seed={seed}", f"epochs={epochs}", "resume=true", f"hydra.run.dir={out / sampler / f'seed{seed}'}",
        *extra,
    ]


def read_progress(run_dir: Path) -> list[dict[str, float]]:
    path = run_dir / "progress.csv"
    if not path.exists():
        return []
    with path.open(newline="") as f:
        # Every column but the code's commit is a number.
        return [{key: float(value) for key, value in row.items() if value and key != "code_commit"}
                for row in csv.DictReader(f)]


def first_epoch_reaching(rows: list[dict[str, float]], level: float) -> int | None:
    # Success rates are float32 in the CSV (0.9 reads 0.8999999761...): compare with a tolerance.
    return next((int(row["epoch"]) for row in rows if row["test_success"] >= level - 1e-6), None)


def report(out: Path, samplers: list[str], seed: int) -> None:
    runs = {sampler: read_progress(out / sampler / f"seed{seed}") for sampler in samplers}
    epochs = max((len(rows) for rows in runs.values()), default=0)
    print(f"\ntest success per epoch, FetchPush standard goals, workers=8, seed {seed}")
    print("epoch " + "".join(f"{s:>10}" for s in samplers))
    for epoch in range(epochs):
        cells = [f"{rows[epoch]['test_success']:10.3f}" if epoch < len(rows) else f"{'':>10}" for rows in runs.values()]
        print(f"{epoch:5d} " + "".join(cells))
    for sampler, rows in runs.items():
        reached = ", ".join(f">= {level}: epoch {first_epoch_reaching(rows, level)}" for level in THRESHOLDS)
        wall = rows[-1]["wall_s"] / 60 if rows else 0.0
        print(f"{sampler:>8}: {len(rows)} epochs, {reached}, wall {wall:.1f} min")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samplers", nargs="+", default=["her", "cebp"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--out", type=Path, default=REPO / "runs" / "learning")
    parser.add_argument("--parallel", action="store_true", help="run the samplers at the same time")
    parser.add_argument("--report-only", action="store_true")
    parser.add_argument("overrides", nargs="*", help="extra Hydra overrides for train.py")
    args = parser.parse_args()
    if not args.report_only:
        commands = [run_command(s, args.seed, args.epochs, args.out, args.overrides) for s in args.samplers]
        if args.parallel:
            processes = [subprocess.Popen(command) for command in commands]
            codes = [process.wait() for process in processes]
        else:
            codes = [subprocess.call(command) for command in commands]
        if any(codes):
            print(f"warning: some runs failed (exit codes {codes}); the report shows what they finished")
    report(args.out, args.samplers, args.seed)


if __name__ == "__main__":
    main()
