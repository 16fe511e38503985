"""CPER's joint-position-controlled Fetch: robot B, the robot of the released CEBP code.

Built from gymnasium-robotics' shipped Fetch XML through ``mujoco.MjSpec``: the mocap weld is
removed, the seven arm joints get ``position`` actuators (kp 300, CPER's control ranges) and, on
PickAndPlace, the two finger actuators take CPER's range 0-0.05. An action is an absolute target
``centre + a * half_range`` per actuator: 7-D with the gripper held closed (Push, Slide), 8-D with
one value for both fingers (PickAndPlace). Every reset starts the arm from CPER's initial joints,
each perturbed by its U(lo, hi).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

CONTROLS: tuple[str, ...] = ("mocap", "joint")
ARM_KP = 300.0
FINGER_KP = 30000.0
FINGER_CTRL_RANGE = (0.0, 0.05)
FINGER_ACTUATORS: tuple[str, str] = ("robot0:l_gripper_finger_joint", "robot0:r_gripper_finger_joint")
MOCAP_BODY = "robot0:mocap"


@dataclass(frozen=True)
class ArmJoint:
    """One actuated arm joint: its control range, CPER's initial angle and the reset perturbation U(lo, hi).

    Args:
        name (str): the joint's name in the Fetch XML.
        ctrl_range (tuple of float): ``(low, high)`` of its position actuator.
        initial (float): CPER's initial angle.
        perturbation (tuple of float): ``(lo, hi)`` of the uniform offset added at every reset.

    Example:
        >>> joint = ArmJoint("robot0:elbow_flex_joint", (0.0, 2.0), 1.55, (-0.1, 0.0))
        >>> joint.centre, joint.half_range
        (1.0, 1.0)
    """

    name: str
    ctrl_range: tuple[float, float]
    initial: float
    perturbation: tuple[float, float]

    @property
    def centre(self) -> float:
        """The middle of the control range: the target of action 0."""
        return 0.5 * (self.ctrl_range[0] + self.ctrl_range[1])

    @property
    def half_range(self) -> float:
        """Half the control range: the target moves this far for an action of 1."""
        return 0.5 * (self.ctrl_range[1] - self.ctrl_range[0])


ARM_JOINTS: tuple[ArmJoint, ...] = (
    ArmJoint("robot0:shoulder_pan_joint", (-0.4, 0.4), 0.0, (-0.1, 0.1)),
    ArmJoint("robot0:shoulder_lift_joint", (-1.221, 0.0), -0.7, (-0.1, 0.0)),
    ArmJoint("robot0:upperarm_roll_joint", (-0.5, 0.5), 0.0, (-0.1, 0.1)),
    ArmJoint("robot0:elbow_flex_joint", (0.0, 2.0), 1.55, (-0.1, 0.0)),
    ArmJoint("robot0:forearm_roll_joint", (-0.5, 0.5), 0.0, (-0.1, 0.1)),
    ArmJoint("robot0:wrist_flex_joint", (0.0, 1.5), 0.75, (-0.1, 0.1)),
    ArmJoint("robot0:wrist_roll_joint", (-0.8, 0.8), 0.0, (-0.1, 0.1)),
)


def check_control(control: str) -> str:
    """``control`` if it names a robot.

    Args:
        control (str): ``"mocap"`` or ``"joint"``.

    Raises:
        ValueError: an unknown control; the message lists the valid ones.

    Example:
        >>> check_control("joint")
        'joint'
    """
    if control not in CONTROLS:
        raise ValueError(f"unknown control {control!r}; valid controls: {', '.join(CONTROLS)}")
    return control


def action_size(control: str, gripper_blocked: bool) -> int:
    """The action's size: 4 under mocap (dx, dy, dz, gripper); under joint control 7 arm targets, plus one
    gripper value unless the gripper is blocked.

    Args:
        control (str): ``"mocap"`` or ``"joint"``.
        gripper_blocked (bool): the fingers are held closed (Push, Slide under joint control).

    Example:
        >>> action_size("joint", gripper_blocked=True), action_size("joint", gripper_blocked=False)
        (7, 8)
    """
    if check_control(control) == "mocap":
        return 4
    return len(ARM_JOINTS) + (0 if gripper_blocked else 1)


def add_joint_actuators(spec: mujoco.MjSpec) -> None:
    """Turns a gymnasium-robotics Fetch spec into CPER's joint-controlled robot (in place).

    Args:
        spec (mujoco.MjSpec): a gymnasium-robotics Fetch model, not yet compiled.

    Example:
        >>> import os, gymnasium_robotics
        >>> path = os.path.join(os.path.dirname(gymnasium_robotics.__file__), "envs/assets/fetch/pick_and_place.xml")
        >>> spec = mujoco.MjSpec.from_file(path)
        >>> add_joint_actuators(spec)
        >>> model = spec.compile()
        >>> model.nu, model.neq
        (9, 0)
    """
    for weld in [eq for eq in spec.equalities if MOCAP_BODY in (eq.name1, eq.name2)]:
        spec.delete(weld)
    for finger in spec.actuators:
        if finger.name in FINGER_ACTUATORS:
            finger.ctrlrange = FINGER_CTRL_RANGE
            finger.set_to_position(kp=FINGER_KP)
    for joint in ARM_JOINTS:
        actuator = spec.add_actuator(
            name=joint.name.replace("_joint", "_actuator"),
            target=joint.name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            ctrllimited=True,
            ctrlrange=joint.ctrl_range,
        )
        actuator.set_to_position(kp=ARM_KP)


class JointController:
    """Maps actions in [-1, 1] to absolute actuator targets, and perturbs the arm at reset, for a compiled model.

    Args:
        model (mujoco.MjModel): a model built with :func:`add_joint_actuators`.
        gripper_blocked (bool): the fingers take no action (7-D actions); else the eighth entry drives both.

    Example:
        >>> import os, gymnasium_robotics
        >>> path = os.path.join(os.path.dirname(gymnasium_robotics.__file__), "envs/assets/fetch/push.xml")
        >>> spec = mujoco.MjSpec.from_file(path)
        >>> add_joint_actuators(spec)
        >>> model = spec.compile(); data = mujoco.MjData(model)
        >>> controller = JointController(model, gripper_blocked=True)
        >>> controller.apply(data, np.zeros(7))
        >>> data.ctrl.round(4).tolist()
        [0.0, -0.6105, 0.0, 1.0, 0.0, 0.75, 0.0]
    """

    def __init__(self, model: mujoco.MjModel, gripper_blocked: bool) -> None:
        self.gripper_blocked = gripper_blocked
        self._arm_ctrl = np.array([model.actuator(j.name.replace("_joint", "_actuator")).id for j in ARM_JOINTS])
        self._arm_qpos = np.array([model.jnt_qposadr[model.joint(j.name).id] for j in ARM_JOINTS])
        self._arm_dof = np.array([model.jnt_dofadr[model.joint(j.name).id] for j in ARM_JOINTS])
        self._centre = np.array([j.centre for j in ARM_JOINTS])
        self._half = np.array([j.half_range for j in ARM_JOINTS])
        self._low = np.array([j.ctrl_range[0] for j in ARM_JOINTS])
        self._high = np.array([j.ctrl_range[1] for j in ARM_JOINTS])
        self._initial = np.array([j.initial for j in ARM_JOINTS])
        self._perturbation = np.array([j.perturbation for j in ARM_JOINTS])
        self._finger_ctrl = None if gripper_blocked else np.array([model.actuator(n).id for n in FINGER_ACTUATORS])

    @property
    def n_actions(self) -> int:
        """The action's size (:func:`action_size`)."""
        return action_size("joint", self.gripper_blocked)

    def apply(self, data: mujoco.MjData, action: np.ndarray) -> None:
        """Sets the actuator targets ``centre + a * half_range``, clipped to each control range.

        Args:
            data (mujoco.MjData): the simulation's data.
            action (np.ndarray): ``[n_actions]`` in ``[-1, 1]``.
        """
        data.ctrl[self._arm_ctrl] = np.clip(self._centre + action[: len(ARM_JOINTS)] * self._half, self._low, self._high)
        if self._finger_ctrl is not None:
            low, high = FINGER_CTRL_RANGE
            centre, half = 0.5 * (low + high), 0.5 * (high - low)
            data.ctrl[self._finger_ctrl] = np.clip(centre + action[len(ARM_JOINTS)] * half, low, high)

    def set_initial_arm(self, data: mujoco.MjData, rng: np.random.Generator | None) -> None:
        """Puts the arm at CPER's initial joints at rest, each perturbed by U(lo, hi) when ``rng`` is given.

        Args:
            data (mujoco.MjData): the simulation's data.
            rng (np.random.Generator or None): draws the perturbation; ``None`` leaves the joints unperturbed.
        """
        angles = self._initial.copy()
        if rng is not None:
            angles += rng.uniform(self._perturbation[:, 0], self._perturbation[:, 1])
        data.qpos[self._arm_qpos] = angles
        data.qvel[self._arm_dof] = 0.0
        data.ctrl[self._arm_ctrl] = np.clip(angles, self._low, self._high)
