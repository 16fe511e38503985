"""Sim2Real: camera sources, table calibration, cube perception, robot backends (MuJoCo twin, Franka) and the loop."""

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
from torchrl_cebp.sim2real.policy import SHIPPED_POLICY, ScriptedPickPlace
from torchrl_cebp.sim2real.real_loop import CameraView, ParallaxCorrection, RealLoopEnv, SafetyStatus, Workspace
from torchrl_cebp.sim2real.robot import FrankyBackend, RobotBackend, RobotState
from torchrl_cebp.sim2real.synthetic import render_table_scene
from torchrl_cebp.sim2real.twin import CAMERA_NAME, SIDE_CAMERA_NAME, TWIN_CALIBRATION, MuJoCoTwinBackend, TwinCamera, TwinScene

__all__ = [
    "CAMERA_NAME",
    "RED_HSV_RANGES",
    "SHIPPED_POLICY",
    "SIDE_CAMERA_NAME",
    "TWIN_CALIBRATION",
    "Blob",
    "CameraView",
    "CameraLost",
    "ColorBlobDetector",
    "CubeLocalization",
    "CubeLocator",
    "CubePerception",
    "FrameSource",
    "FrankyBackend",
    "HSVRange",
    "ImageFolderCamera",
    "MarkerDetector",
    "MuJoCoTwinBackend",
    "OpenCVCamera",
    "ParallaxCorrection",
    "PerceptionStatus",
    "RealLoopEnv",
    "RobotBackend",
    "RobotState",
    "SafetyStatus",
    "ScriptedPickPlace",
    "TableCalibration",
    "TwinCamera",
    "TwinScene",
    "Workspace",
    "apply_homography",
    "aruco_dictionary",
    "aruco_dictionary_names",
    "check_frame",
    "draw_perception",
    "fit_homography",
    "render_table_scene",
]
