"""The DDPG+HER training loop, its config checks, checkpoints and CSV log."""

# First: tensordict's triton import crashes once MuJoCo has loaded OSMesa, and the rollout
# worker process starts by importing this package.
import tensordict  # noqa: F401, I001

from torchrl_cebp.training.checkpoint import load_checkpoint, load_policy, save_checkpoint
from torchrl_cebp.training.config import ConfigError, validate_config
from torchrl_cebp.training.trainer import train

__all__ = ["ConfigError", "load_checkpoint", "load_policy", "save_checkpoint", "train", "validate_config"]
