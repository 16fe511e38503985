"""Franka Panda pick-and-place with finger touch sensors: the simulated side of the Sim2Real transfer.

The scene is assembled with ``mujoco.MjSpec`` from the Panda MJCF and meshes that ship with
gymnasium-robotics (``kitchen_franka/franka_assets``): the arm is moved by a mocap body welded to the
hand (its joint actuators are removed), the fingers keep their position actuators, a red cube stands
on a table, and a touch sensor covers each finger's inner pad. Sites, joints and the observation
follow gymnasium-robotics' Fetch naming, so Fetch's observation (25), goal layout (3) and 4-D action
(``dx, dy, dz`` scaled by 0.05, gripper) are reused unchanged. The goal space is the one the paper's
Sim2Real section describes (no code for it was published): 100-step episodes, goal = table centre +- 0.1,
in the air with probability 0.5 at height U(0, 0.45), object = centre +- 0.1. Every move is clamped to the grip point's
:class:`Workspace` box, as the Sim2Real loop clamps the real arm's.

The robot frame is the world frame: the Panda base sits at the origin on the table top (``z = 0``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import gymnasium as gym
import gymnasium_robotics
import mujoco
import numpy as np
from gymnasium.utils import EzPickle
from gymnasium_robotics.envs.fetch import MujocoFetchEnv

from torchrl_cebp.envs.layout import FETCH_OBSERVATION as OBS
from torchrl_cebp.envs.scripted import ACTION_SCALE, GraspAndLift
from torchrl_cebp.envs.touch import TouchReporting, add_touch_pad

__all__ = [
    "FRANKA_ASSETS",
    "FRANKA_GYM_ID",
    "FRANKA_TASK",
    "FrankaLayout",
    "FrankaPickPlaceEnv",
    "Workspace",
    "franka_spec",
    "make_franka",
    "register",
    "sample_goal",
]

FRANKA_TASK = "franka_pick_place"
FRANKA_GYM_ID = "TouchFrankaPickAndPlace-v0"
FRANKA_ASSETS = os.path.join(os.path.dirname(gymnasium_robotics.__file__), "envs/assets/kitchen_franka/franka_assets")

ARM_JOINTS: tuple[str, ...] = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))
FINGER_JOINTS: tuple[str, str] = ("robot:panda0_finger_joint1", "robot:panda0_finger_joint2")
FINGER_ACTUATORS: tuple[str, str] = ("r_gripper_finger_joint", "l_gripper_finger_joint")
HAND_BODY = "panda0_link7"
# The pose the mocap weld settles into with the hand pointing down and the fingers closing along y
# (found by letting the weld pull the arm there from several starts; all converged to this one).
HOME_QPOS: tuple[float, ...] = (0.0, -0.085, 0.0, -2.3, 0.0, 0.646, 0.0)
# Hand (link7) orientation: fingers down, closing along world y, so a camera facing the robot sees the
# cube between the fingers instead of behind one.
HAND_QUAT: tuple[float, ...] = (0.0, 0.92388, -0.382683, 0.0)
# Grip point on the hand's axis: a grasped cube's centre, with the fingertips 2 cm lower (clear of the table).
GRIP_OFFSET = 0.24
# Env steps a grasped start may take: the scripted grasp needs 8-12 from the start pose to any placement.
GRASP_STEP_LIMIT = 25
# Inner pad of each finger (finger frame): the capsules' inner surface, from fingertip to knuckle.
_PAD_HALF_SIZE = (0.02, 0.006, 0.0325)
_PAD_POS = (0.0, 0.0, 0.0625)
# Name, body, and the local y direction pointing at the other finger.
_FINGERS = (("left", "panda0_leftfinger", -1.0), ("right", "panda0_rightfinger", 1.0))


@dataclass(frozen=True)
class Workspace:
    """The box the grip point may reach and the longest displacement one step may command (robot frame, metres).

    Around the goal space (5 cm beyond it in x, 10 cm in y), from the table top to above the highest goal, and
    within the arm's reach with the hand pointing down: further out (e.g. x = 0.68 at 0.45 m up) the wrist
    joint stops at its limit and the weld swings the hand by centimetres every step. The simulator clamps every
    move to this box, and so does the Sim2Real loop on the real arm.

    Args:
        low (tuple of float, optional): the box's lower corner. Defaults to ``(0.3, -0.2, 0.01)``.
        high (tuple of float, optional): the box's upper corner. Defaults to ``(0.65, 0.2, 0.48)``.
        max_step (float, optional): the longest displacement per axis one step may command.
            Defaults to ``0.05`` (an action of 1).

    Example:
        >>> ws = Workspace(low=(0.3, -0.2, 0.0), high=(0.7, 0.2, 0.5), max_step=0.05)
        >>> ws.clamp(np.array([0.69, 0.0, 0.2]), np.array([0.05, 0.0, 0.0])).round(3).tolist()
        [0.01, 0.0, 0.0]
    """

    low: tuple[float, float, float] = (0.3, -0.2, 0.01)
    high: tuple[float, float, float] = (0.65, 0.2, 0.48)
    max_step: float = ACTION_SCALE

    def clamp(self, position: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """``delta`` limited to ``max_step`` per axis and so that ``position + delta`` stays in the box.

        Args:
            position (np.ndarray): the grip point now.
            delta (np.ndarray): the displacement asked for.
        """
        delta = np.clip(delta, -self.max_step, self.max_step)
        return np.clip(position + delta, self.low, self.high) - position


@dataclass(frozen=True)
class FrankaLayout:
    """Where things are in the Franka scene (robot frame, metres) and what counts as success.

    Args:
        table_centre (tuple of float, optional): the table's centre (x, y). Defaults to ``(0.5, 0.0)``.
        table_half_size (tuple of float, optional): the table's half-size (x, y). Defaults to ``(0.35, 0.45)``.
        table_height (float, optional): ``z`` of the table top. Defaults to ``0.0``.
        cube_size (float, optional): the cube's edge. Defaults to ``0.05``.
        obj_range (float, optional): the cube starts at the table centre +- this in x and y. Defaults to ``0.1``.
        target_range (float, optional): goals lie at the table centre +- this in x and y. Defaults to ``0.1``.
        target_height (float, optional): how high above the table a goal in the air may be. Defaults to ``0.45``.
        distance_threshold (float, optional): the success radius. Defaults to ``0.05``.
        max_episode_steps (int, optional): the episode length. Defaults to ``100``.
        gripper_start_height (float, optional): height of the grip point above the cube centre at the start
            of an episode. Defaults to ``0.2``.
        workspace (Workspace, optional): the box every move is clamped to. Defaults to ``Workspace()``.

    Example:
        >>> FrankaLayout().cube_centre_height
        0.025
    """

    table_centre: tuple[float, float] = (0.5, 0.0)
    table_half_size: tuple[float, float] = (0.35, 0.45)
    table_height: float = 0.0
    cube_size: float = 0.05
    obj_range: float = 0.1
    target_range: float = 0.1
    target_height: float = 0.45
    distance_threshold: float = 0.05
    max_episode_steps: int = 100
    gripper_start_height: float = 0.2
    workspace: Workspace = Workspace()

    @property
    def cube_centre_height(self) -> float:
        """``z`` of a cube resting on the table."""
        return self.table_height + self.cube_size / 2


def sample_goal(layout: FrankaLayout, rng: np.random.Generator) -> np.ndarray:
    """A goal: table centre +- ``target_range`` in x/y, on the table or, with probability 0.5, up to ``target_height`` above.

    Args:
        layout (FrankaLayout): the scene.
        rng (np.random.Generator): draws the goal.

    Returns:
        the goal ``[x, y, z]``.

    Example:
        >>> goal = sample_goal(FrankaLayout(), np.random.default_rng(0))
        >>> goal.shape, bool(goal[2] >= FrankaLayout().cube_centre_height)
        ((3,), True)
    """
    goal = np.empty(3)
    goal[:2] = np.asarray(layout.table_centre) + rng.uniform(-layout.target_range, layout.target_range, size=2)
    goal[2] = layout.cube_centre_height
    if rng.uniform() < 0.5:
        goal[2] += rng.uniform(0.0, layout.target_height)
    return goal


def franka_spec(layout: FrankaLayout = FrankaLayout()) -> mujoco.MjSpec:
    """The Franka pick-and-place scene: Panda (mocap-driven), table, red cube, target site, finger touch sensors.

    Args:
        layout (FrankaLayout, optional): the scene's geometry. Defaults to ``FrankaLayout()``.

    Returns:
        the uncompiled ``mujoco.MjSpec``.

    Example:
        >>> model = franka_spec().compile()
        >>> model.nsensor, model.nu, model.nmocap
        (2, 2, 1)
    """
    spec = mujoco.MjSpec.from_string(
        f"""<mujoco model="franka_pick_place">
          <include file="{FRANKA_ASSETS}/assets.xml"/>
          <include file="{FRANKA_ASSETS}/actuator.xml"/>
          <worldbody><include file="{FRANKA_ASSETS}/chain.xml"/></worldbody>
        </mujoco>"""
    )
    # The include resolved the mesh files against franka_assets/, but the meshes live in franka_assets/meshes/.
    for mesh in spec.meshes:
        mesh.file = os.path.join(FRANKA_ASSETS, "meshes", os.path.relpath(mesh.file, FRANKA_ASSETS))
    # The mocap weld moves the arm; joint servos would fight it.
    for i in range(1, 8):
        spec.delete(spec.actuator(f"panda0_joint{i}"))
    # The kitchen model's joint damping (100) was tuned for its servos; under the weld it makes the hand lag
    # and swing by centimetres on a 5 cm step. With 10 and a stiff weld it tracks within 2 mm.
    for joint in spec.joints:
        if joint.name in ARM_JOINTS:
            joint.damping = 10.0
    # gymnasium-robotics sets each finger's position target to its position plus the action, and MuJoCo clamped
    # the target to the joint range: on the 5 cm cube the fingers sit 2.5 cm from the clamped target, so they
    # squeezed with kp x 2.5 cm = 12.7 N and fast moves shook a held cube loose. Unclamped, the squeeze is the
    # actuators' force limit, 70 N: the Franka Hand's continuous grasp force.
    for name in FINGER_ACTUATORS:
        spec.actuator(name).ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    for body in spec.bodies:
        if body.name.startswith("panda0_link") and body.name != "panda0_link0" or "finger" in body.name:
            body.gravcomp = 1.0  # the real Panda compensates gravity; without it the hand sags below the mocap

    hand = spec.body(HAND_BODY)
    hand.add_site(name="robot0:grip", pos=[0, 0, GRIP_OFFSET], size=[0.01] * 3, rgba=[0, 0, 0, 0])
    for side, body_name, inward in _FINGERS:
        finger = spec.body(body_name)
        # A flat pad like the real Panda's rubber one replaces the kitchen model's crossed capsules, which
        # squeeze a grasped box up and out of the fingers when the hand lifts.
        for geom in finger.geoms:
            if geom.type == mujoco.mjtGeom.mjGEOM_CAPSULE:
                geom.contype = geom.conaffinity = 0
        finger.add_geom(
            name=f"robot0:{side}_pad_geom", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.012, 0.004, 0.03],
            pos=[0.0, -inward * 0.004, _PAD_POS[2]], friction=[1.0, 0.005, 0.0001], condim=4,
        )
        add_touch_pad(spec, body_name, side, _PAD_HALF_SIZE, _PAD_POS)

    world = spec.worldbody
    world.add_light(pos=[0.5, 0, 2.0], dir=[0, 0, -1], diffuse=[0.7] * 3, specular=[0.1] * 3, castshadow=False)
    world.add_light(pos=[0.5, -1.5, 1.5], dir=[0, 1, -1], diffuse=[0.4] * 3, specular=[0.0] * 3, castshadow=False)
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3, 3, 0.1], pos=[0, 0, -0.75],
                   rgba=[0.35, 0.35, 0.38, 1])
    cx, cy = layout.table_centre
    world.add_geom(
        name="table0", type=mujoco.mjtGeom.mjGEOM_BOX, size=[*layout.table_half_size, 0.02],
        pos=[cx, cy, layout.table_height - 0.02], rgba=[0.72, 0.7, 0.66, 1],
    )
    half = layout.cube_size / 2
    cube = world.add_body(name="object0", pos=[cx, cy, layout.cube_centre_height])
    cube.add_freejoint(name="object0:joint")
    # condim 4 (torsional friction) keeps a cube pinched between two pads from spinning about their axis.
    cube.add_geom(name="object0", type=mujoco.mjtGeom.mjGEOM_BOX, size=[half] * 3, mass=0.1, rgba=[0.8, 0.05, 0.05, 1],
                  condim=4)
    cube.add_site(name="object0", size=[0.005] * 3, rgba=[0, 0, 0, 0])
    # Not red: the camera looks for the one red thing on the table.
    world.add_site(name="target0", pos=[cx, cy, 0.3], size=[0.02] * 3, rgba=[0.1, 0.3, 0.9, 0.4],
                   type=mujoco.mjtGeom.mjGEOM_SPHERE)

    world.add_body(name="robot0:mocap", mocap=True, pos=[cx, cy, 0.5])
    spec.add_equality(
        type=mujoco.mjtEq.mjEQ_WELD, name1="robot0:mocap", name2=HAND_BODY, objtype=mujoco.mjtObj.mjOBJ_BODY,
        data=[0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1], solref=[0.005, 1.0],
    )
    return spec


_DEFAULT_CAMERA = {"distance": 1.6, "azimuth": 150.0, "elevation": -25.0, "lookat": np.array([0.5, 0.0, 0.1])}


class FrankaPickPlaceEnv(TouchReporting, MujocoFetchEnv, EzPickle):
    """Franka Panda pick-and-place as a gymnasium goal env with Fetch's observation, goal and action layout.

    ``info["touch"]`` (also ``env.touch``) is each finger pad's touch averaged over the physics substeps.

    With ``grasped_start`` > 0 that fraction of resets hands over the cube already between the closed fingers, at
    its sampled placement on the table (a scripted grasp, :class:`GraspAndLift`, run inside the reset): the HER
    paper's aid for pick-and-place, which began half its training episodes from a state with the box grasped.
    It is for training episodes only; tests and the Sim2Real loop start from the table.

    Args:
        layout (FrankaLayout, optional): scene geometry and goal space. Defaults to ``FrankaLayout()``.
        scene_hook (callable, optional): called with the ``MjSpec`` before it is compiled, to add things
            (markers, cameras). Defaults to ``None``.
        grasped_start (float, optional): probability that a reset starts with the cube grasped.
            Defaults to ``0.0`` (never).
        **kwargs: ``render_mode``, ``width``, ``height`` as for gymnasium-robotics envs.

    Raises:
        ValueError: ``grasped_start`` is not in ``[0, 1]``.

    Example:
        >>> env = FrankaPickPlaceEnv()
        >>> obs, info = env.reset(seed=0)
        >>> obs["observation"].shape, info["touch"].shape, env.max_episode_steps
        ((25,), (2,), 100)
        >>> _, info = FrankaPickPlaceEnv(grasped_start=1.0).reset(seed=0)
        >>> bool((info["touch"] > 0).all())
        True
    """

    def __init__(
        self,
        layout: FrankaLayout = FrankaLayout(),
        scene_hook: Callable[[mujoco.MjSpec], None] | None = None,
        grasped_start: float = 0.0,
        **kwargs: Any,
    ) -> None:
        if not 0.0 <= grasped_start <= 1.0:
            raise ValueError(f"grasped_start={grasped_start!r}: must be a probability in [0, 1]")
        self.layout = layout
        self.grasped_start = grasped_start
        self._scene_hook = scene_hook
        self.touch = np.zeros(2)
        self.max_episode_steps = layout.max_episode_steps
        super().__init__(
            # Only checked to exist: the model is built by _initialize_simulation from franka_spec.
            model_path=os.path.join(FRANKA_ASSETS, "chain.xml"),
            has_object=True,
            block_gripper=False,
            n_substeps=20,
            gripper_extra_height=0.0,
            target_in_the_air=True,
            target_offset=0.0,
            obj_range=layout.obj_range,
            target_range=layout.target_range,
            distance_threshold=layout.distance_threshold,
            initial_qpos=dict(zip(ARM_JOINTS, HOME_QPOS)),
            reward_type="sparse",
            default_camera_config=_DEFAULT_CAMERA,
            **kwargs,
        )
        EzPickle.__init__(self, layout=layout, scene_hook=scene_hook, grasped_start=grasped_start, **kwargs)

    def _initialize_simulation(self) -> None:
        # As MujocoRobotEnv._initialize_simulation, but compiling the generated scene.
        spec = franka_spec(self.layout)
        if self._scene_hook is not None:
            self._scene_hook(spec)
        self.model = spec.compile()
        self.data = self._mujoco.MjData(self.model)
        self._model_names = self._utils.MujocoModelNames(self.model)
        self.locate_touch_sensors()
        self.model.vis.global_.offwidth = max(self.width, self.model.vis.global_.offwidth)
        self.model.vis.global_.offheight = max(self.height, self.model.vis.global_.offheight)
        self._env_setup(initial_qpos=self.initial_qpos)
        self.initial_time = self.data.time
        self.initial_qpos = np.copy(self.data.qpos)
        self.initial_qvel = np.copy(self.data.qvel)

    def _env_setup(self, initial_qpos: dict[str, float]) -> None:
        for name, value in initial_qpos.items():
            self._utils.set_joint_qpos(self.model, self.data, name, value)
        for name in FINGER_JOINTS:
            self._utils.set_joint_qpos(self.model, self.data, name, 0.04)
        self._utils.reset_mocap_welds(self.model, self.data)
        hand_to_grip = np.zeros(3)
        self._mujoco.mju_rotVecQuat(hand_to_grip, np.array([0.0, 0.0, -GRIP_OFFSET]), np.array(HAND_QUAT))
        cx, cy = self.layout.table_centre
        start = np.array([cx, cy, self.layout.cube_centre_height + self.layout.gripper_start_height])
        self.data.mocap_pos[0] = start + hand_to_grip
        self.data.mocap_quat[0] = HAND_QUAT
        self.data.ctrl[:] = 0.04
        for _ in range(10):
            self._mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)
        self.initial_gripper_xpos = self._utils.get_site_xpos(self.model, self.data, "robot0:grip").copy()
        self.height_offset = self._utils.get_site_xpos(self.model, self.data, "object0")[2]

    def _reset_sim(self) -> bool:
        if not super()._reset_sim():
            return False
        # Drawn only when enabled, so that plain resets keep the placements they had before the option existed.
        if self.grasped_start > 0 and self.np_random.uniform() < self.grasped_start:
            return self._grasp_cube()
        return True

    def _grasp_cube(self) -> bool:
        """Runs the scripted grasp until the fingers rest on the cube; False (the reset is redrawn) if it cannot."""
        script = GraspAndLift()
        for _ in range(GRASP_STEP_LIMIT):
            observation = self._get_obs()["observation"]
            action = script(observation, goal=observation[OBS.object_position])
            if script.phase == "carry":
                return True
            self._set_action(action)
            self._mujoco_step(action)
        return False

    def _set_action(self, action: np.ndarray) -> None:
        # Fetch's composition (scaled displacement, gripper pair), but the hand orientation is pinned to
        # HAND_QUAT instead of Fetch's quaternion offset, so it cannot drift under contact.
        action = super(MujocoFetchEnv, self)._set_action(action)
        self._utils.ctrl_set_action(self.model, self.data, action)
        self._utils.reset_mocap2body_xpos(self.model, self.data)
        self._mocap_start = self.data.mocap_pos[0].copy()
        # Unclamped, the hand went wherever the arm reaches: past the table's edge, below its top, behind the base.
        grip = self._utils.get_site_xpos(self.model, self.data, "robot0:grip")
        self._mocap_delta = self.layout.workspace.clamp(grip, action[:3])
        self.data.mocap_quat[0] = HAND_QUAT

    def _mujoco_step(self, action: np.ndarray) -> None:
        # The mocap glides to its target over the substeps, as a real arm's Cartesian motion does; a 5 cm
        # jump at once yanks the stiff weld hard enough to fling a grasped cube out of the fingers.
        # One substep at a time also lets the touch be averaged over the whole env step.
        total = np.zeros(2)
        for k in range(1, self.n_substeps + 1):
            self.data.mocap_pos[0] = self._mocap_start + self._mocap_delta * (k / self.n_substeps)
            self._mujoco.mj_step(self.model, self.data)
            total += self.substep_touch()
        self.touch = total / self.n_substeps

    def _sample_goal(self) -> np.ndarray:
        return sample_goal(self.layout, self.np_random)

    def _render_callback(self) -> None:
        self.model.site_pos[self.model.site("target0").id] = self.goal
        self._mujoco.mj_forward(self.model, self.data)

    def _get_gripper_xpos(self) -> np.ndarray:
        return self.data.body(HAND_BODY).xpos


def make_franka(goal_space: str = "standard", **kwargs: Any) -> FrankaPickPlaceEnv:
    """The (unwrapped) gymnasium Franka env; its one goal space is the paper's, called ``standard``.

    Args:
        goal_space (str, optional): ``"standard"``, the only one. Defaults to ``"standard"``.
        **kwargs: passed to :class:`FrankaPickPlaceEnv`; ``max_episode_steps`` replaces the layout's
            episode length (100, the paper's), as it does for Fetch.

    Raises:
        ValueError: another goal space.

    Example:
        >>> make_franka().reset(seed=1)[0]["desired_goal"].shape
        (3,)
        >>> make_franka(max_episode_steps=50).max_episode_steps
        50
    """
    if goal_space != "standard":
        raise ValueError(f"Unknown goal space {goal_space!r} for {FRANKA_TASK}; valid goal spaces: standard")
    if "max_episode_steps" in kwargs:
        # As gymnasium-robotics' Fetch takes it: the episode length is the layout's, so it reaches the env's truncation.
        steps = kwargs.pop("max_episode_steps")
        kwargs["layout"] = replace(kwargs.get("layout", FrankaLayout()), max_episode_steps=steps)
    return FrankaPickPlaceEnv(**kwargs)


def register() -> None:
    """Register ``TouchFrankaPickAndPlace-v0`` with gymnasium (idempotent).

    Example:
        >>> register()
        >>> gym.spec(FRANKA_GYM_ID).max_episode_steps
        100
    """
    if FRANKA_GYM_ID not in gym.registry:
        gym.register(
            id=FRANKA_GYM_ID,
            entry_point=f"{__name__}:FrankaPickPlaceEnv",
            max_episode_steps=FrankaLayout().max_episode_steps,
        )
