"""Table calibration: where the ArUco markers lie in the robot frame.

The marker positions are measured once by moving the end effector onto each marker centre; the
perception then maps pixels to the table plane through the homography those points define.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np
import yaml

__all__ = ["TableCalibration", "aruco_dictionary", "aruco_dictionary_names"]

# Below this quadrilateral area (m^2) the markers are (nearly) collinear and no homography exists.
_MIN_WORKSPACE_AREA = 1e-4


def aruco_dictionary_names() -> list[str]:
    """The predefined ArUco dictionary names of this OpenCV build, e.g. ``"DICT_4X4_50"``.

    Example:
        >>> "DICT_4X4_50" in aruco_dictionary_names()
        True
    """
    return sorted(name for name in dir(cv2.aruco) if name.startswith("DICT_"))


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """The predefined ArUco dictionary called ``name``.

    Args:
        name (str): one of :func:`aruco_dictionary_names`.

    Raises:
        ValueError: an unknown name; the message lists the valid ones.

    Example:
        >>> aruco_dictionary("DICT_4X4_50").bytesList.shape[0]
        50
    """
    valid = aruco_dictionary_names()
    if name not in valid:
        raise ValueError(f"Unknown ArUco dictionary {name!r}; valid names: {', '.join(valid)}.")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


@dataclass(frozen=True)
class TableCalibration:
    """Robot-frame positions of the table markers, saved as YAML or JSON.

    Args:
        marker_positions (dict): marker id -> robot-frame ``(x, y)`` of the marker centre, in metres; at least 4.
        aruco_dictionary (str, optional): name of the predefined ArUco dictionary the markers were printed from.
            Defaults to ``"DICT_4X4_50"``.
        table_height (float, optional): robot-frame ``z`` of the table surface, in metres. Defaults to ``0.0``.

    Raises:
        ValueError: fewer than 4 markers, an unknown dictionary name (the valid ones are listed),
            non-finite values, or markers that span no area.

    Examples:
        >>> import tempfile, os
        >>> calibration = TableCalibration(
        ...     marker_positions={0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)},
        ...     aruco_dictionary="DICT_4X4_50",
        ...     table_height=0.0,
        ... )
        >>> path = os.path.join(tempfile.mkdtemp(), "table.yaml")
        >>> calibration.save(path)
        >>> TableCalibration.load(path) == calibration
        True
    """

    marker_positions: dict[int, tuple[float, float]]
    aruco_dictionary: str = "DICT_4X4_50"
    table_height: float = 0.0

    def __post_init__(self) -> None:
        # Normalise types so that a calibration read from JSON (string keys, lists) compares equal.
        positions = {int(k): (float(v[0]), float(v[1])) for k, v in self.marker_positions.items()}
        object.__setattr__(self, "marker_positions", positions)
        object.__setattr__(self, "table_height", float(self.table_height))
        if len(positions) < 4:
            raise ValueError(
                f"A calibration needs at least 4 markers for a homography, got {len(positions)}: "
                f"ids {sorted(positions)}."
            )
        aruco_dictionary(self.aruco_dictionary)
        points = self.robot_points()
        if not (np.isfinite(points).all() and np.isfinite(self.table_height)):
            raise ValueError(f"Calibration values must be finite: {positions}, table_height={self.table_height}.")
        area = cv2.contourArea(cv2.convexHull(points))
        if area < _MIN_WORKSPACE_AREA:
            raise ValueError(
                f"The marker positions span {area:.2e} m^2 (< {_MIN_WORKSPACE_AREA:g}): they are (nearly) "
                f"collinear and define no homography: {positions}."
            )

    @property
    def marker_ids(self) -> list[int]:
        """The calibrated marker ids, sorted."""
        return sorted(self.marker_positions)

    def robot_points(self, ids: list[int] | None = None) -> np.ndarray:
        """Robot-frame ``(x, y)`` of the markers ``ids`` as a float32 ``[N, 2]`` array.

        Args:
            ids (list of int, optional): the markers, in the order wanted; ``None`` is all of them, sorted.
                Defaults to ``None``.
        """
        ids = self.marker_ids if ids is None else ids
        return np.array([self.marker_positions[i] for i in ids], dtype=np.float32)

    def to_dict(self) -> dict[str, Any]:
        """A plain ``dict`` (lists, not tuples) ready for YAML or JSON."""
        data = asdict(self)
        data["marker_positions"] = {i: list(xy) for i, xy in sorted(self.marker_positions.items())}
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TableCalibration:
        """Builds a calibration from :meth:`to_dict`'s layout.

        Args:
            data (dict): the fields of :meth:`to_dict`.

        Raises:
            ValueError: an unknown field (not ignored), or an invalid calibration.
        """
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"Unknown calibration fields {unknown}; expected {sorted(known)}.")
        return cls(**data)

    def save(self, path: str | Path) -> None:
        """Writes the calibration as YAML or JSON.

        Args:
            path (str or Path): ends in ``.yaml``, ``.yml`` or ``.json``.

        Raises:
            ValueError: another ending.
        """
        path = Path(path)
        dump, _ = _format(path)
        path.write_text(dump(self.to_dict()))

    @classmethod
    def load(cls, path: str | Path) -> TableCalibration:
        """Reads a calibration written by :meth:`save` (or by hand in the same layout).

        Args:
            path (str or Path): a ``.yaml``, ``.yml`` or ``.json`` file.

        Raises:
            ValueError: another ending, a file without a mapping, or an invalid calibration.
        """
        path = Path(path)
        _, parse = _format(path)
        data = parse(path.read_text())
        if not isinstance(data, dict):
            raise ValueError(f"{str(path)!r} does not hold a calibration mapping.")
        return cls.from_dict(data)


# PyYAML comes with hydra-core (through omegaconf), a core dependency.
_FORMATS: dict[str, tuple[Callable[[dict[str, Any]], str], Callable[[str], Any]]] = {
    ".json": (lambda data: json.dumps(data, indent=2), json.loads),
    ".yaml": (lambda data: yaml.safe_dump(data, sort_keys=False), yaml.safe_load),
    ".yml": (lambda data: yaml.safe_dump(data, sort_keys=False), yaml.safe_load),
}


def _format(path: Path) -> tuple[Callable[[dict[str, Any]], str], Callable[[str], Any]]:
    try:
        return _FORMATS[path.suffix.lower()]
    except KeyError:
        raise ValueError(f"Calibration files end in {sorted(_FORMATS)}, got {str(path)!r}.") from None
