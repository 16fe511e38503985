"""The camera -> perception -> robot loop as a TorchRL env, with the policy's Fetch-layout observation.

Each step checks that the observation the action was computed from was valid before anything moves:
markers missing or cube not found -> the robot holds still and ``safety_status`` says why; a displacement
outside the workspace box or longer than ``max_step`` is clamped (``clamped``); a lost camera stops the
robot and ends the episode (``safety_status`` = camera lost, ``terminated``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_cebp.envs.franka import FrankaLayout, Workspace, sample_goal
from torchrl_cebp.envs.layout import FETCH_OBSERVATION
from torchrl_cebp.sim2real.camera import CameraLost, FrameSource
from torchrl_cebp.sim2real.calibration import TableCalibration
from torchrl_cebp.sim2real.perception import CubeLocator, CubePerception, PerceptionStatus
from torchrl_cebp.sim2real.robot import RobotBackend, RobotState

__all__ = ["CameraView", "ParallaxCorrection", "RealLoopEnv", "SafetyStatus", "Workspace"]


class SafetyStatus(IntEnum):
    """Why a step did (0) or did not move the robot; written as ``safety_status``.

    ``OK`` (0): the robot moved. ``MARKERS`` (1): no view perceives the cube, and the first camera lacks its
    markers (see :class:`~torchrl_cebp.sim2real.PerceptionStatus`). ``CUBE`` (2): no view perceives the cube,
    the first camera has its markers, and none is in the gripper. ``CAMERA_LOST`` (3): no frame; the robot
    stopped and the episode is over. ``INVALID_ACTION`` (4): NaN or inf in the action.

    Example:
        >>> SafetyStatus(3).reason
        'camera_lost'
    """

    OK = 0
    MARKERS = 1
    CUBE = 2
    CAMERA_LOST = 3
    INVALID_ACTION = 4

    @property
    def reason(self) -> str:
        """``"ok"``, ``"markers"``, ``"cube"``, ``"camera_lost"`` or ``"invalid_action"``."""
        return self.name.lower()


class ParallaxCorrection:
    """Moves a table-plane position to where a point ``height`` above the table really is.

    :class:`~torchrl_cebp.sim2real.perception.CubeLocator` maps the cube's outline onto the table plane;
    seen obliquely, its top and sides land further from the camera than the cube is. Along the camera
    ray the point at ``height`` lies ``1 - height / camera_z`` of the way from the camera to its
    table-plane image.

    Args:
        camera_position (tuple of float): the camera's robot-frame ``(x, y, z)``.
        height (float): the height above the table of the point perceived (the cube's centre: half its edge).
        table_height (float, optional): robot-frame ``z`` of the table surface. Defaults to ``0.0``.

    Example:
        >>> fix = ParallaxCorrection(camera_position=(1.0, 0.0, 1.0), height=0.5, table_height=0.0)
        >>> fix(np.array([0.0, 0.0, 0.5])).tolist()
        [0.5, 0.0, 0.5]
    """

    def __init__(self, camera_position: tuple[float, float, float], height: float, table_height: float = 0.0) -> None:
        self.camera = np.asarray(camera_position, np.float64)
        self.table_height = float(table_height)
        self.scale = 1.0 - height / (self.camera[2] - table_height)

    def __call__(self, position: np.ndarray) -> np.ndarray:
        out = np.asarray(position, np.float64).copy()
        out[:2] = self.camera[:2] + (out[:2] - self.camera[:2]) * self.scale
        return out

    def ray_distance(self, position: np.ndarray, point: np.ndarray) -> float:
        """How far ``point`` lies from the camera ray through ``position``'s table-plane image (metres).

        Whatever its height, what the camera saw at ``position`` lies on that ray: a cube held off the table
        is on it, and a gripper far from it holds no cube the camera sees.

        Args:
            position (np.ndarray): a perceived table-plane position ``(x, y, ...)``.
            point (np.ndarray): a robot-frame ``(x, y, z)``.

        Example:
            >>> fix = ParallaxCorrection(camera_position=(1.0, 0.0, 1.0), height=0.5, table_height=0.0)
            >>> fix.ray_distance(np.array([0.0, 0.0, 0.5]), np.array([0.5, 0.0, 0.5])), fix.ray_distance(np.array([0.0, 0.0, 0.5]), np.array([0.5, 0.2, 0.5]))
            (0.0, 0.2)
        """
        on_table = np.array([position[0], position[1], self.table_height], np.float64)
        direction = (on_table - self.camera) / np.linalg.norm(on_table - self.camera)
        return float(np.linalg.norm(np.cross(np.asarray(point, np.float64) - self.camera, direction)))


@dataclass(frozen=True)
class CameraView:
    """One view of the table: a camera, the perception of its frames, and its viewpoint's parallax correction.

    Each view needs its own :class:`~torchrl_cebp.sim2real.perception.CubeLocator`: the locator remembers its
    camera's last homography. Without a parallax correction (camera position unknown) a view's cube is not
    corrected for its height, and the view cannot overrule the in-gripper rule of :class:`RealLoopEnv`.

    Args:
        camera (FrameSource): the camera.
        perception (CubePerception): the perception of its frames, with a locator of its own.
        parallax (ParallaxCorrection, optional): the viewpoint's correction; ``None`` corrects nothing.
            Defaults to ``None``.

    Example:
        >>> from torchrl_cebp.sim2real import CubeLocator
        >>> from torchrl_cebp.sim2real.twin import SIDE_CAMERA_NAME, MuJoCoTwinBackend, TwinCamera
        >>> backend = MuJoCoTwinBackend(seed=0)
        >>> side = TwinCamera(backend, SIDE_CAMERA_NAME)
        >>> view = CameraView.calibrated(side, backend.calibration, side.position)
        >>> env = RealLoopEnv(backend, TwinCamera(backend), CubePerception(CubeLocator(backend.calibration)), more_views=[view])
        >>> len(env.views), env.reset()["perception_ok"].item()
        (2, True)
    """

    camera: FrameSource
    perception: CubePerception
    parallax: ParallaxCorrection | None = None

    @classmethod
    def calibrated(
        cls, camera: FrameSource, calibration: TableCalibration, camera_position: Sequence[float] | None = None
    ) -> CameraView:
        """The view of ``camera`` through a fresh locator of ``calibration``, parallax-corrected when the camera's
        robot-frame position is known.

        Args:
            camera (FrameSource): the camera.
            calibration (TableCalibration): the table's markers.
            camera_position (sequence of float, optional): the camera's robot-frame ``(x, y, z)``; ``None`` or
                empty when unknown. Defaults to ``None``.

        Raises:
            ValueError: a position of other than 3 numbers.
        """
        locator = CubeLocator(calibration)
        known = camera_position is not None and len(camera_position) > 0
        if known and len(camera_position) != 3:
            raise ValueError(f"A camera position is x, y, z in the robot frame, got {tuple(camera_position)}.")
        parallax = ParallaxCorrection(camera_position, locator.cube_size / 2, calibration.table_height) if known else None
        return cls(camera, CubePerception(locator), parallax)


def fetch_observation(state: RobotState, cube: np.ndarray, previous: tuple[RobotState, np.ndarray] | None, dt: float) -> np.ndarray:
    """The 25-D Fetch observation from the robot state and the cube position (rotation unknown: zero).

    Velocities are per-step displacements, as Fetch multiplies them by the step time ``dt``; the cube's
    comes from the change since ``previous`` (zero on the first step) relative to the gripper's.

    Args:
        state (RobotState): the robot now.
        cube (np.ndarray): the cube's robot-frame position.
        previous (tuple or None): ``(state, cube)`` of the previous step; ``None`` on the first step.
        dt (float): the simulator's step time.

    Example:
        >>> state = RobotState(np.zeros(3), np.zeros(3), np.full(2, 0.04), np.zeros(2))
        >>> fetch_observation(state, np.array([0.1, 0.0, 0.0]), None, 0.04).shape
        (25,)
    """
    if previous is None:
        cube_velp = np.zeros(3)
    else:
        cube_velp = (cube - previous[1]) - (state.grip_pos - previous[0].grip_pos)
    return FETCH_OBSERVATION.pack(
        gripper_position=state.grip_pos,
        object_position=cube,
        object_relative_position=cube - state.grip_pos,
        finger_positions=state.finger_pos,
        object_rotation=np.zeros(3),
        object_velocity=cube_velp,
        object_angular_velocity=np.zeros(3),
        gripper_velocity=state.grip_vel * dt,
        finger_velocities=state.finger_vel * dt,
    )


class RealLoopEnv(EnvBase):
    """Camera + :class:`CubePerception` + robot backend, assembled into the policy's keys.

    Root and ``"next"``: float32 ``observation`` [25], ``achieved_goal`` [3] (the perceived cube),
    ``desired_goal`` [3], ``cube_position`` [3] (NaN when not perceived), bool ``perception_ok``,
    int64 ``perception_status`` and ``safety_status`` (:class:`SafetyStatus`), bool ``clamped``,
    ``is_success``; ``"next"`` adds ``reward`` and ``done``/``terminated``/``truncated``. When the cube
    is not perceived the cube entries of ``observation`` are NaN, so nothing downstream can act on a stale one.

    While the gripper is closed on something the width of the cube, the cube is where the gripper is:
    a lifted cube is off the table plane the camera measures on. Unless a camera with a parallax correction
    sees the cube along a ray that passes more than a cube's width from the gripper: then the gripper closed
    beside the cube, not on it.

    With ``more_views`` every camera is read on every step (so that no view's frame is older than the
    step), and the cube is taken from the first view, in order, that perceives it: the arm that hides it
    from one camera rarely hides it from a second one placed elsewhere.

    Args:
        backend (RobotBackend): the robot.
        camera (FrameSource): frame source (BGR).
        perception (CubePerception): the calibrated cube perception (reads ``"pixels"``).
        workspace (Workspace, optional): end-effector box and max step; ``None`` takes the layout's, the box
            the simulator trains in. Defaults to ``None``.
        layout (FrankaLayout, optional): goal space, success threshold, episode length and cube size.
            Defaults to ``FrankaLayout()`` (the Franka sim's).
        parallax (ParallaxCorrection, optional): correction of the perceived cube position for an oblique
            camera. Defaults to ``None``.
        goal (np.ndarray, optional): a fixed goal; ``None`` samples one per episode like the simulator.
            Defaults to ``None``.
        dt (float, optional): the simulator's step time, to scale velocities as Fetch does. Defaults to ``0.04``.
        more_views (sequence of CameraView, optional): further cameras, each with its own perception and
            parallax correction. Defaults to ``()``.

    Example:
        >>> from torchrl_cebp.sim2real import CubeLocator
        >>> from torchrl_cebp.sim2real.twin import MuJoCoTwinBackend, TwinCamera
        >>> backend = MuJoCoTwinBackend(seed=0)
        >>> env = RealLoopEnv(backend, TwinCamera(backend), CubePerception(CubeLocator(backend.calibration)))
        >>> env.rollout(2)["next", "observation"].shape
        torch.Size([2, 25])
    """

    def __init__(
        self,
        backend: RobotBackend,
        camera: FrameSource,
        perception: CubePerception,
        workspace: Workspace | None = None,
        layout: FrankaLayout = FrankaLayout(),
        parallax: ParallaxCorrection | None = None,
        goal: np.ndarray | None = None,
        dt: float = 0.04,
        more_views: Sequence[CameraView] = (),
    ) -> None:
        super().__init__(device="cpu", batch_size=torch.Size([]))
        self.backend, self.layout = backend, layout
        self.workspace = layout.workspace if workspace is None else workspace
        self.views = (CameraView(camera, perception, parallax), *more_views)
        self.fixed_goal = None if goal is None else np.asarray(goal, np.float64)
        self.dt = dt
        self.max_episode_steps = layout.max_episode_steps
        self._rng = np.random.default_rng()
        self._goal = np.zeros(3)
        self._previous: tuple[RobotState, np.ndarray] | None = None
        self._steps = 0

        def flag() -> Categorical:
            return Categorical(2, (1,), dtype=torch.bool)

        self.observation_spec = Composite(
            observation=Unbounded((FETCH_OBSERVATION.size,), dtype=torch.float32),
            achieved_goal=Unbounded((3,), dtype=torch.float32),
            desired_goal=Unbounded((3,), dtype=torch.float32),
            cube_position=Unbounded((3,), dtype=torch.float32),
            perception_ok=flag(),
            perception_status=Categorical(len(PerceptionStatus), (1,), dtype=torch.int64),
            safety_status=Categorical(len(SafetyStatus), (1,), dtype=torch.int64),
            clamped=flag(),
            is_success=flag(),
        )
        self.action_spec = Bounded(-1.0, 1.0, (4,), dtype=torch.float32)
        self.reward_spec = Unbounded((1,), dtype=torch.float32)
        self.done_spec = Composite(done=flag(), terminated=flag(), truncated=flag())

    @staticmethod
    def _look(view: CameraView, frame: np.ndarray) -> tuple[PerceptionStatus, np.ndarray, np.ndarray]:
        # The status, the cube as mapped onto the table plane, and the cube corrected for its height.
        td = view.perception(TensorDict(pixels=torch.from_numpy(frame)))
        status = PerceptionStatus(int(td["perception_status"]))
        on_plane = td["cube_position"].numpy().astype(np.float64)
        correct = status is PerceptionStatus.OK and view.parallax is not None
        return status, on_plane, view.parallax(on_plane) if correct else on_plane

    def _perceive(self, state: RobotState) -> tuple[np.ndarray, PerceptionStatus]:
        # What the latest observation was perceived from, one frame per view (debug annotates them).
        self.last_frames = tuple(view.camera.read() for view in self.views)
        looks = [self._look(view, frame) for view, frame in zip(self.views, self.last_frames)]
        status, _, cube = next((look for look in looks if look[0] is PerceptionStatus.OK), looks[0])
        sightings = [(view.parallax, on_plane) for view, (seen, on_plane, _) in zip(self.views, looks) if seen is PerceptionStatus.OK]
        # The gripper's word needs a camera that sees its markers: one that does not may have been moved.
        with_markers = any(seen is not PerceptionStatus.MARKERS for seen, _, _ in looks)
        if with_markers and self._in_gripper(state, sightings):
            return state.grip_pos.copy(), PerceptionStatus.OK
        return cube, status

    def _in_gripper(self, state: RobotState, sightings: list[tuple[ParallaxCorrection | None, np.ndarray]]) -> bool:
        # Closed on the cube: narrower than open, wider than empty, and the cube was at the fingers last step;
        # and no camera that sees the cube sees it off the gripper (a cube left behind on the table).
        width, size = state.gripper_width, self.layout.cube_size
        near = self._previous is not None and np.linalg.norm(self._previous[1] - self._previous[0].grip_pos) < size / 2
        seen_elsewhere = any(
            parallax is not None and parallax.ray_distance(seen, state.grip_pos) > size for parallax, seen in sightings
        )
        return near and 0.6 * size < width < 1.2 * size and not seen_elsewhere

    def _observe(self, safety: SafetyStatus, clamped: bool) -> dict[str, torch.Tensor]:
        state = self.backend.state()
        cube, status = self._perceive(state)
        ok = status is PerceptionStatus.OK
        if not ok:
            cube = np.full(3, np.nan)
            # PerceptionStatus and SafetyStatus share their codes for "markers" and "cube".
            safety = SafetyStatus(int(status)) if safety is SafetyStatus.OK else safety
        observation = fetch_observation(state, cube, self._previous if ok else None, self.dt)
        self._previous = (state, cube) if ok else None
        return self._pack(observation, cube, status, safety, clamped)

    def _pack(
        self, observation: np.ndarray, cube: np.ndarray, status: PerceptionStatus, safety: SafetyStatus, clamped: bool
    ) -> dict[str, torch.Tensor]:
        ok = status is PerceptionStatus.OK
        success = bool(ok and np.linalg.norm(cube - self._goal) <= self.layout.distance_threshold)
        achieved = torch.as_tensor(cube, dtype=torch.float32)
        return {
            "observation": torch.as_tensor(observation, dtype=torch.float32),
            "achieved_goal": achieved,
            "desired_goal": torch.as_tensor(self._goal, dtype=torch.float32),
            "cube_position": achieved.clone(),
            "perception_ok": torch.tensor([ok]),
            "perception_status": torch.tensor([int(status)]),
            "safety_status": torch.tensor([int(safety)]),
            "clamped": torch.tensor([clamped]),
            "is_success": torch.tensor([success]),
        }

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        self.backend.reset()
        self._goal = self.fixed_goal if self.fixed_goal is not None else sample_goal(self.layout, self._rng)
        self._previous, self._steps = None, 0
        out = self._observe(SafetyStatus.OK, False)
        not_done = torch.zeros(1, dtype=torch.bool)
        out.update(done=not_done, terminated=not_done.clone(), truncated=not_done.clone())
        return TensorDict(out, batch_size=self.batch_size)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action").detach().cpu().numpy().astype(np.float64)
        self._steps += 1
        clamped, safety = False, SafetyStatus.OK
        if not bool(tensordict.get("perception_ok").all()):
            safety = SafetyStatus(int(tensordict.get("perception_status")))
            self.backend.hold()
        elif not np.isfinite(action).all():
            safety = SafetyStatus.INVALID_ACTION
            self.backend.hold()
        else:
            wanted = np.clip(action[:3], -1.0, 1.0) * self.workspace.max_step
            delta = self.workspace.clamp(self.backend.state().grip_pos, wanted)
            clamped = bool(np.abs(delta - action[:3] * self.workspace.max_step).max() > 1e-9)
            self.backend.move(delta, float(np.clip(action[3], -1.0, 1.0)))
        truncated = torch.tensor([self._steps >= self.max_episode_steps])
        try:
            out = self._observe(safety, clamped)
            terminated = torch.zeros(1, dtype=torch.bool)
        except CameraLost:
            self.backend.stop()
            self._previous = None
            out = self._pack(
                np.full(FETCH_OBSERVATION.size, np.nan), np.full(3, np.nan), PerceptionStatus.MARKERS, SafetyStatus.CAMERA_LOST, clamped
            )
            terminated = torch.ones(1, dtype=torch.bool)
        out["reward"] = torch.tensor([0.0 if bool(out["is_success"]) else -1.0])
        out.update(done=terminated | truncated, terminated=terminated, truncated=truncated)
        return TensorDict(out, batch_size=self.batch_size)

    def _set_seed(self, seed: int | None) -> None:
        self._rng = np.random.default_rng(seed)
