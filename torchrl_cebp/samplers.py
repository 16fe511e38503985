"""The samplers, importable as ``torchrl_cebp.samplers`` (they live in :mod:`torchrl_cebp.replay.samplers`)."""
from torchrl_cebp.replay.samplers import *  # noqa: F401,F403
from torchrl_cebp.replay.samplers import __all__  # noqa: F401
