"""Camera frame sources for the Sim2Real pipeline.

Every source returns OpenCV-style frames (``H x W x 3``, ``uint8``, BGR) from :meth:`FrameSource.read`
and reports a vanished camera with :class:`CameraLost`, so a control loop has one exception to catch
before it stops the robot.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np

__all__ = ["CameraLost", "FrameSource", "ImageFolderCamera", "OpenCVCamera", "check_frame"]


class CameraLost(RuntimeError):
    """The camera stopped delivering frames (unplugged, stream dropped, recording exhausted).

    Example:
        >>> import cv2, numpy as np, tempfile, os
        >>> folder = tempfile.mkdtemp()
        >>> _ = cv2.imwrite(os.path.join(folder, "frame_0.png"), np.zeros((4, 6, 3), np.uint8))
        >>> camera = ImageFolderCamera(folder)
        >>> _ = camera.read()
        >>> try:
        ...     camera.read()
        ... except CameraLost as lost:
        ...     print(str(lost).endswith("delivered no frame."))
        True
    """


def check_frame(frame: np.ndarray, expected_size: tuple[int, int] | None = None) -> np.ndarray:
    """Checks that ``frame`` is a non-empty ``H x W x 3`` ``uint8`` image, of ``expected_size=(H, W)`` if given.

    Args:
        frame (np.ndarray): the image.
        expected_size (tuple of int, optional): ``(height, width)``; ``None`` accepts any size.
            Defaults to ``None``.

    Returns:
        ``frame`` itself.

    Raises:
        ValueError: naming the shape (and dtype) that was got and the one that was expected.

    Examples:
        >>> import numpy as np
        >>> check_frame(np.zeros((480, 640, 3), np.uint8), expected_size=(480, 640)).shape
        (480, 640, 3)
    """
    expected = "(H, W, 3)" if expected_size is None else str((*expected_size, 3))
    if frame.size == 0:
        raise ValueError(f"Empty camera frame: got shape {frame.shape}, expected {expected}.")
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
        raise ValueError(
            f"Camera frame must be uint8 {expected}: got shape {frame.shape} dtype {frame.dtype}."
        )
    if expected_size is not None and frame.shape[:2] != tuple(expected_size):
        raise ValueError(f"Camera frame has the wrong size: got shape {frame.shape}, expected {expected}.")
    return frame


class FrameSource(ABC):
    """A camera: :meth:`read` returns the next checked BGR frame, :meth:`close` releases the device.

    Subclasses implement :meth:`_grab`, returning ``None`` when no frame can be had.

    Args:
        expected_size (tuple of int, optional): ``(height, width)`` every frame must have; ``None`` accepts
            any size. Defaults to ``None``.

    Example:
        >>> import numpy as np
        >>> class Grey(FrameSource):
        ...     def _grab(self):
        ...         return np.full((4, 6, 3), 128, np.uint8)
        >>> with Grey(expected_size=(4, 6)) as camera:
        ...     camera.read().shape
        (4, 6, 3)
    """

    def __init__(self, expected_size: tuple[int, int] | None = None) -> None:
        self.expected_size = None if expected_size is None else tuple(expected_size)

    @abstractmethod
    def _grab(self) -> np.ndarray | None: ...

    def read(self) -> np.ndarray:
        """Returns the next frame (``H x W x 3`` uint8 BGR).

        Raises:
            CameraLost: there is no frame.
            ValueError: the frame is not of the expected size or type.
        """
        frame = self._grab()
        if frame is None:
            raise CameraLost(f"{self!r} delivered no frame.")
        return check_frame(frame, self.expected_size)

    def close(self) -> None:
        """Releases the underlying device; the default has nothing to release."""

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class OpenCVCamera(FrameSource):
    """A ``cv2.VideoCapture`` source: a device index, a video file or a stream URL.

    Args:
        source (int, str or Path): device index (``0`` is the first webcam), video file path or stream URL.
        expected_size (tuple of int, optional): ``(height, width)`` every frame must have; ``None`` accepts
            any size. Defaults to ``None``.
        api_preference (int, optional): OpenCV capture backend, e.g. ``cv2.CAP_V4L2``. Defaults to
            ``cv2.CAP_ANY`` (OpenCV chooses).

    Raises:
        CameraLost: if the source cannot be opened.

    Examples:
        >>> import cv2, numpy as np, tempfile, os
        >>> path = os.path.join(tempfile.mkdtemp(), "clip.avi")
        >>> writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
        >>> _ = writer.write(np.zeros((48, 64, 3), np.uint8)); writer.release()
        >>> with OpenCVCamera(path, expected_size=(48, 64)) as camera:
        ...     camera.read().shape
        (48, 64, 3)
    """

    def __init__(
        self,
        source: int | str | Path,
        expected_size: tuple[int, int] | None = None,
        api_preference: int = cv2.CAP_ANY,
    ) -> None:
        super().__init__(expected_size)
        self.source = source if isinstance(source, int) else str(source)
        self._capture = cv2.VideoCapture(self.source, api_preference)
        if not self._capture.isOpened():
            raise CameraLost(f"Could not open camera source {self.source!r}.")

    def _grab(self) -> np.ndarray | None:
        ok, frame = self._capture.read()
        return frame if ok else None

    def close(self) -> None:
        """Releases the capture."""
        self._capture.release()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(source={self.source!r})"


def _natural_key(path: Path) -> list[int | str]:
    # "frame_2.png" must come before "frame_10.png" even when the recorder did not zero-pad.
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.name)]


class ImageFolderCamera(FrameSource):
    """Replays the images of a folder in natural name order, for a camera-only debug mode.

    Args:
        folder (str or Path): folder of recorded frames.
        expected_size (tuple of int, optional): ``(height, width)`` every frame must have; ``None`` accepts
            any size. Defaults to ``None``.
        loop (bool, optional): start again at the first image after the last instead of raising
            :class:`CameraLost`. Defaults to ``False``.
        extensions (tuple of str, optional): file name endings (lower case) that count as images.
            Defaults to ``(".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")``.

    Raises:
        FileNotFoundError: the folder does not exist or holds no images.

    Examples:
        >>> import cv2, numpy as np, tempfile, os
        >>> folder = tempfile.mkdtemp()
        >>> for i in (1, 2, 10):
        ...     _ = cv2.imwrite(os.path.join(folder, f"frame_{i}.png"), np.full((4, 6, 3), i, np.uint8))
        >>> camera = ImageFolderCamera(folder)
        >>> [int(camera.read()[0, 0, 0]) for _ in range(3)]
        [1, 2, 10]
    """

    def __init__(
        self,
        folder: str | Path,
        expected_size: tuple[int, int] | None = None,
        loop: bool = False,
        extensions: tuple[str, ...] = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"),
    ) -> None:
        super().__init__(expected_size)
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise FileNotFoundError(f"Image folder {str(self.folder)!r} does not exist.")
        self.paths = sorted(
            (p for p in self.folder.iterdir() if p.suffix.lower() in extensions), key=_natural_key
        )
        if not self.paths:
            raise FileNotFoundError(f"No images with endings {extensions} in {str(self.folder)!r}.")
        self.loop = loop
        self._next = 0

    def _grab(self) -> np.ndarray | None:
        if self._next == len(self.paths):
            if not self.loop:
                return None
            self._next = 0
        path = self.paths[self._next]
        self._next += 1
        frame = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if frame is None:
            raise CameraLost(f"Could not decode recorded frame {str(path)!r}.")
        return frame

    def __repr__(self) -> str:
        return f"{type(self).__name__}(folder={str(self.folder)!r}, loop={self.loop})"
