"""Train DDPG + HER with a replay sampler on a touch-sensing Fetch task: the package's command line.

    python -m torchrl_cebp.train preset=quick                      # about 20 seconds on 2 CPU cores
    torchrl-cebp-train sampler=cebp env=pick_place                 # the same entry point, installed as a command
    torchrl-cebp-train -m sampler=her,cebp seed=0,1                # sweep, two jobs at a time
    torchrl-cebp-train sampler=cebp env=pick_place resume=true     # continue after the last finished epoch

Options: ``--help``, and the configs shipped in ``torchrl_cebp/conf/``. A run folder has one writer: a second process
on a folder in use is refused before it writes anything, and exits non-zero (in a sweep, its job is named as refused
and the other jobs run).
"""

import sys
from pathlib import Path

import hydra

import torchrl_cebp
from hydra.core.hydra_config import HydraConfig
from hydra.errors import CompactHydraException
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from torchrl_cebp.training import ConfigError, RunFolderInUseError, RunFolderLock, train, validate_config
from torchrl_cebp.training.checkpoint import UnreadableFileError


class RunRefusedError(CompactHydraException):
    """A sweep's run that did not start: Hydra runs the sweep's other jobs, then names this one and exits non-zero."""


def save_hydra_config(cfg: DictConfig, run_dir: str | Path) -> None:
    """Writes the run's config where Hydra would (``.hydra/config.yaml``, ``hydra.yaml``, ``overrides.yaml``).

    The configs set ``hydra.output_subdir: null``, so that Hydra itself writes nothing before the run folder's lock is
    held; this writes the same three files once it is.

    Args:
        cfg (DictConfig): the run's composed config.
        run_dir (str or Path): the run's folder.
    """
    hydra_config = HydraConfig.get()
    folder = Path(run_dir) / ".hydra"
    folder.mkdir(parents=True, exist_ok=True)
    OmegaConf.save(cfg, folder / "config.yaml")
    OmegaConf.save(OmegaConf.create({"hydra": hydra_config}), folder / "hydra.yaml")
    OmegaConf.save(OmegaConf.create(list(hydra_config.overrides.task)), folder / "overrides.yaml")


@hydra.main(config_path="conf", config_name="config", version_base="1.3")
def train_job(cfg: DictConfig) -> None:
    """Trains one run into Hydra's output folder (one job of a sweep with ``-m``)."""
    run_dir = HydraConfig.get().runtime.output_dir
    try:
        validate_config(cfg)  # a wrong value is named before anything is written (train checks it again)
        with RunFolderLock(run_dir):
            save_hydra_config(cfg, run_dir)
            csv_path = train(cfg, run_dir)
    except (ConfigError, RunFolderInUseError, UnreadableFileError) as error:  # a message, not a stack trace
        if HydraConfig.get().mode == RunMode.MULTIRUN:
            print(f"refused: {error}", file=sys.stderr, flush=True)
            raise RunRefusedError(str(error)) from None
        sys.exit(f"error: {error}")
    print(f"per-epoch results: {csv_path}")


def main() -> None:
    """The command line: Hydra's (``--help``, overrides, ``-m``), and ``--version`` for this package's version."""
    if sys.argv[1:] == ["--version"]:  # Hydra's own --version names Hydra's
        print(f"torchrl-cebp {torchrl_cebp.__version__}")
        return
    train_job()


if __name__ == "__main__":
    main()
