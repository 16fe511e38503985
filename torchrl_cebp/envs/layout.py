"""Where each quantity sits in the Fetch observation vector: the one place that names its slices.

gymnasium-robotics' Fetch builds the 25-D observation in this order; the Franka task, the Sim2Real
loop and the samplers reuse it. With ``touch_in_observation`` (the released code's PickAndPlace and
Slide) two entries follow: the step's touch (left + right, mean over the substeps) and its running
episode sum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# (name, size) in the order of gymnasium-robotics' BaseFetchEnv._get_obs.
_FETCH_FIELDS: tuple[tuple[str, int], ...] = (
    ("gripper_position", 3),
    ("object_position", 3),
    ("object_relative_position", 3),  # object - gripper
    ("finger_positions", 2),  # their sum is the gripper opening
    ("object_rotation", 3),  # Euler angles
    ("object_velocity", 3),  # per step (velocity x dt), relative to the gripper
    ("object_angular_velocity", 3),  # per step
    ("gripper_velocity", 3),  # per step
    ("finger_velocities", 2),  # per step
)
_TOUCH_FIELDS: tuple[tuple[str, int], ...] = (("touch", 1), ("touch_total", 1))


@dataclass(frozen=True)
class ObservationLayout:
    """Named slices of a Fetch-style observation, with or without the two touch entries.

    Every field name is also an attribute giving its slice (``layout.gripper_position``).

    Args:
        with_touch (bool, optional): the layout ends with ``touch`` and ``touch_total`` (27 entries
            instead of 25). Defaults to ``False``.

    Example:
        >>> import numpy as np
        >>> layout = ObservationLayout(with_touch=True)
        >>> layout.size, layout.gripper_position, layout.touch
        (27, slice(0, 3, None), slice(25, 26, None))
        >>> obs = np.zeros(25); obs[layout.finger_positions] = 0.02
        >>> float(FETCH_OBSERVATION.gripper_opening(obs))
        0.04
    """

    with_touch: bool = False

    @property
    def fields(self) -> tuple[tuple[str, int], ...]:
        """``(name, size)`` of every field, in order."""
        return _FETCH_FIELDS + (_TOUCH_FIELDS if self.with_touch else ())

    @property
    def size(self) -> int:
        """The observation's length."""
        return sum(size for _, size in self.fields)

    def slice(self, name: str) -> slice:
        """The slice of field ``name``.

        Args:
            name (str): a field of :attr:`fields`.

        Raises:
            KeyError: an unknown field; the message lists the fields.

        Example:
            >>> FETCH_OBSERVATION.slice("object_position")
            slice(3, 6, None)
        """
        start = 0
        for field, size in self.fields:
            if field == name:
                return slice(start, start + size)
            start += size
        raise KeyError(f"no field {name!r} in this layout; fields: {[field for field, _ in self.fields]}")

    def __getattr__(self, name: str) -> slice:
        if name not in {field for field, _ in self.fields}:
            raise AttributeError(f"{type(self).__name__} has no field {name!r}; fields: {[f for f, _ in self.fields]}")
        return self.slice(name)

    def gripper_opening(self, observation):
        """Distance between the finger pads: the sum of the two finger positions.

        Args:
            observation (np.ndarray or torch.Tensor): ``[..., size]`` observations.

        Returns:
            ``[...]``: one opening per observation.
        """
        return observation[..., self.finger_positions].sum(-1)

    def pack(self, **fields: np.ndarray) -> np.ndarray:
        """The float32 observation from every field of the layout, by name.

        Args:
            **fields (np.ndarray): one array per field, of its size.

        Raises:
            ValueError: a field is missing or unknown.

        Example:
            >>> parts = {name: np.full(size, i) for i, (name, size) in enumerate(FETCH_OBSERVATION.fields)}
            >>> FETCH_OBSERVATION.pack(**parts)[FETCH_OBSERVATION.object_position].tolist()
            [1.0, 1.0, 1.0]
        """
        missing = [name for name, _ in self.fields if name not in fields]
        if missing or len(fields) != len(self.fields):
            raise ValueError(f"pack needs exactly the fields {[name for name, _ in self.fields]}; missing {missing}")
        return np.concatenate([np.asarray(fields[name], np.float64).reshape(size) for name, size in self.fields]).astype(
            np.float32
        )


FETCH_OBSERVATION = ObservationLayout()
