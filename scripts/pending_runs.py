"""Filters a queue of training runs, one line of ``train.py`` overrides each, to those not yet committed.

A run is committed when ``docs/results/comparison/<its run folder>/progress.csv`` holds all its epochs. On a new
machine ``runs/`` is gone, so ``resume=true`` would repeat such a run from epoch 0 (bit for bit on the same CPU, within
float noise on another); this filter skips it instead, and names each skipped run on stderr. Lines pass through
unchanged, in order.

    printf '%s\n' "+comparison=push_standard sampler=her seed=0" | python scripts/pending_runs.py
"""

import argparse
import sys
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.hydra_config import HydraConfig

import torchrl_cebp.training.config  # noqa: F401  (registers the resolvers that name the run folders)

REPO = Path(__file__).resolve().parents[1]
COMMITTED = REPO / "docs" / "results" / "comparison"


def run_folder_and_epochs(overrides: list[str]) -> tuple[Path, int]:
    """The run folder under ``runs/`` that ``train.py <overrides>`` writes, and its number of epochs."""
    cfg = compose("config", overrides=overrides, return_hydra_config=True)
    HydraConfig.instance().set_config(cfg)  # the folder's name reads hydra:runtime.choices
    return Path(cfg.hydra.run.dir).relative_to("runs"), int(cfg.epochs)


def committed_epochs(folder: Path, root: Path = COMMITTED) -> int:
    """How many epochs the committed ``progress.csv`` of a run folder holds (0 when there is none)."""
    csv = root / folder / "progress.csv"
    return max(sum(1 for _ in csv.open()) - 1, 0) if csv.is_file() else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--committed", type=Path, default=COMMITTED, help="the committed run folders (default: %(default)s)")
    args = parser.parse_args()
    with initialize_config_dir(str(REPO / "conf"), version_base="1.3"):
        for line in sys.stdin:
            if not line.strip():
                continue
            folder, epochs = run_folder_and_epochs(line.split())
            done = committed_epochs(folder, args.committed)
            if done >= epochs:
                print(f"[pending] skipped, {done} of {epochs} epochs committed: {folder}", file=sys.stderr)
            else:
                print(line.rstrip("\n"), flush=True)


if __name__ == "__main__":
    main()
