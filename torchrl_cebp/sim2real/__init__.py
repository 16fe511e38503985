"""Sim2Real: camera sources, table calibration and the camera perception of the red cube."""

from torchrl_cebp.sim2real.calibration import TableCalibration, aruco_dictionary, aruco_dictionary_names
from torchrl_cebp.sim2real.camera import CameraLost, FrameSource, ImageFolderCamera, OpenCVCamera, check_frame
from torchrl_cebp.sim2real.perception import (
    RED_HSV_RANGES,
    Blob,
    ColorBlobDetector,
    CubeLocalization,
    CubeLocator,
    CubePerception,
    HSVRange,
    MarkerDetector,
    PerceptionStatus,
    apply_homography,
    draw_perception,
    fit_homography,
)
from torchrl_cebp.sim2real.synthetic import render_table_scene

__all__ = [
    "RED_HSV_RANGES",
    "Blob",
    "CameraLost",
    "ColorBlobDetector",
    "CubeLocalization",
    "CubeLocator",
    "CubePerception",
    "FrameSource",
    "HSVRange",
    "ImageFolderCamera",
    "MarkerDetector",
    "OpenCVCamera",
    "PerceptionStatus",
    "TableCalibration",
    "apply_homography",
    "aruco_dictionary",
    "aruco_dictionary_names",
    "check_frame",
    "draw_perception",
    "fit_homography",
    "render_table_scene",
]
