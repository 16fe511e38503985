"""Touch sensing shared by the Fetch and Franka tasks: pad sites with MuJoCo touch sensors, reported per step."""

from __future__ import annotations

import mujoco
import numpy as np

TOUCH_SENSORS: tuple[str, str] = ("robot0:left_touch", "robot0:right_touch")
PAD_RGBA = (0.1, 0.9, 0.2, 0.6)


def add_touch_pad(
    spec: mujoco.MjSpec,
    body_name: str,
    side: str,
    half_size: tuple[float, float, float],
    pos: tuple[float, float, float],
) -> None:
    """Adds a visible box site ``robot0:<side>_pad`` on ``body_name`` and a touch sensor ``robot0:<side>_touch`` on it.

    A touch sensor reports the summed normal force of the contacts inside its site's volume.

    Args:
        spec (mujoco.MjSpec): the model, not yet compiled.
        body_name (str): the body carrying the pad.
        side (str): ``"left"`` or ``"right"``: names the site and sensor.
        half_size (tuple of float): the box site's half-sizes.
        pos (tuple of float): the site's position in the body's frame.

    Example:
        >>> spec = mujoco.MjSpec()
        >>> _ = spec.worldbody.add_body(name="finger")
        >>> add_touch_pad(spec, "finger", "left", (0.01, 0.01, 0.01), (0, 0, 0))
        >>> spec.compile().nsensor
        1
    """
    site_name = f"robot0:{side}_pad"
    spec.body(body_name).add_site(
        name=site_name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(half_size),
        pos=list(pos),
        rgba=list(PAD_RGBA),
        group=0,  # rendered by default
    )
    spec.add_sensor(
        name=f"robot0:{side}_touch",
        type=mujoco.mjtSensor.mjSENS_TOUCH,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname=site_name,
    )


def add_table_blind_touch_pad(
    spec: mujoco.MjSpec,
    finger_body: str,
    side: str,
    half_size: tuple[float, float, float],
    pos: tuple[float, float, float],
    table_body: str = "table0",
) -> None:
    """Adds CPER's touch pad that never feels the table: a sensor body ``robot0:<side>_sensor`` on ``finger_body``.

    The sensor body (as heavy as a Fetch finger link, CPER's inertial) carries a copy of the finger's
    first geom, whose contacts with ``table_body`` are excluded, and the pad site and sensor of
    :func:`add_touch_pad`. A touch sensor only counts contacts of its own body's geoms, so the finger
    itself still stands on the table while the pad reads only the object and anything else.

    Args:
        spec (mujoco.MjSpec): the model, not yet compiled.
        finger_body (str): the finger link the sensor body hangs from.
        side (str): ``"left"`` or ``"right"``: names the body, site and sensor.
        half_size (tuple of float): the box site's half-sizes.
        pos (tuple of float): the site's position in the sensor body's frame.
        table_body (str, optional): the body whose contacts the pad never feels. Defaults to ``"table0"``.

    Example:
        >>> import os, gymnasium_robotics
        >>> path = os.path.join(os.path.dirname(gymnasium_robotics.__file__), "envs/assets/fetch/push.xml")
        >>> spec = mujoco.MjSpec.from_file(path)
        >>> add_table_blind_touch_pad(spec, "robot0:l_gripper_finger_link", "left", (0.037, 0.00795, 0.0145), (0.001, 0.00795, 0))
        >>> model = spec.compile()
        >>> model.nsensor, float(model.body("robot0:left_sensor").mass[0])
        (1, 4.0)
    """
    finger = spec.body(finger_body)
    pad_geom = finger.geoms[0]
    sensor_name = f"robot0:{side}_sensor"
    sensor_body = finger.add_body(name=sensor_name, mass=4.0, ipos=[-0.01, 0.0, 0.0], inertia=[0.1, 0.1, 0.1])
    sensor_body.add_geom(
        name=f"{sensor_name}_geom",
        type=pad_geom.type,
        size=list(pad_geom.size),
        pos=list(pad_geom.pos),
        condim=pad_geom.condim,
        friction=list(pad_geom.friction),
        margin=pad_geom.margin,
        solref=list(pad_geom.solref),
        solimp=list(pad_geom.solimp),
        rgba=[0.0, 0.0, 0.0, 0.0],  # the finger's own geom is the one drawn
    )
    spec.add_exclude(bodyname1=table_body, bodyname2=sensor_name)
    add_touch_pad(spec, sensor_name, side, half_size, pos)


class TouchReporting:
    """Mixin for a gymnasium-robotics MuJoCo env whose model has the two pad sensors of :func:`add_touch_pad`.

    ``touch`` (and ``info["touch"]``) holds ``[left, right]``: the mean over the physics substeps
    after a step (the env's ``_mujoco_step`` calls :meth:`substep_touch`), the reading at the
    reset state after a reset.

    The mixin takes no constructor arguments of its own: put it before the env class in the bases, and call
    :meth:`locate_touch_sensors` once the model is compiled.

    Attributes:
        touch (np.ndarray): ``[left, right]``, the touch of the last step or reset.

    Example:
        >>> from torchrl_cebp.envs import make_touch_fetch
        >>> env = make_touch_fetch("pick_place")  # a TouchReporting env
        >>> _, info = env.reset(seed=0)
        >>> info["touch"].tolist()  # the gripper starts in free air
        [0.0, 0.0]
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    n_substeps: int
    touch: np.ndarray

    def locate_touch_sensors(self) -> None:
        """Finds the sensors in the compiled model; call it once the model exists."""
        self._touch_adr = np.array(
            [self.model.sensor_adr[self.model.sensor(name).id] for name in TOUCH_SENSORS], dtype=np.int64
        )

    def substep_touch(self) -> np.ndarray:
        """The two sensors' current readings ``[left, right]`` (a view into ``data.sensordata``)."""
        return self.data.sensordata[self._touch_adr]

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """gymnasium's ``step``, with the step's touch in ``info["touch"]``.

        Args:
            action (np.ndarray): the env's action.
        """
        obs, reward, terminated, truncated, info = super().step(action)
        info["touch"] = self.touch.copy()
        return obs, reward, terminated, truncated, info

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """gymnasium's ``reset``, with the touch at the reset state in ``info["touch"]``.

        Args:
            seed (int, optional): reseeds the env's generator. Defaults to ``None``.
            options (dict, optional): gymnasium's reset options. Defaults to ``None``.
        """
        obs, info = super().reset(seed=seed, options=options)
        # mj_forward in _reset_sim has evaluated the sensors at the reset state.
        self.touch = self.substep_touch().copy()
        info["touch"] = self.touch.copy()
        return obs, info
