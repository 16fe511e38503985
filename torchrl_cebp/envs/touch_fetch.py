"""Fetch PickAndPlace, Push and Slide (gymnasium-robotics MuJoCo v4) with a touch sensor on each finger pad.

The touch sites and sensors are added to the XML that ships with gymnasium-robotics through
``mujoco.MjSpec``, so no robot XML is copied. Each step reports the touch of the left and right
finger averaged over the physics substeps in ``info["touch"]`` (also ``env.touch``).

Registered gymnasium ids: ``TouchFetch{PickAndPlace,Push,Slide}-v0`` (standard goal space) and
``TouchFetch{PickAndPlace,Push,Slide}Extended-v0`` (CPER's goal space); they differ in
``max_episode_steps``, hence one id per goal space.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.utils import EzPickle
from gymnasium_robotics.envs.fetch.pick_and_place import MujocoFetchPickAndPlaceEnv
from gymnasium_robotics.envs.fetch.push import MujocoFetchPushEnv
from gymnasium_robotics.envs.fetch.slide import MujocoFetchSlideEnv

from torchrl_cebp.envs.goal_spaces import GOAL_SPACES, GoalSpace, get_goal_space
from torchrl_cebp.envs.touch import TouchReporting, add_touch_pad

# CPER's pad geometry; the inner side of the right finger is its local -y, of the left one +y.
_PAD_HALF_SIZE = (0.037, 0.00795, 0.0145)
_FINGERS = (("left", "robot0:l_gripper_finger_link", 1.0), ("right", "robot0:r_gripper_finger_link", -1.0))


def touch_spec(model_path: str, table_half_size: tuple[float, float] | None = None) -> mujoco.MjSpec:
    """Load a Fetch XML and add a visible touch-sensing box site on each finger's inner pad.

    ``table_half_size`` resizes the table keeping its edge next to the robot in place.

    Example:
        >>> import os, gymnasium_robotics
        >>> path = os.path.join(os.path.dirname(gymnasium_robotics.__file__), "envs/assets/fetch/push.xml")
        >>> touch_spec(path).compile().nsensor
        2
    """
    spec = mujoco.MjSpec.from_file(model_path)
    for side, body_name, inward in _FINGERS:
        add_touch_pad(spec, body_name, side, _PAD_HALF_SIZE, (0.001, inward * _PAD_HALF_SIZE[1], 0.0))
    if table_half_size is not None:
        table = spec.body("table0")
        top = table.geoms[0]
        table.pos[0] += table_half_size[0] - top.size[0]
        top.size[:2] = table_half_size
    return spec


class _TouchFetchMixin(TouchReporting):
    """Touch sensing and goal-space settings on top of a gymnasium-robotics ``MujocoFetch*Env``."""

    task: str

    def __init__(self, goal_space: str = "standard", **kwargs: Any) -> None:
        self.goal_space = goal_space
        self.space: GoalSpace = get_goal_space(self.task, goal_space)
        self.touch = np.zeros(2)
        super().__init__(**kwargs)
        # The parent constructors hard-code the standard values; the sampling methods read these attributes.
        self.target_offset = np.asarray(self.space.target_offset)
        self.obj_range = self.space.obj_range
        self.target_range = self.space.target_range
        self.distance_threshold = self.space.distance_threshold
        self.max_episode_steps = self.space.max_episode_steps
        EzPickle.__init__(self, goal_space=goal_space, **kwargs)

    def _initialize_simulation(self) -> None:
        # As MujocoRobotEnv._initialize_simulation, but compiling the touch-augmented spec.
        self.model = touch_spec(self.fullpath, self.space.table_half_size).compile()
        self.data = self._mujoco.MjData(self.model)
        self._model_names = self._utils.MujocoModelNames(self.model)
        self.locate_touch_sensors()
        self.model.vis.global_.offwidth = self.width
        self.model.vis.global_.offheight = self.height
        self._env_setup(initial_qpos=self.initial_qpos)
        self.initial_time = self.data.time
        self.initial_qpos = np.copy(self.data.qpos)
        self.initial_qvel = np.copy(self.data.qvel)

    def _mujoco_step(self, action: np.ndarray) -> None:
        # One substep at a time so the touch can be averaged over the whole env step.
        total = np.zeros(2)
        for _ in range(self.n_substeps):
            self._mujoco.mj_step(self.model, self.data)
            total += self.substep_touch()
        self.touch = total / self.n_substeps

    def _reset_sim(self) -> bool:
        super()._reset_sim()
        if self.space.shift_object_x:
            # CPER shifts before rejecting starts within 0.1 of the gripper, so resample rather than translate.
            gripper_xy = self.initial_gripper_xpos[:2]
            object_xy = gripper_xy
            while np.linalg.norm(object_xy - gripper_xy) < 0.1:
                object_xy = gripper_xy + self.np_random.uniform(-self.obj_range, self.obj_range, size=2)
                object_xy[0] += self.obj_range
            object_qpos = self._utils.get_joint_qpos(self.model, self.data, "object0:joint")
            object_qpos[:2] = object_xy
            self._utils.set_joint_qpos(self.model, self.data, "object0:joint", object_qpos)
            self._mujoco.mj_forward(self.model, self.data)
        return True

    def _sample_goal(self) -> np.ndarray:
        if self.space.target_height is None:
            return super()._sample_goal()
        goal = self.initial_gripper_xpos[:3] + self.np_random.uniform(-self.target_range, self.target_range, size=3)
        goal += self.target_offset
        goal[2] = self.height_offset + self.np_random.uniform(0.0, self.space.target_height)
        return goal


class TouchFetchPickAndPlaceEnv(_TouchFetchMixin, MujocoFetchPickAndPlaceEnv):
    """Fetch PickAndPlace with finger touch sensors.

    Example:
        >>> env = TouchFetchPickAndPlaceEnv(goal_space="extended")
        >>> _, info = env.reset(seed=0)
        >>> info["touch"].shape
        (2,)
    """

    task = "pick_place"


class TouchFetchPushEnv(_TouchFetchMixin, MujocoFetchPushEnv):
    """Fetch Push (gripper blocked closed) with finger touch sensors.

    Example:
        >>> env = TouchFetchPushEnv()
        >>> _ = env.reset(seed=0)
        >>> env.step(env.action_space.sample())[4]["touch"].shape
        (2,)
    """

    task = "push"


class TouchFetchSlideEnv(_TouchFetchMixin, MujocoFetchSlideEnv):
    """Fetch Slide with finger touch sensors.

    Example:
        >>> TouchFetchSlideEnv(goal_space="extended").max_episode_steps
        70
    """

    task = "slide"


TOUCH_FETCH_CLASSES: dict[str, type[_TouchFetchMixin]] = {
    cls.task: cls for cls in (TouchFetchPickAndPlaceEnv, TouchFetchPushEnv, TouchFetchSlideEnv)
}


def make_touch_fetch(task: str, goal_space: str = "standard", **kwargs: Any) -> _TouchFetchMixin:
    """Build the (unwrapped) gymnasium touch-sensing Fetch env; ``kwargs`` go to gymnasium-robotics.

    Example:
        >>> env = make_touch_fetch("push", "extended", render_mode="rgb_array", width=64, height=48)
        >>> env.reset(seed=1)[0]["observation"].shape
        (25,)
    """
    get_goal_space(task, goal_space)  # validates both names before any model is built
    return TOUCH_FETCH_CLASSES[task](goal_space=goal_space, **kwargs)


def gym_id(task: str, goal_space: str = "standard") -> str:
    """The registered gymnasium id of ``task`` under ``goal_space``.

    Example:
        >>> gym_id("pick_place", "extended")
        'TouchFetchPickAndPlaceExtended-v0'
    """
    get_goal_space(task, goal_space)
    name = TOUCH_FETCH_CLASSES[task].__name__.removesuffix("Env")
    return f"{name}{'Extended' if goal_space == 'extended' else ''}-v0"


def register() -> None:
    """Register every task x goal space with gymnasium (idempotent).

    Example:
        >>> import gymnasium as gym
        >>> register()
        >>> gym.spec("TouchFetchSlideExtended-v0").max_episode_steps
        70
    """
    for task, cls in TOUCH_FETCH_CLASSES.items():
        for name in GOAL_SPACES:
            env_id = gym_id(task, name)
            if env_id not in gym.registry:
                gym.register(
                    id=env_id,
                    entry_point=f"{__name__}:{cls.__name__}",
                    kwargs={"goal_space": name},
                    max_episode_steps=get_goal_space(task, name).max_episode_steps,
                )
