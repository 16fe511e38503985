"""The MuJoCo digital twin of the real setup: the Franka scene, ArUco markers on the table, fixed cameras.

The markers are generated with ``cv2.aruco.generateImageMarker`` and written as PNG textures to a cache
directory at run time, so the twin's camera images go through exactly the perception the real camera
images go through.
"""

from __future__ import annotations

import gc
import os
import tempfile
from pathlib import Path

import cv2
import mujoco
import numpy as np
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModuleBase

from torchrl_cebp.envs.franka import FrankaLayout, FrankaPickPlaceEnv
from torchrl_cebp.envs.layout import FETCH_OBSERVATION as OBS
from torchrl_cebp.sim2real.calibration import TableCalibration, aruco_dictionary
from torchrl_cebp.sim2real.camera import FrameSource
from torchrl_cebp.sim2real.robot import RobotBackend, RobotState

__all__ = ["CAMERA_NAME", "SIDE_CAMERA_NAME", "TWIN_CALIBRATION", "MuJoCoTwinBackend", "TwinCamera", "TwinScene", "marker_texture"]

# Outside the cube's and the goal's x/y range (table centre +- 0.1), inside the table (centre +- 0.35 x 0.45).
TWIN_CALIBRATION = TableCalibration(
    {0: (0.3, -0.35), 1: (0.3, 0.35), 2: (0.75, 0.35), 3: (0.75, -0.35)}, "DICT_4X4_50", table_height=0.0
)
CAMERA_NAME = "sim2real_camera"
# The second view, beside the table: it sees the cube between the fingers where the arm hides it from the first.
SIDE_CAMERA_NAME = "sim2real_side_camera"
# An ArUco marker needs a white quiet zone around its black border to be found.
_QUIET_ZONE = 1.4


def marker_texture(dictionary: str, marker_id: int, pixels: int = 140, cache_dir: str | Path | None = None) -> Path:
    """A PNG of marker ``marker_id`` with a white quiet zone, written once to ``cache_dir``.

    Args:
        dictionary (str): the predefined ArUco dictionary's name.
        marker_id (int): the marker.
        pixels (int, optional): the PNG's side, quiet zone included. Defaults to ``140``.
        cache_dir (str or Path, optional): where the PNG is kept; ``None`` is a folder in the temp dir.
            Defaults to ``None``.

    Returns:
        the PNG's path.

    Example:
        >>> import cv2
        >>> cv2.imread(str(marker_texture("DICT_4X4_50", 3))).shape
        (140, 140, 3)
    """
    cache = Path(cache_dir) if cache_dir is not None else Path(tempfile.gettempdir()) / "torchrl_cebp_aruco"
    path = cache / f"{dictionary}_{marker_id}_{pixels}.png"
    if not path.exists():
        cache.mkdir(parents=True, exist_ok=True)
        side = round(pixels / _QUIET_ZONE)
        image = np.full((pixels, pixels), 255, np.uint8)
        offset = (pixels - side) // 2
        image[offset : offset + side, offset : offset + side] = cv2.aruco.generateImageMarker(
            aruco_dictionary(dictionary), marker_id, side
        )
        # Write then rename, so a concurrent reader never sees half a PNG.
        tmp = path.with_suffix(f".{os.getpid()}.png")
        cv2.imwrite(str(tmp), cv2.cvtColor(image, cv2.COLOR_GRAY2BGR))
        tmp.replace(path)
    return path


def _look_at(position: np.ndarray, target: np.ndarray) -> list[float]:
    # MuJoCo's camera frame from its x and y axes: x to the image's right, y up, looking along -z.
    forward = (target - position) / np.linalg.norm(target - position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return [*right, *np.cross(right, forward)]


class TwinScene:
    """Adds the markers of a calibration and two fixed cameras to the Franka scene (a ``scene_hook``).

    The main camera (:data:`CAMERA_NAME`) faces the robot across the table, as in the paper's setup. The
    side camera (:data:`SIDE_CAMERA_NAME`) looks across the table from the robot's right: a second view,
    for a loop that must see the cube while the gripper hides it from the first.

    Args:
        calibration (TableCalibration, optional): marker ids and robot-frame centres (``table_height`` is the
            table top). Defaults to ``TWIN_CALIBRATION``.
        marker_size (float, optional): printed marker edge, black border included, metres. Defaults to ``0.08``.
        camera_pos (tuple of float, optional): where the main camera is (robot frame).
            Defaults to ``(1.25, 0.0, 0.95)``.
        camera_target (tuple of float, optional): what the main camera looks at. Defaults to ``(0.5, 0.0, 0.0)``.
        side_camera_pos (tuple of float, optional): where the side camera is. Defaults to ``(0.5, -0.85, 1.0)``.
        side_camera_target (tuple of float, optional): what the side camera looks at.
            Defaults to ``(0.55, 0.0, 0.0)``.
        fovy (float, optional): vertical field of view, degrees. Defaults to ``50.0``.
        image_size (tuple of int, optional): ``(height, width)`` of the rendered frames. Defaults to ``(360, 480)``.

    Example:
        >>> env = FrankaPickPlaceEnv(scene_hook=TwinScene(TWIN_CALIBRATION))
        >>> env.model.camera(CAMERA_NAME).id, env.model.camera(SIDE_CAMERA_NAME).id
        (0, 1)
    """

    def __init__(
        self,
        calibration: TableCalibration = TWIN_CALIBRATION,
        marker_size: float = 0.08,
        camera_pos: tuple[float, float, float] = (1.25, 0.0, 0.95),
        camera_target: tuple[float, float, float] = (0.5, 0.0, 0.0),
        side_camera_pos: tuple[float, float, float] = (0.5, -0.85, 1.0),
        side_camera_target: tuple[float, float, float] = (0.55, 0.0, 0.0),
        fovy: float = 50.0,
        image_size: tuple[int, int] = (360, 480),
    ) -> None:
        self.calibration = calibration
        self.marker_size = marker_size
        self.camera_pos = np.asarray(camera_pos, np.float64)
        self.camera_target = np.asarray(camera_target, np.float64)
        self.side_camera_pos = np.asarray(side_camera_pos, np.float64)
        self.side_camera_target = np.asarray(side_camera_target, np.float64)
        self.fovy = fovy
        self.image_size = image_size

    def camera_position(self, name: str) -> np.ndarray:
        """Where camera ``name`` is, in the robot frame.

        Args:
            name (str): :data:`CAMERA_NAME` or :data:`SIDE_CAMERA_NAME`.

        Raises:
            ValueError: another name.
        """
        positions = {CAMERA_NAME: self.camera_pos, SIDE_CAMERA_NAME: self.side_camera_pos}
        if name not in positions:
            raise ValueError(f"The twin has no camera {name!r}; its cameras: {', '.join(positions)}.")
        return positions[name].copy()

    def __call__(self, spec: mujoco.MjSpec) -> None:
        half = self.marker_size * _QUIET_ZONE / 2
        for marker_id, (x, y) in self.calibration.marker_positions.items():
            name = f"aruco_{marker_id}"
            png = marker_texture(self.calibration.aruco_dictionary, marker_id)
            spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D, file=str(png))
            material = spec.add_material(name=name)
            material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
            spec.worldbody.add_geom(
                name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=[half, half, 0.0005],
                pos=[x, y, self.calibration.table_height + 0.0005], material=name, contype=0, conaffinity=0,
            )
        for name, position, target in (
            (CAMERA_NAME, self.camera_pos, self.camera_target),
            (SIDE_CAMERA_NAME, self.side_camera_pos, self.side_camera_target),
        ):
            spec.worldbody.add_camera(name=name, pos=position.tolist(), xyaxes=_look_at(position, target), fovy=self.fovy)
        spec.visual.global_.offheight = max(spec.visual.global_.offheight, self.image_size[0])
        spec.visual.global_.offwidth = max(spec.visual.global_.offwidth, self.image_size[1])


class MuJoCoTwinBackend(RobotBackend):
    """The Franka pick-and-place simulation as a robot backend, with the markers and camera of :class:`TwinScene`.

    ``move`` is one simulator step (20 physics substeps, 40 ms) of the Fetch-style action; ``hold`` is
    a step that stays put with the last gripper command. After :meth:`stop` the arm refuses to move
    until :meth:`reset`, as a real robot after a stop would.

    Args:
        scene (TwinScene, optional): markers and cameras; ``None`` is ``TwinScene()``. Defaults to ``None``.
        layout (FrankaLayout, optional): the Franka scene geometry. Defaults to ``FrankaLayout()``.
        seed (int, optional): seeds the first episode's cube placement; ``None`` leaves it unseeded.
            Defaults to ``None``.

    Example:
        >>> backend = MuJoCoTwinBackend(seed=0)
        >>> backend.reset()
        >>> backend.move(np.array([0.0, 0.0, 0.02]), gripper=1.0)
        >>> round(float(backend.state().grip_pos[2]), 2)
        0.24
    """

    def __init__(
        self, scene: TwinScene | None = None, layout: FrankaLayout = FrankaLayout(), seed: int | None = None
    ) -> None:
        self.scene = TwinScene() if scene is None else scene
        self.env = FrankaPickPlaceEnv(layout=layout, scene_hook=self.scene)
        self.layout = layout
        self._seed = seed
        self._gripper = 1.0
        self.stopped = False

    @property
    def max_step(self) -> float:
        """The largest displacement one :meth:`move` can make (Fetch's action scale, which the env keeps)."""
        return self.layout.workspace.max_step

    @property
    def calibration(self) -> TableCalibration:
        """The markers as placed in the model (what the hardware calibration would measure)."""
        model = self.env.model
        positions = {
            marker_id: tuple(model.geom(f"aruco_{marker_id}").pos[:2]) for marker_id in self.scene.calibration.marker_ids
        }
        return TableCalibration(positions, self.scene.calibration.aruco_dictionary, self.layout.table_height)

    def reset(self) -> None:
        """Resets the simulation: the arm to its start pose, gripper open, the cube to its next placement."""
        self.env.reset(seed=self._seed)
        self._seed = None  # seeds the first episode only; later ones continue the stream
        self._gripper = 1.0
        self.stopped = False

    def state(self) -> RobotState:
        """The simulated grip point's and fingers' positions and velocities."""
        obs = self.env._get_obs()["observation"]
        dt = self.env.dt
        # Fetch's observation stores velocities multiplied by the step time.
        return RobotState(
            grip_pos=obs[OBS.gripper_position],
            grip_vel=obs[OBS.gripper_velocity] / dt,
            finger_pos=obs[OBS.finger_positions],
            finger_vel=obs[OBS.finger_velocities] / dt,
        )

    def move(self, delta_xyz: np.ndarray, gripper: float) -> None:
        """One simulator step towards ``delta_xyz`` with the gripper command.

        Args:
            delta_xyz (np.ndarray): the robot-frame displacement, at most :attr:`max_step` per axis.
            gripper (float): ``+1`` opens fully, ``-1`` closes.

        Raises:
            RuntimeError: the twin was stopped and not reset since.
        """
        if self.stopped:
            raise RuntimeError("The twin robot was stopped; reset() it before moving again.")
        self._gripper = float(gripper)
        action = np.append(np.clip(np.asarray(delta_xyz) / self.max_step, -1.0, 1.0), self._gripper)
        self.env.step(action.astype(np.float32))

    def hold(self) -> None:
        """One simulator step that stays put with the last gripper command (nothing once stopped)."""
        if not self.stopped:
            self.env.step(np.array([0.0, 0.0, 0.0, self._gripper], np.float32))

    def stop(self) -> None:
        """Refuses every :meth:`move` until :meth:`reset`."""
        self.stopped = True

    @torch.no_grad()
    def simulate(self, policy: TensorDictModuleBase, goal: np.ndarray) -> bool:
        """One episode in plain simulation: ``policy`` acts on the true state (no camera), towards ``goal``.

        Resets like :meth:`reset` (the next cube placement of the seed's stream), so a second backend with
        the seed of a camera loop's replays that loop's episodes on the same cube placements and goals.
        Args:
            policy (TensorDictModuleBase): reads ``"observation"`` and ``"desired_goal"``, writes ``"action"``.
            goal (np.ndarray): the goal ``[x, y, z]``.

        Returns:
            whether the cube ends within the success threshold of ``goal``, as the camera loop scores it.

        Example:
            >>> from torchrl_cebp.sim2real import ScriptedPickPlace
            >>> type(MuJoCoTwinBackend(seed=0).simulate(ScriptedPickPlace(), np.array([0.5, 0.0, 0.2])))
            <class 'bool'>
        """
        self.reset()
        self.env.goal = np.asarray(goal, np.float64).copy()
        obs = self.env._get_obs()
        info: dict = {}
        for _ in range(self.layout.max_episode_steps):
            td = TensorDict({key: torch.as_tensor(obs[key], dtype=torch.float32) for key in ("observation", "desired_goal")})
            obs, _, _, _, info = self.env.step(policy(td)["action"].numpy())
        return bool(info["is_success"])

    def cube_position(self) -> np.ndarray:
        """Ground truth the real setup does not have: the simulated cube's centre."""
        return self.env._utils.get_site_xpos(self.env.model, self.env.data, "object0").copy()

    @property
    def touch(self) -> np.ndarray:
        """Finger-pad touch of the last step (left, right)."""
        return self.env.touch.copy()


class TwinCamera(FrameSource):
    """Renders one of the twin's fixed cameras: BGR frames, like :class:`~torchrl_cebp.sim2real.camera.OpenCVCamera`'s.

    Args:
        backend (MuJoCoTwinBackend): the twin.
        name (str, optional): :data:`CAMERA_NAME` (the main camera) or :data:`SIDE_CAMERA_NAME`.
            Defaults to ``CAMERA_NAME``.

    Example:
        >>> backend = MuJoCoTwinBackend(seed=0)
        >>> backend.reset()
        >>> TwinCamera(backend).read().shape, TwinCamera(backend, SIDE_CAMERA_NAME).position.tolist()
        ((360, 480, 3), [0.5, -0.85, 1.0])
    """

    def __init__(self, backend: MuJoCoTwinBackend, name: str = CAMERA_NAME) -> None:
        super().__init__(expected_size=backend.scene.image_size)
        self.backend = backend
        self.name = name
        self.position = backend.scene.camera_position(name)
        height, width = backend.scene.image_size
        # MuJoCo's render context frees its GL objects by id in whichever GL context is current when it is
        # destroyed. One left unreachable in a reference cycle (a closed or dropped gymnasium env's
        # renderer) and collected after this camera rendered wipes this camera's textures: collect such
        # garbage before this camera's context exists.
        gc.collect()
        self._renderer = mujoco.Renderer(backend.env.model, height, width)
        self.lost = False  # set to simulate an unplugged camera

    def _grab(self) -> np.ndarray | None:
        if self.lost:
            return None
        self._renderer.update_scene(self.backend.env.data, camera=self.name)
        return cv2.cvtColor(self._renderer.render(), cv2.COLOR_RGB2BGR)

    def close(self) -> None:
        """Frees the renderer."""
        self._renderer.close()

    def __repr__(self) -> str:
        return f"TwinCamera({self.name!r})"
