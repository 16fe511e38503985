"""DDPG+HER agent pieces: networks, observation/goal normaliser, loss, exploration; and the shipped trained agents."""

from torchrl_cebp.agents.exploration import HERExploration
from torchrl_cebp.agents.loss import ClippedTD0Estimator, HERDDPGLoss
from torchrl_cebp.agents.networks import make_actor, make_critic
from torchrl_cebp.agents.normalizer import ObsGoalNormalizer, RunningNormalizer
from torchrl_cebp.agents.shipped import SHIPPED_AGENTS, shipped_agent

__all__ = [
    "ClippedTD0Estimator",
    "HERDDPGLoss",
    "HERExploration",
    "ObsGoalNormalizer",
    "RunningNormalizer",
    "SHIPPED_AGENTS",
    "make_actor",
    "make_critic",
    "shipped_agent",
]
