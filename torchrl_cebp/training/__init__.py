"""The DDPG+HER training loop, its config checks, checkpoints and CSV log."""

from torchrl_cebp.training.checkpoint import load_checkpoint, load_policy, save_checkpoint
from torchrl_cebp.training.config import ConfigError, compose_config, validate_config
from torchrl_cebp.training.run_lock import RunFolderInUseError, RunFolderLock
from torchrl_cebp.training.trainer import train

__all__ = [
    "ConfigError", "RunFolderInUseError", "RunFolderLock", "compose_config", "load_checkpoint", "load_policy", "save_checkpoint", "train",
    "validate_config",
]
