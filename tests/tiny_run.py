"""The tests' tiny training config: the real trainer, envs and samplers, a few seconds of training."""
import csv
import shutil
from pathlib import Path


from torchrl_cebp.training.config import compose_config

REPO = Path(__file__).resolve().parents[1]
TINY = [
    "epochs=2",
    "cycles_per_epoch=2",
    "updates_per_cycle=3",
    "batch_size=16",
    "test_episodes=2",
    "replay.capacity=5000",
    "agent.hidden=[32,32]",
]
# What the session's shared run (the ``tiny_run`` fixture) trains: HER on push, two epochs of TINY.
TINY_RUN = ("sampler=her", "env=push")


def config(*overrides: str):
    """The composed ``torchrl_cebp/conf/config.yaml`` with :data:`TINY`, then ``overrides``."""
    return compose_config(*TINY, *overrides)


def rows(csv_path: Path) -> list[dict[str, str]]:
    with csv_path.open(newline="") as f:
        return list(csv.DictReader(f))


def copy_run(run_dir: Path, to: Path) -> Path:
    """A copy of a run directory that a test may change (the session's shared run stays as it was trained)."""
    return Path(shutil.copytree(run_dir, to))
