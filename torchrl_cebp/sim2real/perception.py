"""Camera perception for the Sim2Real pick-and-place: where is the red cube in the robot frame?

ArUco markers at calibrated robot-frame positions give, per frame, a homography from image pixels to
the table plane; the red cube is found with an HSV colour filter and its pixel centre is mapped
through that homography (paper, Sim2Real section; no code was published).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import IntEnum

import cv2
import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs.transforms import Transform

from torchrl_cebp.sim2real.calibration import TableCalibration, aruco_dictionary

__all__ = [
    "RED_HSV_RANGES",
    "Blob",
    "ColorBlobDetector",
    "CubeLocalization",
    "CubeLocator",
    "CubePerception",
    "HSVRange",
    "MarkerDetector",
    "PerceptionStatus",
    "apply_homography",
    "draw_perception",
    "fit_homography",
]


class PerceptionStatus(IntEnum):
    """Outcome of one frame; the integer is what :class:`CubePerception` writes to the tensordict.

    ``OK`` (0): the cube is located. ``MARKERS`` (1): fewer than 4 calibrated markers are visible and the
    camera is not confirmed unmoved, so there is no homography. ``CUBE`` (2): no colour blob of at least
    the minimum area.

    Example:
        >>> PerceptionStatus(2).reason, int(PerceptionStatus.OK)
        ('cube', 0)
    """

    OK = 0
    MARKERS = 1
    CUBE = 2

    @property
    def reason(self) -> str:
        """``"ok"``, ``"markers"`` or ``"cube"``."""
        return self.name.lower()


def _quad_centre(corners: np.ndarray) -> np.ndarray:
    # The diagonals' intersection is the true projected centre under perspective; the corner mean is not.
    p0, p1, p2, p3 = corners.astype(np.float64)
    d1, d2 = p2 - p0, p3 - p1
    # ArUco quads are convex, so the diagonals always cross.
    t = ((p1[0] - p0[0]) * d2[1] - (p1[1] - p0[1]) * d2[0]) / (d1[0] * d2[1] - d1[1] * d2[0])
    return p0 + t * d1


class MarkerDetector:
    """Finds ArUco markers in a BGR frame and returns the pixel centre of each.

    Args:
        dictionary (str, optional): predefined ArUco dictionary name. Defaults to ``"DICT_4X4_50"``.
        ids (iterable of int, optional): only these marker ids are reported (others in view are ignored);
            ``None`` reports all. Defaults to ``None``.
        parameters (cv2.aruco.DetectorParameters, optional): OpenCV detector parameters; ``None`` gives
            OpenCV's defaults with corners refined to sub-pixel accuracy. Defaults to ``None``.

    Examples:
        >>> import cv2, numpy as np
        >>> dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
        >>> frame = np.full((200, 200, 3), 255, np.uint8)
        >>> frame[50:150, 50:150] = cv2.aruco.generateImageMarker(dictionary, 7, 100)[..., None]
        >>> centres = MarkerDetector("DICT_4X4_50").detect(frame)
        >>> list(centres), np.round(centres[7]).tolist()
        ([7], [100.0, 100.0])
    """

    def __init__(
        self,
        dictionary: str = "DICT_4X4_50",
        ids: Iterable[int] | None = None,
        parameters: cv2.aruco.DetectorParameters | None = None,
    ) -> None:
        if parameters is None:
            parameters = cv2.aruco.DetectorParameters()
            parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.ids = None if ids is None else frozenset(ids)
        self._detector = cv2.aruco.ArucoDetector(aruco_dictionary(dictionary), parameters)

    def detect(self, frame: np.ndarray) -> dict[int, np.ndarray]:
        """Marker id -> pixel centre ``(u, v)`` (float64) of each wanted marker seen exactly once.

        Args:
            frame (np.ndarray): ``H x W x 3`` uint8 BGR.
        """
        corners, ids, _ = self._detector.detectMarkers(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
        if ids is None:
            return {}
        found: dict[int, list[np.ndarray]] = {}
        for marker_id, quad in zip(ids.ravel().tolist(), corners):
            if self.ids is None or marker_id in self.ids:
                found.setdefault(marker_id, []).append(_quad_centre(quad.reshape(4, 2)))
        # An id seen twice (a reflection, a second print) is ambiguous: treat it as not seen.
        return {marker_id: centres[0] for marker_id, centres in found.items() if len(centres) == 1}


def fit_homography(pixel_points: np.ndarray, robot_points: np.ndarray) -> np.ndarray:
    """The ``3 x 3`` homography from pixel ``(u, v)`` to robot-frame table ``(x, y)``.

    Exactly 4 correspondences use ``cv2.getPerspectiveTransform``; more use a least-squares
    ``cv2.findHomography`` over all of them.

    Args:
        pixel_points (np.ndarray): ``[N, 2]`` pixel ``(u, v)``, ``N >= 4``.
        robot_points (np.ndarray): the matching ``[N, 2]`` robot-frame ``(x, y)``.

    Raises:
        ValueError: fewer than 4 pairs, or unequal counts.

    Examples:
        >>> import numpy as np
        >>> pixels = np.array([[0, 0], [100, 0], [100, 100], [0, 100]], np.float32)
        >>> H = fit_homography(pixels, pixels / 100)
        >>> apply_homography(H, np.array([[50.0, 25.0]])).round(3).tolist()
        [[0.5, 0.25]]
    """
    pixel_points = np.asarray(pixel_points, np.float32).reshape(-1, 2)
    robot_points = np.asarray(robot_points, np.float32).reshape(-1, 2)
    if len(pixel_points) != len(robot_points) or len(pixel_points) < 4:
        raise ValueError(
            f"A homography needs at least 4 matching point pairs, got {len(pixel_points)} pixel and "
            f"{len(robot_points)} robot-frame points."
        )
    if len(pixel_points) == 4:
        return cv2.getPerspectiveTransform(pixel_points, robot_points)
    homography, _ = cv2.findHomography(pixel_points, robot_points, method=0)
    return homography


def apply_homography(homography: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Maps ``[N, 2]`` points through ``homography``; returns ``[N, 2]`` float64.

    Args:
        homography (np.ndarray): ``3 x 3``.
        points (np.ndarray): ``[N, 2]``.

    Example:
        >>> apply_homography(np.diag([2.0, 3.0, 1.0]), np.array([[1.0, 1.0]])).tolist()
        [[2.0, 3.0]]
    """
    points = np.asarray(points, np.float64).reshape(-1, 1, 2)
    return cv2.perspectiveTransform(points, np.asarray(homography, np.float64)).reshape(-1, 2)


@dataclass(frozen=True)
class HSVRange:
    """An inclusive OpenCV HSV box (hue 0-180, saturation and value 0-255).

    Args:
        lower (tuple of int): the lowest ``(h, s, v)``.
        upper (tuple of int): the highest ``(h, s, v)``.

    Example:
        >>> import numpy as np
        >>> blue = HSVRange((100, 100, 50), (130, 255, 255))
        >>> frame = np.zeros((40, 40, 3), np.uint8); frame[10:30, 10:30] = (255, 0, 0)
        >>> ColorBlobDetector([blue], min_area=50).detect(frame).centre.tolist()
        [19.5, 19.5]
    """

    lower: tuple[int, int, int]
    upper: tuple[int, int, int]


# Red straddles hue 0 = 180 in OpenCV's hue circle, so it takes two boxes.
RED_HSV_RANGES: tuple[HSVRange, ...] = (
    HSVRange((0, 100, 50), (10, 255, 255)),
    HSVRange((170, 100, 50), (180, 255, 255)),
)


@dataclass(frozen=True)
class Blob:
    """A detected colour region, as :meth:`ColorBlobDetector.detect` returns it.

    Args:
        centre (np.ndarray): pixel centroid ``(u, v)``.
        contour (np.ndarray): outer contour ``[N, 1, 2]``.
        area (float): area in pixels.

    Example:
        >>> import numpy as np
        >>> frame = np.zeros((40, 40, 3), np.uint8); frame[10:20, 10:30] = (0, 0, 255)
        >>> blob = ColorBlobDetector(min_area=50).detect(frame)
        >>> blob.area, blob.contour.shape[1:]
        (165.0, (1, 2))
    """

    centre: np.ndarray
    contour: np.ndarray
    area: float


class ColorBlobDetector:
    """Finds the largest region inside any of some HSV ranges (by default: red).

    Args:
        hsv_ranges (sequence of HSVRange, optional): the colour boxes; a pixel in any of them counts.
            Defaults to ``RED_HSV_RANGES``.
        min_area (float, optional): smaller regions (pixels) are noise, not the cube. Defaults to ``100.0``.
        open_kernel (int, optional): side of the morphological opening that removes speckle before contours
            are taken; ``0`` or ``1`` disables it. Defaults to ``5``.

    Raises:
        ValueError: no HSV range.

    Examples:
        >>> import numpy as np
        >>> frame = np.full((100, 100, 3), 200, np.uint8)
        >>> frame[20:40, 60:80] = (0, 0, 255)
        >>> blob = ColorBlobDetector(min_area=50).detect(frame)
        >>> blob.centre.round(1).tolist(), blob.area > 300
        ([69.5, 29.5], True)
    """

    def __init__(
        self, hsv_ranges: Sequence[HSVRange] = RED_HSV_RANGES, min_area: float = 100.0, open_kernel: int = 5
    ) -> None:
        if not hsv_ranges:
            raise ValueError("ColorBlobDetector needs at least one HSV range.")
        self.hsv_ranges = tuple(hsv_ranges)
        self.min_area = min_area
        self._kernel = (
            cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (open_kernel, open_kernel)) if open_kernel > 1 else None
        )

    def mask(self, frame: np.ndarray) -> np.ndarray:
        """The ``uint8`` 0/255 mask of in-range pixels of a BGR frame, speckle removed.

        Args:
            frame (np.ndarray): ``H x W x 3`` uint8 BGR.
        """
        hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV)
        mask = np.zeros(hsv.shape[:2], np.uint8)
        for hsv_range in self.hsv_ranges:
            mask |= cv2.inRange(hsv, np.array(hsv_range.lower), np.array(hsv_range.upper))
        if self._kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        return mask

    def detect(self, frame: np.ndarray) -> Blob | None:
        """The largest in-range region of at least ``min_area`` pixels, or ``None``.

        Args:
            frame (np.ndarray): ``H x W x 3`` uint8 BGR.
        """
        contours, _ = cv2.findContours(self.mask(frame), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if not contours:
            return None
        contour = max(contours, key=cv2.contourArea)
        moments = cv2.moments(contour)
        if moments["m00"] == 0 or moments["m00"] < self.min_area:
            return None
        centre = np.array([moments["m10"] / moments["m00"], moments["m01"] / moments["m00"]])
        return Blob(centre=centre, contour=contour, area=float(moments["m00"]))


@dataclass(frozen=True)
class CubeLocalization:
    """What :meth:`CubeLocator.locate` saw in one frame.

    ``position`` is the robot-frame cube centre (float32 ``[3]``), all NaN unless ``status`` is OK; the
    other fields are kept whatever the status, for the debug drawing. ``homography_kept`` says that fewer
    than 4 markers were seen and the homography is the one last fitted on at least 4 (the camera had not moved).

    Args:
        status (PerceptionStatus): the outcome.
        position (np.ndarray): the cube centre, float32 ``[3]``.
        marker_centres (dict): marker id -> pixel centre of the markers seen.
        missing_markers (tuple of int): the calibrated markers not seen.
        blob (Blob or None): the cube's colour region, if found.
        homography (np.ndarray or None): pixel to table plane, if any.
        homography_kept (bool, optional): the homography is the last one fitted. Defaults to ``False``.

    Example:
        >>> import numpy as np
        >>> calibration = TableCalibration({0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)})
        >>> seen = CubeLocator(calibration).locate(np.full((120, 160, 3), 255, np.uint8))
        >>> seen.reason, seen.missing_markers, bool(np.isnan(seen.position).all())
        ('markers', (0, 1, 2, 3), True)
    """

    status: PerceptionStatus
    position: np.ndarray
    marker_centres: dict[int, np.ndarray]
    missing_markers: tuple[int, ...]
    blob: Blob | None
    homography: np.ndarray | None
    homography_kept: bool = False

    @property
    def ok(self) -> bool:
        """Whether ``position`` is valid."""
        return self.status is PerceptionStatus.OK

    @property
    def reason(self) -> str:
        """``"ok"``, ``"markers"`` or ``"cube"``."""
        return self.status.reason


def _plane_centroid(homography: np.ndarray, contour: np.ndarray) -> np.ndarray:
    # Perspective enlarges the near half of the cube face, pulling the pixel centroid towards the
    # camera; the centroid of the contour mapped onto the table plane has no such bias.
    outline = apply_homography(homography, contour.reshape(-1, 2)).astype(np.float32)
    moments = cv2.moments(outline)
    return np.array([moments["m10"] / moments["m00"], moments["m01"] / moments["m00"]])


class CubeLocator:
    """Locates the cube in the robot frame from one BGR frame.

    The homography is refitted on every frame from all visible calibrated markers (at least 4), so a
    bumped camera is followed rather than silently mis-mapping. When the arm hides markers and fewer than
    4 are seen, the homography last fitted is kept, but only while at least ``min_markers_to_confirm`` of
    the visible markers sit within ``camera_moved_px`` pixels of where they were then: a fixed camera that
    has not moved maps the table as before, and a moved one is caught by the markers it still sees. That
    memory belongs to one camera: give each camera its own locator.

    Args:
        calibration (TableCalibration): the markers' robot-frame positions, dictionary and table height.
        cube_size (float, optional): cube edge in metres; the cube centre is half of it above the table.
            Defaults to ``0.05``.
        blob_detector (ColorBlobDetector, optional): how the cube is found; ``None`` finds red.
            Defaults to ``None``.
        marker_parameters (cv2.aruco.DetectorParameters, optional): OpenCV ArUco detector parameters, see
            :class:`MarkerDetector`. Defaults to ``None``.
        camera_moved_px (float, optional): how far (pixels) a visible marker may lie from its position at the
            last fit before the camera counts as moved; ``None`` never keeps a homography (every frame needs
            4 markers). Defaults to ``2.0``.
        min_markers_to_confirm (int, optional): how many visible markers must confirm an unmoved camera.
            Defaults to ``2``.

    Raises:
        ValueError: ``min_markers_to_confirm`` below 1.

    Examples:
        >>> from torchrl_cebp.sim2real.synthetic import render_table_scene
        >>> calibration = TableCalibration({0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)})
        >>> frame = render_table_scene(calibration, cube_xy=(0.55, 0.1))
        >>> result = CubeLocator(calibration, cube_size=0.05).locate(frame)
        >>> result.reason, [round(float(v), 2) for v in result.position[:2]], round(float(result.position[2]), 3)
        ('ok', [0.55, 0.1], 0.025)
    """

    def __init__(
        self,
        calibration: TableCalibration,
        cube_size: float = 0.05,
        blob_detector: ColorBlobDetector | None = None,
        marker_parameters: cv2.aruco.DetectorParameters | None = None,
        camera_moved_px: float | None = 2.0,
        min_markers_to_confirm: int = 2,
    ) -> None:
        if min_markers_to_confirm < 1:
            raise ValueError(f"min_markers_to_confirm must be at least 1, got {min_markers_to_confirm}.")
        self.calibration = calibration
        self.cube_size = cube_size
        self.blob_detector = ColorBlobDetector() if blob_detector is None else blob_detector
        self.marker_detector = MarkerDetector(
            calibration.aruco_dictionary, calibration.marker_ids, marker_parameters
        )
        self.camera_moved_px = camera_moved_px
        self.min_markers_to_confirm = min_markers_to_confirm
        self._last_fit: tuple[np.ndarray, dict[int, np.ndarray]] | None = None  # homography, marker centres

    def _kept_homography(self, markers: dict[int, np.ndarray]) -> np.ndarray | None:
        if self._last_fit is None or self.camera_moved_px is None:
            return None
        homography, fitted_on = self._last_fit
        shifts = [float(np.linalg.norm(markers[i] - fitted_on[i])) for i in markers.keys() & fitted_on.keys()]
        if len(shifts) < self.min_markers_to_confirm or max(shifts) > self.camera_moved_px:
            return None
        return homography

    def locate(self, frame: np.ndarray) -> CubeLocalization:
        """Detects markers and cube in ``frame`` and maps the cube to the robot frame.

        Args:
            frame (np.ndarray): ``H x W x 3`` uint8 BGR.
        """
        markers = self.marker_detector.detect(frame)
        missing = tuple(i for i in self.calibration.marker_ids if i not in markers)
        visible = [i for i in self.calibration.marker_ids if i in markers]
        homography, kept = None, False
        if len(visible) >= 4:
            homography = fit_homography(
                np.array([markers[i] for i in visible]), self.calibration.robot_points(visible)
            )
            self._last_fit = (homography, markers)
        else:
            homography = self._kept_homography(markers)
            kept = homography is not None
        blob = self.blob_detector.detect(frame)
        position = np.full(3, np.nan, np.float32)
        if homography is None:
            status = PerceptionStatus.MARKERS
        elif blob is None:
            status = PerceptionStatus.CUBE
        else:
            status = PerceptionStatus.OK
            position[:2] = _plane_centroid(homography, blob.contour)
            position[2] = self.calibration.table_height + self.cube_size / 2
        return CubeLocalization(status, position, markers, missing, blob, homography, kept)


class CubePerception(Transform):
    """Writes the cube's robot-frame position, read off a camera image, into the tensordict.

    On every step and reset the image under ``in_key`` (uint8 ``[*batch, H, W, 3]``) goes through a
    :class:`CubeLocator`. Three entries are written: ``position_key`` (float32 ``[*batch, 3]``, NaN when
    perception failed, never a stale value), ``ok_key`` (bool) and ``status_key`` (int64
    :class:`PerceptionStatus`: 0 ok, 1 markers missing, 2 cube not found).

    Args:
        locator (CubeLocator): the calibrated cube locator.
        in_key (NestedKey, optional): the image entry. Defaults to ``"pixels"``.
        position_key (NestedKey, optional): the cube position's entry. Defaults to ``"cube_position"``.
        ok_key (NestedKey, optional): the success flag's entry. Defaults to ``"perception_ok"``.
        status_key (NestedKey, optional): the status's entry. Defaults to ``"perception_status"``.
        channel_order (str, optional): ``"bgr"`` for OpenCV camera frames (:mod:`torchrl_cebp.sim2real.camera`),
            ``"rgb"`` for pixels rendered by simulators and gym envs. Defaults to ``"bgr"``.

    Raises:
        ValueError: another ``channel_order``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.sim2real.synthetic import render_table_scene
        >>> calibration = TableCalibration({0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)})
        >>> perception = CubePerception(CubeLocator(calibration))
        >>> frame = torch.from_numpy(render_table_scene(calibration, cube_xy=(0.4, -0.1)))
        >>> td = perception(TensorDict(pixels=frame))
        >>> td["perception_ok"].item(), PerceptionStatus(td["perception_status"].item()).reason
        (True, 'ok')
        >>> [round(v, 2) for v in td["cube_position"].tolist()]
        [0.4, -0.1, 0.03]
    """

    def __init__(
        self,
        locator: CubeLocator,
        in_key: NestedKey = "pixels",
        position_key: NestedKey = "cube_position",
        ok_key: NestedKey = "perception_ok",
        status_key: NestedKey = "perception_status",
        channel_order: str = "bgr",
    ) -> None:
        if channel_order not in ("bgr", "rgb"):
            raise ValueError(f"channel_order must be 'bgr' or 'rgb', got {channel_order!r}.")
        super().__init__(in_keys=[in_key], out_keys=[position_key, ok_key, status_key])
        self.locator = locator
        self.channel_order = channel_order

    def _locate(self, image: np.ndarray) -> CubeLocalization:
        if self.channel_order == "rgb":
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        return self.locator.locate(np.ascontiguousarray(image))

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        """Perceives each image under ``in_key`` of ``next_tensordict`` and writes the three entries into it: the
        transform's work on every env step, and what calling it on a tensordict does."""
        pixels = next_tensordict.get(self.in_keys[0])
        batch_shape = pixels.shape[:-3]
        images = pixels.detach().cpu().numpy().reshape(-1, *pixels.shape[-3:])
        results = [self._locate(image) for image in images]
        position_key, ok_key, status_key = self.out_keys
        device = pixels.device
        next_tensordict.set(
            position_key,
            torch.from_numpy(np.stack([r.position for r in results])).reshape(*batch_shape, 3).to(device),
        )
        next_tensordict.set(
            ok_key, torch.tensor([r.ok for r in results], dtype=torch.bool, device=device).reshape(batch_shape)
        )
        next_tensordict.set(
            status_key,
            torch.tensor([int(r.status) for r in results], dtype=torch.int64, device=device).reshape(batch_shape),
        )
        return next_tensordict

    forward = _call

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        # The reset observation is a fresh frame: perceive it like any other.
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        """Adds the three output entries' specs.

        Args:
            observation_spec (Composite): the env's observation spec.
        """
        shape, device = observation_spec.shape, observation_spec.device
        position_key, ok_key, status_key = self.out_keys
        observation_spec[position_key] = Unbounded(shape=(*shape, 3), dtype=torch.float32, device=device)
        observation_spec[ok_key] = Categorical(2, shape=shape, dtype=torch.bool, device=device)
        observation_spec[status_key] = Categorical(
            len(PerceptionStatus), shape=shape, dtype=torch.int64, device=device
        )
        return observation_spec


_GREEN, _RED, _YELLOW, _MAGENTA = (0, 200, 0), (0, 0, 255), (0, 220, 255), (255, 0, 255)


def draw_perception(frame: np.ndarray, localization: CubeLocalization) -> np.ndarray:
    """A copy of ``frame`` annotated with what was perceived, for writing to disk with ``cv2.imwrite``.

    Draws the workspace polygon through the visible marker centres, each marker centre with its id, the
    cube contour and centre with its robot-frame ``(x, y, z)``, and a status line naming any missing
    markers.

    Args:
        frame (np.ndarray): the frame that was perceived (``H x W x 3`` uint8 BGR).
        localization (CubeLocalization): what :meth:`CubeLocator.locate` saw in it.

    Examples:
        >>> from torchrl_cebp.sim2real.synthetic import render_table_scene
        >>> calibration = TableCalibration({0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)})
        >>> frame = render_table_scene(calibration, cube_xy=(0.5, 0.0))
        >>> debug = draw_perception(frame, CubeLocator(calibration).locate(frame))
        >>> debug.shape == frame.shape and bool((debug != frame).any())
        True
    """
    canvas = frame.copy()
    font = cv2.FONT_HERSHEY_SIMPLEX
    centres = localization.marker_centres
    if len(centres) >= 3:
        hull = cv2.convexHull(np.array(list(centres.values()), np.float32)).astype(np.int32)
        cv2.polylines(canvas, [hull], isClosed=True, color=_YELLOW, thickness=2, lineType=cv2.LINE_AA)
    for marker_id, (u, v) in centres.items():
        cv2.circle(canvas, (round(u), round(v)), 4, _GREEN, -1, cv2.LINE_AA)
        cv2.putText(canvas, f"id {marker_id}", (round(u) + 6, round(v) - 6), font, 0.5, _GREEN, 1, cv2.LINE_AA)
    blob = localization.blob
    if blob is not None:
        u, v = (round(c) for c in blob.centre)
        cv2.drawContours(canvas, [blob.contour], -1, _MAGENTA, 2, cv2.LINE_AA)
        cv2.drawMarker(canvas, (u, v), _MAGENTA, cv2.MARKER_CROSS, 12, 2)
        if localization.ok:
            x, y, z = localization.position
            label = f"({x:.3f}, {y:.3f}, {z:.3f}) m"
            cv2.putText(canvas, label, (u + 8, v + 18), font, 0.5, _MAGENTA, 1, cv2.LINE_AA)
    if localization.ok:
        status, color = "ok", _GREEN
        if localization.homography_kept:
            status = f"ok, markers {list(localization.missing_markers)} hidden, camera unmoved"
    elif localization.status is PerceptionStatus.MARKERS:
        status, color = f"markers missing: {list(localization.missing_markers)}", _RED
    else:
        status, color = "cube not found", _RED
    cv2.putText(canvas, status, (10, 24), font, 0.7, color, 2, cv2.LINE_AA)
    return canvas
