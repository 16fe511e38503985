import cv2
import numpy as np
import pytest
from sim2real_frames import DEGRADATIONS, FRAME_SIZE, degrade

from torchrl_cebp.sim2real import (
    ColorBlobDetector,
    CubeLocator,
    HSVRange,
    MarkerDetector,
    PerceptionStatus,
    TableCalibration,
    apply_homography,
    draw_perception,
    fit_homography,
    render_table_scene,
)

CUBE_SIZE = 0.05
# Spread over the workspace, clear of the markers' white borders.
CUBE_POSITIONS = [(0.5, 0.0), (0.42, -0.18), (0.6, 0.17), (0.36, 0.2), (0.63, -0.2)]
# Two viewpoints: oblique from the robot's side of the table, and rotated, from a corner.
VIEWS = {
    "oblique": None,
    "corner": np.array([[420, 40], [620, 260], [300, 470], [30, 180]], np.float32),
}
TOLERANCE = 0.01  # metres


@pytest.mark.parametrize("view", VIEWS)
@pytest.mark.parametrize("condition", DEGRADATIONS)
def test_cube_position_within_a_centimetre(calibration, condition, view):
    locator = CubeLocator(calibration, cube_size=CUBE_SIZE)
    for yaw, cube_xy in enumerate(CUBE_POSITIONS):
        frame = render_table_scene(
            calibration, cube_xy, cube_size=CUBE_SIZE, cube_yaw=0.3 * yaw, table_corners_px=VIEWS[view]
        )
        result = locator.locate(degrade(frame, condition))
        assert result.reason == "ok", (cube_xy, result.missing_markers)
        error = np.linalg.norm(result.position[:2] - cube_xy)
        assert error < TOLERANCE, (cube_xy, result.position)
        assert result.position[2] == pytest.approx(calibration.table_height + CUBE_SIZE / 2)
        assert result.position.dtype == np.float32


def test_covered_marker_fails_with_markers(calibration):
    frame = render_table_scene(calibration, (0.5, 0.0), occluded_markers=[2])
    result = CubeLocator(calibration).locate(degrade(frame, "noise"))
    assert (result.ok, result.reason, result.missing_markers) == (False, "markers", (2,))
    assert np.isnan(result.position).all()
    # The cube is still reported for the debug drawing, just not trusted.
    assert result.blob is not None and result.homography is None


def test_hidden_marker_keeps_the_homography_of_an_unmoved_camera(calibration):
    locator = CubeLocator(calibration)
    assert locator.locate(render_table_scene(calibration, (0.5, 0.0))).ok
    frame = render_table_scene(calibration, (0.42, -0.18), occluded_markers=[2])
    result = locator.locate(degrade(frame, "noise"))
    assert (result.ok, result.homography_kept, result.missing_markers) == (True, True, (2,))
    assert np.linalg.norm(result.position[:2] - (0.42, -0.18)) < TOLERANCE
    assert (draw_perception(frame, result) != frame).any()


@pytest.mark.parametrize(
    "locator_options, view",
    [({}, "corner"), ({"min_markers_to_confirm": 4}, "oblique"), ({"camera_moved_px": None}, "oblique")],
    ids=["camera moved", "too few to confirm", "never kept"],
)
def test_hidden_marker_fails_unless_the_camera_is_confirmed_unmoved(calibration, locator_options, view):
    locator = CubeLocator(calibration, **locator_options)
    assert locator.locate(render_table_scene(calibration, (0.5, 0.0))).ok
    frame = render_table_scene(calibration, (0.5, 0.0), occluded_markers=[2], table_corners_px=VIEWS[view])
    result = locator.locate(frame)
    assert (result.ok, result.reason, result.homography_kept) == (False, "markers", False)
    assert result.homography is None and np.isnan(result.position).all()


def test_no_cube_fails_with_cube(calibration):
    frame = render_table_scene(calibration, None)
    result = CubeLocator(calibration).locate(degrade(frame, "all"))
    assert (result.ok, result.reason, result.status) == (False, "cube", PerceptionStatus.CUBE)
    assert np.isnan(result.position).all() and result.homography is not None


def test_red_speck_below_min_area_is_no_cube(calibration):
    frame = render_table_scene(calibration, (0.5, 0.0), cube_size=0.006)
    assert CubeLocator(calibration).locate(frame).reason == "cube"


def test_fifth_marker_tolerates_one_covered_and_ignores_foreign_ids(calibration):
    five = TableCalibration({**calibration.marker_positions, 4: (0.5, 0.32)}, table_height=calibration.table_height)
    # Marker 9 is in view but in no calibration: it must not disturb anything.
    scene = TableCalibration({**five.marker_positions, 9: (0.5, -0.33)})
    frame = render_table_scene(scene, (0.45, 0.1), occluded_markers=[1])
    result = CubeLocator(five).locate(frame)
    assert result.reason == "ok" and result.missing_markers == (1,)
    assert set(result.marker_centres) == {0, 2, 3, 4}
    assert np.linalg.norm(result.position[:2] - (0.45, 0.1)) < TOLERANCE


def test_marker_detector_reports_only_configured_ids(calibration):
    frame = render_table_scene(calibration, None)
    assert set(MarkerDetector("DICT_4X4_50").detect(frame)) == {0, 1, 2, 3}
    assert set(MarkerDetector("DICT_4X4_50", ids=[1, 3, 42]).detect(frame)) == {1, 3}
    # Markers of another dictionary are not found.
    assert MarkerDetector("DICT_6X6_50").detect(frame) == {}
    with pytest.raises(ValueError, match="Unknown ArUco dictionary"):
        MarkerDetector("DICT_4X4")


def test_fit_homography_four_and_least_squares():
    truth = np.array([[0.002, 0.0001, 0.1], [-0.0003, 0.0015, -0.2], [1e-5, 2e-6, 1.0]])
    pixels = np.array([[10, 20], [600, 30], [620, 460], [15, 450], [300, 240], [100, 400]], np.float64)
    robot = apply_homography(truth, pixels)
    for n in (4, 6):
        np.testing.assert_allclose(apply_homography(fit_homography(pixels[:n], robot[:n]), pixels), robot, atol=1e-5)
    with pytest.raises(ValueError, match="at least 4"):
        fit_homography(pixels[:3], robot[:3])


@pytest.mark.parametrize("hue", [2, 176])
def test_red_on_both_sides_of_hue_zero(hue):
    frame = np.full((60, 60, 3), 180, np.uint8)
    frame[20:40, 10:30] = cv2.cvtColor(np.array([[[hue, 230, 200]]], np.uint8), cv2.COLOR_HSV2BGR)
    blob = ColorBlobDetector(min_area=50).detect(frame)
    np.testing.assert_allclose(blob.centre, (19.5, 29.5), atol=0.5)


def test_blob_ranges_are_configurable():
    frame = np.full((60, 60, 3), 180, np.uint8)
    frame[10:30, 30:50] = (0, 200, 0)  # green
    assert ColorBlobDetector().detect(frame) is None
    green = ColorBlobDetector([HSVRange((50, 100, 50), (70, 255, 255))], min_area=50)
    np.testing.assert_allclose(green.detect(frame).centre, (39.5, 19.5), atol=0.5)
    assert ColorBlobDetector([HSVRange((50, 100, 50), (70, 255, 255))], min_area=500).detect(frame) is None


@pytest.mark.parametrize("cube_xy, occluded", [((0.5, 0.0), ()), ((0.5, 0.0), (3,)), (None, ())])
def test_debug_frame_written_to_disk(tmp_path, calibration, cube_xy, occluded):
    frame = render_table_scene(calibration, cube_xy, occluded_markers=occluded)
    debug = draw_perception(frame, CubeLocator(calibration).locate(frame))
    path = tmp_path / "debug.png"
    assert cv2.imwrite(str(path), debug)
    written = cv2.imread(str(path))
    assert written.shape == (*FRAME_SIZE, 3) and (written != frame).any()
    assert (frame == render_table_scene(calibration, cube_xy, occluded_markers=occluded)).all()
