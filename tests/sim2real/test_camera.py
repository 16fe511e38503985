import cv2
import numpy as np
import pytest

from torchrl_cebp.sim2real import CameraLost, ImageFolderCamera, OpenCVCamera, check_frame


def write_frames(folder, names, size=(48, 64)):
    for value, name in enumerate(names):
        cv2.imwrite(str(folder / name), np.full((*size, 3), 10 * value, np.uint8))


def test_folder_replays_in_natural_order_then_loses_camera(tmp_path):
    # Written in value order 0, 10, 20 under names whose plain sort would be 1, 10, 2.
    write_frames(tmp_path, ["frame_1.png", "frame_2.png", "frame_10.png"])
    (tmp_path / "notes.txt").write_text("not an image")
    with ImageFolderCamera(tmp_path, expected_size=(48, 64)) as camera:
        assert [int(camera.read()[0, 0, 0]) for _ in range(3)] == [0, 10, 20]
        with pytest.raises(CameraLost):
            camera.read()


def test_folder_loops(tmp_path):
    write_frames(tmp_path, ["a.png", "b.png"])
    camera = ImageFolderCamera(tmp_path, loop=True)
    assert [int(camera.read()[0, 0, 0]) for _ in range(5)] == [0, 10, 0, 10, 0]


def test_folder_wrong_size_raises(tmp_path):
    write_frames(tmp_path, ["a.png"], size=(40, 64))
    with pytest.raises(ValueError, match=r"got shape \(40, 64, 3\), expected \(48, 64, 3\)"):
        ImageFolderCamera(tmp_path, expected_size=(48, 64)).read()


def test_folder_undecodable_image_is_camera_lost(tmp_path):
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(CameraLost, match="broken.png"):
        ImageFolderCamera(tmp_path).read()


def test_folder_without_images(tmp_path):
    with pytest.raises(FileNotFoundError, match="No images"):
        ImageFolderCamera(tmp_path)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        ImageFolderCamera(tmp_path / "missing")


@pytest.mark.parametrize(
    "frame, message",
    [
        (np.zeros((0, 0, 3), np.uint8), r"Empty camera frame: got shape \(0, 0, 3\), expected \(48, 64, 3\)"),
        (np.zeros((48, 64), np.uint8), r"got shape \(48, 64\) dtype uint8"),
        (np.zeros((48, 64, 3), np.float32), r"dtype float32"),
        (np.zeros((64, 48, 3), np.uint8), r"wrong size: got shape \(64, 48, 3\), expected \(48, 64, 3\)"),
    ],
)
def test_check_frame_rejects(frame, message):
    with pytest.raises(ValueError, match=message):
        check_frame(frame, expected_size=(48, 64))


def test_opencv_camera_on_video_file(tmp_path):
    path = str(tmp_path / "clip.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    for value in (40, 120, 200):
        writer.write(np.full((48, 64, 3), value, np.uint8))
    writer.release()
    with OpenCVCamera(path, expected_size=(48, 64)) as camera:
        # MJPG is lossy: the grey levels come back within a few units.
        np.testing.assert_allclose([camera.read().mean() for _ in range(3)], [40, 120, 200], atol=5)
        with pytest.raises(CameraLost):
            camera.read()
    with OpenCVCamera(path, expected_size=(64, 48)) as camera, pytest.raises(ValueError, match="wrong size"):
        camera.read()


def test_opencv_camera_closed_or_missing_is_camera_lost(tmp_path):
    path = str(tmp_path / "clip.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    writer.write(np.zeros((48, 64, 3), np.uint8))
    writer.release()
    camera = OpenCVCamera(path)
    camera.close()
    with pytest.raises(CameraLost):
        camera.read()
    with pytest.raises(CameraLost, match="Could not open"):
        OpenCVCamera(str(tmp_path / "missing.avi"))
