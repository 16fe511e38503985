"""Fetch PickAndPlace, Push and Slide (gymnasium-robotics MuJoCo v4) with a touch sensor on each finger pad.

The touch sites and sensors are added to the XML that ships with gymnasium-robotics through
``mujoco.MjSpec``, so no robot XML is copied. Each step reports the touch of the left and right
finger averaged over the physics substeps in ``info["touch"]`` (also ``env.touch``).

Two robots: ``control="mocap"``, robot A, gymnasium-robotics' Fetch (4-D Cartesian action, the CEBP
code's Initial commit, on which the paper's Fig. 2 was made), and ``control="joint"``, robot B, CPER's
joint-position-controlled Fetch (the released ICRA commit; :mod:`torchrl_cebp.envs.joint_control`).
``touch_ignores_table`` puts the pads on CPER's sensor bodies, which never feel the table;
``touch_in_observation`` appends the step's touch and its running episode sum to the observation
(:mod:`torchrl_cebp.envs.layout`).

Registered gymnasium ids: ``TouchFetch{PickAndPlace,Push,Slide}[Joint][Extended]-v0``: one per
control (the action spaces differ) and goal space (``max_episode_steps`` differs); the touch
options are keyword arguments of ``gym.make``.
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

from gymnasium import spaces

from torchrl_cebp.envs.goal_spaces import GOAL_SPACES, GoalSpace, get_goal_space
from torchrl_cebp.envs.joint_control import CONTROLS, JointController, add_joint_actuators, check_control
from torchrl_cebp.envs.layout import ObservationLayout
from torchrl_cebp.envs.touch import TouchReporting, add_table_blind_touch_pad, add_touch_pad

# CPER's pad geometry; the inner side of the right finger is its local -y, of the left one +y.
_PAD_HALF_SIZE = (0.037, 0.00795, 0.0145)
_FINGERS = (("left", "robot0:l_gripper_finger_link", 1.0), ("right", "robot0:r_gripper_finger_link", -1.0))


def touch_spec(
    model_path: str,
    table_half_size: tuple[float, float] | None = None,
    *,
    control: str = "mocap",
    touch_ignores_table: bool = False,
) -> mujoco.MjSpec:
    """Load a Fetch XML and add a visible touch-sensing box site on each finger's inner pad.

    Args:
        model_path (str): the gymnasium-robotics Fetch XML.
        table_half_size (tuple of float, optional): resizes the table (x, y), keeping its edge next to the
            robot in place; ``None`` keeps the XML's table. Defaults to ``None``.
        control (str, optional): ``"mocap"``, or ``"joint"`` for CPER's joint-controlled robot.
            Defaults to ``"mocap"``.
        touch_ignores_table (bool, optional): puts the pads on sensor bodies that never touch the table.
            Defaults to ``False``.

    Returns:
        the uncompiled ``mujoco.MjSpec``.

    Example:
        >>> import os, gymnasium_robotics
        >>> path = os.path.join(os.path.dirname(gymnasium_robotics.__file__), "envs/assets/fetch/push.xml")
        >>> touch_spec(path).compile().nsensor
        2
        >>> touch_spec(path, control="joint", touch_ignores_table=True).compile().nu
        7
    """
    check_control(control)
    spec = mujoco.MjSpec.from_file(model_path)
    add_pad = add_table_blind_touch_pad if touch_ignores_table else add_touch_pad
    for side, body_name, inward in _FINGERS:
        add_pad(spec, body_name, side, _PAD_HALF_SIZE, (0.001, inward * _PAD_HALF_SIZE[1], 0.0))
    if control == "joint":
        add_joint_actuators(spec)
    if table_half_size is not None:
        table = spec.body("table0")
        top = table.geoms[0]
        table.pos[0] += table_half_size[0] - top.size[0]
        top.size[:2] = table_half_size
    return spec


class _TouchFetchMixin(TouchReporting):
    """Touch sensing, goal space and robot (mocap or joint control) on top of a gymnasium-robotics ``MujocoFetch*Env``."""

    task: str

    def __init__(
        self,
        goal_space: str = "standard",
        control: str = "mocap",
        touch_ignores_table: bool = False,
        touch_in_observation: bool = False,
        max_episode_steps: int | None = None,
        **kwargs: Any,
    ) -> None:
        self.goal_space = goal_space
        self.control = check_control(control)
        self.touch_ignores_table = touch_ignores_table
        self.layout = ObservationLayout(with_touch=touch_in_observation)
        self.space: GoalSpace = get_goal_space(self.task, goal_space)
        self.touch = np.zeros(2)
        self.touch_total = 0.0
        self.joint_controller: JointController | None = None
        super().__init__(**kwargs)
        # The parent constructors hard-code the standard values; the sampling methods read these attributes.
        self.target_offset = np.asarray(self.space.target_offset)
        self.obj_range = self.space.obj_range
        self.target_range = self.space.target_range
        self.distance_threshold = self.space.distance_threshold
        # The Initial commit registered Slide with 70-step episodes on the standard goals.
        self.max_episode_steps = max_episode_steps or self.space.max_episode_steps
        if self.joint_controller is not None:
            self.action_space = spaces.Box(-1.0, 1.0, shape=(self.joint_controller.n_actions,), dtype=np.float32)
        EzPickle.__init__(
            self,
            goal_space=goal_space,
            control=control,
            touch_ignores_table=touch_ignores_table,
            touch_in_observation=touch_in_observation,
            max_episode_steps=max_episode_steps,
            **kwargs,
        )

    def _initialize_simulation(self) -> None:
        # As MujocoRobotEnv._initialize_simulation, but compiling the touch-augmented spec.
        spec = touch_spec(
            self.fullpath, self.space.table_half_size, control=self.control, touch_ignores_table=self.touch_ignores_table
        )
        self.model = spec.compile()
        self.data = self._mujoco.MjData(self.model)
        self._model_names = self._utils.MujocoModelNames(self.model)
        self.locate_touch_sensors()
        if self.control == "joint":
            self.joint_controller = JointController(self.model, gripper_blocked=self.block_gripper)
        self.model.vis.global_.offwidth = self.width
        self.model.vis.global_.offheight = self.height
        self._env_setup(initial_qpos=self.initial_qpos)
        self.initial_time = self.data.time
        self.initial_qpos = np.copy(self.data.qpos)
        self.initial_qvel = np.copy(self.data.qvel)

    def _env_setup(self, initial_qpos: dict) -> None:
        if self.joint_controller is None:
            return super()._env_setup(initial_qpos)
        # CPER's initial joints instead of a mocap move. As in CPER, object starts and goals are drawn
        # around the grip of the unperturbed initial pose, fixed for every episode.
        for name, value in initial_qpos.items():
            self._utils.set_joint_qpos(self.model, self.data, name, value)
        self.joint_controller.set_initial_arm(self.data, rng=None)
        self._mujoco.mj_forward(self.model, self.data)
        self.initial_gripper_xpos = self._utils.get_site_xpos(self.model, self.data, "robot0:grip").copy()
        # gymnasium-robotics' initial object pose is 2.5 cm deep in the table (CPER's is 0.5 cm):
        # let it settle, so that the goals on the table are where a resting object's centre can be.
        for _ in range(10):
            self._mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)
        self.height_offset = self._utils.get_site_xpos(self.model, self.data, "object0")[2]

    def _set_action(self, action: np.ndarray) -> None:
        if self.joint_controller is None:
            return super()._set_action(action)
        self.joint_controller.apply(self.data, action)

    def _mujoco_step(self, action: np.ndarray) -> None:
        # One substep at a time so the touch can be averaged over the whole env step.
        total = np.zeros(2)
        for _ in range(self.n_substeps):
            self._mujoco.mj_step(self.model, self.data)
            total += self.substep_touch()
        self.touch = total / self.n_substeps
        self.touch_total += float(self.touch.sum())

    def _reset_sim(self) -> bool:
        # As MujocoFetchEnv._reset_sim, with the joint robot's perturbed start and the goal space's object start.
        self._mujoco.mj_resetData(self.model, self.data)
        self.data.time = self.initial_time
        self.data.qpos[:] = np.copy(self.initial_qpos)
        self.data.qvel[:] = np.copy(self.initial_qvel)
        if self.joint_controller is not None:
            self.joint_controller.set_initial_arm(self.data, self.np_random)
        object_qpos = self._utils.get_joint_qpos(self.model, self.data, "object0:joint")
        object_qpos[:2] = self._sample_object_xy()
        self._utils.set_joint_qpos(self.model, self.data, "object0:joint", object_qpos)
        self._mujoco.mj_forward(self.model, self.data)
        self.touch = self.substep_touch().copy()
        self.touch_total = 0.0
        return True

    def _sample_object_xy(self) -> np.ndarray:
        # At least 0.1 from the gripper; CPER's Slide shifts the draw before that test.
        gripper_xy = self.initial_gripper_xpos[:2]
        object_xy = gripper_xy
        while np.linalg.norm(object_xy - gripper_xy) < 0.1:
            object_xy = gripper_xy + self.np_random.uniform(-self.obj_range, self.obj_range, size=2)
            if self.space.shift_object_x:
                object_xy[0] += self.obj_range
        return object_xy

    def _get_obs(self) -> dict[str, np.ndarray]:
        obs = super()._get_obs()
        if self.layout.with_touch:
            obs["observation"] = np.concatenate([obs["observation"], [self.touch.sum(), self.touch_total]])
        return obs

    def _sample_goal(self) -> np.ndarray:
        if self.space.target_height is None:
            return super()._sample_goal()
        goal = self.initial_gripper_xpos[:3] + self.np_random.uniform(-self.target_range, self.target_range, size=3)
        goal += self.target_offset
        goal[2] = self.height_offset + self.np_random.uniform(0.0, self.space.target_height)
        return goal


class TouchFetchPickAndPlaceEnv(_TouchFetchMixin, MujocoFetchPickAndPlaceEnv):
    """Fetch PickAndPlace with finger touch sensors.

    :func:`make_touch_fetch` builds one by task name.

    Args:
        goal_space (str, optional): ``"standard"`` or ``"extended"``. Defaults to ``"standard"``.
        control (str, optional): ``"mocap"`` (gymnasium-robotics' Fetch) or ``"joint"`` (CPER's
            joint-controlled Fetch). Defaults to ``"mocap"``.
        touch_ignores_table (bool, optional): puts the pads on sensor bodies that never feel the table.
            Defaults to ``False``.
        touch_in_observation (bool, optional): appends the step's touch and its running episode sum to the
            observation. Defaults to ``False``.
        max_episode_steps (int, optional): the episode length. Defaults to ``None``: the goal space's.
        **kwargs: forwarded to the gymnasium-robotics env (``render_mode``, ``width``, ``height``, ...).

    Raises:
        ValueError: an unknown goal space or control.

    Example:
        >>> env = TouchFetchPickAndPlaceEnv(goal_space="extended")
        >>> _, info = env.reset(seed=0)
        >>> info["touch"].shape
        (2,)
    """

    task = "pick_place"


class TouchFetchPushEnv(_TouchFetchMixin, MujocoFetchPushEnv):
    """Fetch Push (gripper blocked closed) with finger touch sensors.

    :func:`make_touch_fetch` builds one by task name.

    Args:
        **kwargs: the arguments of :class:`TouchFetchPickAndPlaceEnv` (``goal_space``, ``control``,
            ``touch_ignores_table``, ``touch_in_observation``, ``max_episode_steps``, and the gymnasium-robotics
            env's), with the same defaults.

    Raises:
        ValueError: an unknown goal space or control.

    Example:
        >>> env = TouchFetchPushEnv()
        >>> _ = env.reset(seed=0)
        >>> env.step(env.action_space.sample())[4]["touch"].shape
        (2,)
    """

    task = "push"


class TouchFetchSlideEnv(_TouchFetchMixin, MujocoFetchSlideEnv):
    """Fetch Slide with finger touch sensors.

    :func:`make_touch_fetch` builds one by task name.

    Args:
        **kwargs: the arguments of :class:`TouchFetchPickAndPlaceEnv` (``goal_space``, ``control``,
            ``touch_ignores_table``, ``touch_in_observation``, ``max_episode_steps``, and the gymnasium-robotics
            env's), with the same defaults.

    Raises:
        ValueError: an unknown goal space or control.

    Example:
        >>> TouchFetchSlideEnv(goal_space="extended").max_episode_steps
        70
    """

    task = "slide"


# What render() frames: the table top, near enough to see the object and the goal (the red sphere). gymnasium-robotics'
# own camera frames the whole robot from 2.5 m, where a 5 cm block is a few pixels.
RENDER_CAMERA = {"distance": 1.0, "azimuth": 150.0, "elevation": -30.0, "lookat": np.array([1.3, 0.75, 0.45])}

TOUCH_FETCH_CLASSES: dict[str, type[_TouchFetchMixin]] = {
    cls.task: cls for cls in (TouchFetchPickAndPlaceEnv, TouchFetchPushEnv, TouchFetchSlideEnv)
}


def make_touch_fetch(task: str, goal_space: str = "standard", **kwargs: Any) -> _TouchFetchMixin:
    """Build the (unwrapped) gymnasium touch-sensing Fetch env.

    Args:
        task (str): ``"pick_place"``, ``"push"`` or ``"slide"``.
        goal_space (str, optional): ``"standard"`` or ``"extended"``. Defaults to ``"standard"``.
        **kwargs: ``control`` (``"mocap"`` or ``"joint"``, default ``"mocap"``), ``touch_ignores_table``
            and ``touch_in_observation`` (default ``False``; see :class:`~torchrl_cebp.envs.RobotOptions`),
            ``max_episode_steps`` (default: the goal space's), and gymnasium-robotics' own
            (``render_mode``, ``width``, ``height``, ``default_camera_config`` (default :data:`RENDER_CAMERA`), ...).

    Raises:
        ValueError: an unknown task, goal space or control.

    Example:
        >>> env = make_touch_fetch("push", "extended", render_mode="rgb_array", width=64, height=48)
        >>> env.reset(seed=1)[0]["observation"].shape
        (25,)
        >>> env = make_touch_fetch("pick_place", "extended", control="joint", touch_in_observation=True)
        >>> env.action_space.shape, env.reset(seed=1)[0]["observation"].shape
        ((8,), (27,))
    """
    get_goal_space(task, goal_space)  # validates both names before any model is built
    return TOUCH_FETCH_CLASSES[task](goal_space=goal_space, **{"default_camera_config": RENDER_CAMERA, **kwargs})


def gym_id(task: str, goal_space: str = "standard", control: str = "mocap") -> str:
    """The registered gymnasium id of ``task`` under ``goal_space`` and ``control``.

    Args:
        task (str): ``"pick_place"``, ``"push"`` or ``"slide"``.
        goal_space (str, optional): ``"standard"`` or ``"extended"``. Defaults to ``"standard"``.
        control (str, optional): ``"mocap"`` or ``"joint"``. Defaults to ``"mocap"``.

    Example:
        >>> gym_id("pick_place", "extended"), gym_id("push", "extended", "joint")
        ('TouchFetchPickAndPlaceExtended-v0', 'TouchFetchPushJointExtended-v0')
    """
    get_goal_space(task, goal_space)
    check_control(control)
    name = TOUCH_FETCH_CLASSES[task].__name__.removesuffix("Env")
    return f"{name}{'Joint' if control == 'joint' else ''}{'Extended' if goal_space == 'extended' else ''}-v0"


def register() -> None:
    """Register every task x goal space x control with gymnasium (idempotent).

    Example:
        >>> import gymnasium as gym
        >>> register()
        >>> gym.spec("TouchFetchSlideExtended-v0").max_episode_steps
        70
        >>> gym.make("TouchFetchPushJointExtended-v0", touch_ignores_table=True).action_space.shape
        (7,)
    """
    for task, cls in TOUCH_FETCH_CLASSES.items():
        for name in GOAL_SPACES:
            for control in CONTROLS:
                env_id = gym_id(task, name, control)
                if env_id not in gym.registry:
                    gym.register(
                        id=env_id,
                        entry_point=f"{__name__}:{cls.__name__}",
                        kwargs={"goal_space": name, "control": control},
                        max_episode_steps=get_goal_space(task, name).max_episode_steps,
                    )
