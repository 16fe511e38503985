"""Touch-sensing Fetch PickAndPlace, Push, Slide and a Franka pick-and-place as gymnasium and TorchRL envs.

Example:
    >>> from torchrl_cebp.envs import make_env
    >>> make_env("push", seed=0).reset()["touch"].shape
    torch.Size([2])
"""

import contextlib
import io
import sys

# gymnasium-robotics prints, at import, a notice on its Adroit tasks' reward versions: on every command of ours, about
# no task of ours. Imported first here, with that notice kept off the terminal and anything else it prints let through.
with contextlib.redirect_stderr(io.StringIO()) as _printed:
    import gymnasium_robotics  # noqa: F401
sys.stderr.write("".join(line for line in _printed.getvalue().splitlines(True) if "AdroitHand" not in line))

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
