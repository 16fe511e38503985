"""A scripted pick-and-place for the Fetch-layout envs: the reference the diagnosis measures the Franka task
with, and how a Franka training episode can start with the cube already grasped (``grasped_start``)."""

from __future__ import annotations

import numpy as np

from torchrl_cebp.envs.layout import FETCH_OBSERVATION as OBS

__all__ = ["ACTION_SCALE", "GraspAndLift", "move_towards"]

# gymnasium-robotics' Fetch action scale, which the Franka env reuses: an action of 1 asks for a 5 cm move.
ACTION_SCALE = 0.05


def move_towards(grip: np.ndarray, target: np.ndarray, gripper: float) -> np.ndarray:
    """The 4-D action moving the grip point towards ``target`` at top speed (magnitude 1 per axis until within a step).

    Args:
        grip (np.ndarray): the grip point's position.
        target (np.ndarray): where it should go.
        gripper (float): the gripper action, ``1`` open, ``-1`` closed.

    Returns:
        the float32 action ``[dx, dy, dz, gripper]``.

    Example:
        >>> move_towards(np.zeros(3), np.array([0.2, 0.01, 0.0]), gripper=-1.0).tolist()
        [1.0, 0.20000000298023224, 0.0, -1.0]
    """
    return np.append(np.clip((target - grip) / ACTION_SCALE, -1.0, 1.0), gripper).astype(np.float32)


class GraspAndLift:
    """A scripted pick-and-place at the policy's top speed: over the cube, down, close, then carry to the goal.

    ``phase`` is ``"approach"``, ``"descend"``, ``"close"`` and then ``"carry"`` once the fingers have stopped on
    the cube. It never lets go or grasps again once it carries, so a cube that slips out stays dropped.

    Args:
        hover (float, optional): height above the cube to line up at. Defaults to ``0.05``.
        tolerance (float, optional): how close the grip must come to a waypoint. Defaults to ``0.005``.

    Example:
        >>> script = GraspAndLift()
        >>> obs = np.zeros(OBS.size, np.float32); obs[OBS.object_position] = [0.5, 0.0, 0.025]
        >>> script(obs, goal=np.array([0.5, 0.0, 0.4])).tolist()  # over the cube at top speed, fingers open
        [1.0, 0.0, 1.0, 1.0]
        >>> script.phase
        'approach'
    """

    def __init__(self, hover: float = 0.05, tolerance: float = 0.005) -> None:
        self.hover, self.tolerance = hover, tolerance
        self.phase, self._widths = "approach", []

    def __call__(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        grip, cube, width = obs[OBS.gripper_position], obs[OBS.object_position], float(OBS.gripper_opening(obs))
        above = cube + [0.0, 0.0, self.hover]
        if self.phase == "approach" and np.linalg.norm(above - grip) < 2 * self.tolerance and width > 0.06:
            self.phase = "descend"
        if self.phase == "descend" and np.linalg.norm(cube - grip) < self.tolerance:
            self.phase = "close"
        if self.phase == "close":
            self._widths.append(width)
            if len(self._widths) > 2 and self._widths[-2] - width < 0.0005:  # the fingers have stopped on the cube
                self.phase = "carry"
        target, gripper = {"approach": (above, 1.0), "descend": (cube, 1.0), "close": (grip, -1.0),
                           "carry": (goal, -1.0)}[self.phase]
        return move_towards(grip, target, gripper)
