"""Synthetic camera views of the calibrated table, for testing the perception without a robot.

The scene is painted top-down in the robot frame (1 px per millimetre by default) and warped into the
camera image by a perspective homography, so the true robot-frame position of everything is known.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from torchrl_cebp.sim2real.calibration import TableCalibration, aruco_dictionary

__all__ = ["render_table_scene"]

# An ArUco marker needs a white quiet zone around its black border to be found.
_QUIET_ZONE = 1.4


def render_table_scene(
    calibration: TableCalibration,
    cube_xy: tuple[float, float] | None,
    *,
    cube_size: float = 0.05,
    cube_yaw: float = 0.0,
    marker_size: float = 0.08,
    occluded_markers: Sequence[int] = (),
    image_size: tuple[int, int] = (480, 640),
    table_corners_px: np.ndarray | None = None,
    margin: float = 0.1,
    resolution: float = 1e-3,
    table_bgr: tuple[int, int, int] = (170, 190, 200),
    cube_bgr: tuple[int, int, int] = (30, 30, 200),
) -> np.ndarray:
    """Renders the table with its markers and a red cube top face as a camera would see it.

    Args:
        calibration (TableCalibration): the markers (ids, robot-frame centres, dictionary) to paint.
        cube_xy (tuple of float or None): robot-frame ``(x, y)`` of the cube centre; ``None`` paints no cube.
        cube_size (float, optional): cube edge, metres. Defaults to ``0.05``.
        cube_yaw (float, optional): cube rotation about the table normal, radians. Defaults to ``0.0``.
        marker_size (float, optional): printed marker edge (black border included), metres. Defaults to ``0.08``.
        occluded_markers (sequence of int, optional): ids painted over by a dark patch, as if a hand covered
            them. Defaults to ``()``.
        image_size (tuple of int, optional): ``(height, width)`` of the camera image. Defaults to ``(480, 640)``.
        table_corners_px (np.ndarray, optional): ``[4, 2]`` image pixels where the table rectangle's corners
            land (far-left, far-right, near-right, near-left); ``None`` is an oblique view from behind the
            table. Defaults to ``None``.
        margin (float, optional): table border around the markers, metres. Defaults to ``0.1``.
        resolution (float, optional): metres per pixel of the top-down painting. Defaults to ``1e-3``.
        table_bgr (tuple of int, optional): table colour. Defaults to ``(170, 190, 200)``.
        cube_bgr (tuple of int, optional): cube colour. Defaults to ``(30, 30, 200)``.

    Returns:
        An ``image_size + (3,)`` uint8 BGR frame.

    Examples:
        >>> calibration = TableCalibration({0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)})
        >>> render_table_scene(calibration, cube_xy=(0.5, 0.1)).shape
        (480, 640, 3)
    """
    points = calibration.robot_points()
    x_min, y_min = points.min(axis=0) - margin
    x_max, y_max = points.max(axis=0) + margin
    width, height = round((y_max - y_min) / resolution), round((x_max - x_min) / resolution)

    def to_canvas(xy: np.ndarray) -> np.ndarray:
        # Canvas columns run along -y and rows along -x: far side of the table (large x) at the top.
        xy = np.asarray(xy, dtype=np.float64)
        return np.stack([(y_max - xy[..., 1]) / resolution, (x_max - xy[..., 0]) / resolution], axis=-1)

    canvas = np.empty((height, width, 3), np.uint8)
    canvas[:] = table_bgr
    dictionary = aruco_dictionary(calibration.aruco_dictionary)
    side = round(marker_size / resolution)
    for marker_id, xy in calibration.marker_positions.items():
        col, row = np.round(to_canvas(xy)).astype(int)
        _paste_square(canvas, col, row, np.full((_odd(side * _QUIET_ZONE),) * 2, 255, np.uint8))
        _paste_square(canvas, col, row, cv2.aruco.generateImageMarker(dictionary, marker_id, _odd(side)))
        if marker_id in occluded_markers:
            _paste_square(canvas, col, row, np.full((_odd(side * 1.6),) * 2, 50, np.uint8))
    if cube_xy is not None:
        half = cube_size / 2
        c, s = np.cos(cube_yaw), np.sin(cube_yaw)
        corners = np.array([[-half, -half], [half, -half], [half, half], [-half, half]]) @ [[c, s], [-s, c]]
        polygon = to_canvas(corners + np.asarray(cube_xy))
        # Sub-pixel vertices (shift=4) keep the painted centre within a fraction of a millimetre.
        cv2.fillPoly(canvas, [np.round(polygon * 16).astype(np.int32)], cube_bgr, cv2.LINE_AA, shift=4)

    if table_corners_px is None:
        h, w = image_size
        table_corners_px = np.array(
            [[0.25 * w, 0.12 * h], [0.75 * w, 0.12 * h], [0.97 * w, 0.95 * h], [0.03 * w, 0.95 * h]]
        )
    canvas_corners = np.array([[0, 0], [width, 0], [width, height], [0, height]], np.float32)
    homography = cv2.getPerspectiveTransform(canvas_corners, np.asarray(table_corners_px, np.float32))
    return cv2.warpPerspective(
        canvas, homography, (image_size[1], image_size[0]), flags=cv2.INTER_LINEAR, borderValue=(40, 40, 40)
    )


def _odd(size: float) -> int:
    # An odd-sized square centred on a pixel has its centre exactly there, not half a pixel off.
    return 2 * round(size / 2) + 1


def _paste_square(canvas: np.ndarray, col: int, row: int, patch: np.ndarray) -> None:
    size = patch.shape[0]
    top, left = row - size // 2, col - size // 2
    canvas[top : top + size, left : left + size] = patch[..., None]
