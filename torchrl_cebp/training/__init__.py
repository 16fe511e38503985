"""The DDPG+HER training loop, its config checks, checkpoints and CSV log."""

from torchrl_cebp.training.checkpoint import load_checkpoint, load_policy, save_checkpoint
from torchrl_cebp.training.config import ConfigError, validate_config
from torchrl_cebp.training.trainer import train

__all__ = ["ConfigError", "load_checkpoint", "load_policy", "save_checkpoint", "train", "validate_config"]
