"""Touch-sensing Fetch PickAndPlace, Push, Slide and a Franka pick-and-place as gymnasium and TorchRL envs.

Example:
    >>> from torchrl_cebp.envs import make_env
    >>> make_env("push", seed=0).reset()["touch"].shape
    torch.Size([2])
"""

from torchrl_cebp.envs.franka import FRANKA_TASK, FrankaPickPlaceEnv, make_franka
from torchrl_cebp.envs.franka import register as register_franka
from torchrl_cebp.envs.goal_spaces import GOAL_SPACES, TASKS
from torchrl_cebp.envs.joint_control import CONTROLS
from torchrl_cebp.envs.layout import FETCH_OBSERVATION, ObservationLayout
from torchrl_cebp.envs.reward import compute_reward_of
from torchrl_cebp.envs.torchrl_env import ALL_TASKS, RobotOptions, TouchFetchEnv, make_env, make_env_from_config, make_goal_env
from torchrl_cebp.envs.touch_fetch import gym_id, make_touch_fetch, register

register()
register_franka()

__all__ = [
    "ALL_TASKS",
    "CONTROLS",
    "FETCH_OBSERVATION",
    "FRANKA_TASK",
    "GOAL_SPACES",
    "TASKS",
    "FrankaPickPlaceEnv",
    "ObservationLayout",
    "RobotOptions",
    "TouchFetchEnv",
    "compute_reward_of",
    "gym_id",
    "make_env",
    "make_env_from_config",
    "make_franka",
    "make_goal_env",
    "make_touch_fetch",
]
