"""The robot side of the Sim2Real loop: one interface for the MuJoCo twin and the real Franka.

A backend moves the end effector by Cartesian displacements and reports the state the policy's
observation needs; everything else (perception, safety, observation assembly) lives in
:class:`~torchrl_cebp.sim2real.real_loop.RealLoopEnv` and is the same for both.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FrankyBackend", "RobotBackend", "RobotState"]


@dataclass(frozen=True)
class RobotState:
    """End-effector and gripper state in the robot frame (metres, metres per second).

    ``finger_pos`` is each finger's opening from the centre (the Fetch/Panda finger joint), so the
    gripper width is their sum.

    Args:
        grip_pos (np.ndarray): the grip point's position ``[3]``.
        grip_vel (np.ndarray): its velocity ``[3]``.
        finger_pos (np.ndarray): each finger's opening from the centre ``[2]``.
        finger_vel (np.ndarray): their velocities ``[2]``.

    Example:
        >>> state = RobotState(np.zeros(3), np.zeros(3), np.full(2, 0.02), np.zeros(2))
        >>> state.gripper_width
        0.04
    """

    grip_pos: np.ndarray
    grip_vel: np.ndarray
    finger_pos: np.ndarray
    finger_vel: np.ndarray

    @property
    def gripper_width(self) -> float:
        """Distance between the finger pads."""
        return float(np.sum(self.finger_pos))


class RobotBackend(ABC):
    """A robot arm with a parallel gripper, driven by end-effector displacements.

    ``gripper`` follows the policy's convention: ``+1`` opens fully, ``-1`` closes (grasps), values in
    between move each finger by ``gripper`` metres from where it is, as the simulator's position servo does.

    Example:
        >>> class Still(RobotBackend):
        ...     def reset(self): pass
        ...     def state(self): return RobotState(np.zeros(3), np.zeros(3), np.zeros(2), np.zeros(2))
        ...     def move(self, delta_xyz, gripper): pass
        ...     def hold(self): pass
        ...     def stop(self): pass
        >>> Still().state().gripper_width
        0.0
    """

    @abstractmethod
    def reset(self) -> None:
        """Brings the arm to its start pose with the gripper open (in the twin: also re-places the cube)."""

    @abstractmethod
    def state(self) -> RobotState:
        """The current end-effector and gripper state."""

    @abstractmethod
    def move(self, delta_xyz: np.ndarray, gripper: float) -> None:
        """Moves the end effector by ``delta_xyz`` and commands the gripper.

        Args:
            delta_xyz (np.ndarray): the robot-frame displacement, already clamped to the workspace.
            gripper (float): ``+1`` opens fully, ``-1`` closes.
        """

    @abstractmethod
    def hold(self) -> None:
        """Stays where it is for one control period, keeping the last gripper command (a grasp stays a grasp)."""

    @abstractmethod
    def stop(self) -> None:
        """Stops all motion now; the backend may refuse to move again until :meth:`reset`."""


class FrankyBackend(RobotBackend):
    """The real Franka Panda through ``franky`` (``pip install torchrl-cebp[real]``, i.e. ``franky-control``).

    It needs the robot's network and a real-time kernel. Every move is an absolute
    Cartesian target (current position + displacement, orientation kept), because franky's relative
    motions are expressed in the end-effector frame, not the base frame the policy acts in. Moves block
    until reached; the gripper grasps with ``grasp_force`` when closing and opens fully otherwise.

    Args:
        host (str): the robot controller's address.
        home (tuple of float, optional): grip-point start position (robot frame), the simulator's start above
            the table centre. Defaults to ``(0.5, 0.0, 0.225)``.
        grip_offset (tuple of float, optional): robot-frame offset from franky's end-effector frame to the
            simulator's grip point (the cube centre when grasped; the sim's grip point is 2 cm above the
            fingertips). Defaults to ``(0.0, 0.0, 0.02)``.
        dynamics_factor (float, optional): fraction of the robot's velocity/acceleration/jerk limits used for
            every motion. Defaults to ``0.1``.
        grasp_force (float, optional): gripper force in newtons when closing. Defaults to ``20.0``.
        grasp_width (float, optional): expected object width for ``grasp`` (the cube edge). Defaults to ``0.05``.

    Raises:
        ImportError: ``franky`` is not installed.

    Example:
        >>> backend = FrankyBackend("172.16.0.2")  # doctest: +SKIP
        >>> backend.reset(); backend.move(np.array([0.0, 0.0, -0.02]), gripper=1.0)  # doctest: +SKIP
    """

    def __init__(
        self,
        host: str,
        home: tuple[float, float, float] = (0.5, 0.0, 0.225),
        grip_offset: tuple[float, float, float] = (0.0, 0.0, 0.02),
        dynamics_factor: float = 0.1,
        grasp_force: float = 20.0,
        grasp_width: float = 0.05,
    ) -> None:
        self._franky = _import_franky()
        self.robot = self._franky.Robot(host)
        self.robot.relative_dynamics_factor = dynamics_factor
        self.gripper = self._franky.Gripper(host)
        self.home = np.asarray(home, dtype=np.float64)
        self.grip_offset = np.asarray(grip_offset, dtype=np.float64)
        self.grasp_force = grasp_force
        self.grasp_width = grasp_width
        self._closed = False
        self.stopped = False

    def _move_grip_to(self, grip_pos: np.ndarray) -> None:
        pose = self.robot.current_cartesian_state.pose.end_effector_pose
        target = self._franky.Affine((grip_pos - self.grip_offset).tolist(), pose.quaternion)
        self.robot.move(self._franky.CartesianMotion(target, self._franky.ReferenceType.Absolute))

    def reset(self) -> None:
        """Recovers from errors, moves the grip point to ``home`` and opens the gripper."""
        self.robot.recover_from_errors()
        self.stopped = False
        self._move_grip_to(self.home)
        self.gripper.open(0.05)
        self._closed = False

    def state(self) -> RobotState:
        """The grip point's pose and velocity, and the gripper's width, read from the robot."""
        cartesian = self.robot.current_cartesian_state
        width = float(self.gripper.width)
        return RobotState(
            grip_pos=np.asarray(cartesian.pose.end_effector_pose.translation, dtype=np.float64) + self.grip_offset,
            grip_vel=np.asarray(cartesian.velocity.end_effector_twist.linear, dtype=np.float64),
            finger_pos=np.full(2, width / 2),
            # The gripper reports no velocity; between blocking moves it stands still.
            finger_vel=np.zeros(2),
        )

    def move(self, delta_xyz: np.ndarray, gripper: float) -> None:
        """Moves to the current grip point plus ``delta_xyz`` (blocking), then grasps or opens on a change.

        Args:
            delta_xyz (np.ndarray): the robot-frame displacement, already clamped to the workspace.
            gripper (float): below 0 grasps with ``grasp_force``, otherwise opens fully.

        Raises:
            RuntimeError: the robot was stopped and not reset since.
        """
        if self.stopped:
            raise RuntimeError("The robot was stopped; reset() it before moving again.")
        self._move_grip_to(self.state().grip_pos + np.asarray(delta_xyz, dtype=np.float64))
        close = gripper < 0
        if close != self._closed:
            if close:
                self.gripper.grasp(self.grasp_width, 0.05, self.grasp_force, epsilon_outer=0.04)
            else:
                self.gripper.open(0.05)
            self._closed = close

    def hold(self) -> None:
        """Nothing to do: franky's moves block until done, so between commands the arm already stands still."""

    def stop(self) -> None:
        """Stops the robot; :meth:`move` refuses until :meth:`reset`."""
        self.stopped = True
        self.robot.stop()


def _import_franky() -> Any:
    try:
        import franky
    except ImportError as error:
        raise ImportError(
            "The real-robot backend needs franky: pip install 'torchrl-cebp[real]' (the franky-control package), "
            "on a machine with a real-time kernel that reaches the Franka controller."
        ) from error
    return franky
