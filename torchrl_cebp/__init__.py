"""Contact Energy Based Hindsight Experience Prioritization (CEBP) and its baselines, as TorchRL components."""

# Before anything loads MuJoCo: with MUJOCO_GL=osmesa, tensordict's triton import segfaults once
# libOSMesa is loaded, and every subpackage imports one or the other.
import tensordict  # noqa: F401, I001

__version__ = "0.1.0"
