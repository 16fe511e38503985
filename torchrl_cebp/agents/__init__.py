"""DDPG+HER agent pieces: networks, observation/goal normaliser, loss, exploration."""

from torchrl_cebp.agents.exploration import HERExploration
from torchrl_cebp.agents.loss import ClippedTD0Estimator, HERDDPGLoss
from torchrl_cebp.agents.networks import make_actor, make_critic
from torchrl_cebp.agents.normalizer import ObsGoalNormalizer, RunningNormalizer

__all__ = [
    "ClippedTD0Estimator",
    "HERDDPGLoss",
    "HERExploration",
    "ObsGoalNormalizer",
    "RunningNormalizer",
    "make_actor",
    "make_critic",
]
