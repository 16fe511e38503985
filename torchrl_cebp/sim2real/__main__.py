"""Sim2Real commands: run a policy through camera -> perception -> robot, calibrate the table, write debug frames.

    python -m torchrl_cebp.sim2real run policy=scripted backend=sim episodes=5
    python -m torchrl_cebp.sim2real run checkpoint=runs/.../seed0 backend=sim episodes=20
    python -m torchrl_cebp.sim2real calibrate backend=sim out=table.yaml
    python -m torchrl_cebp.sim2real calibrate backend=franky host=172.16.0.2 out=table.yaml
    python -m torchrl_cebp.sim2real debug out=debug_frames steps=40
    python -m torchrl_cebp.sim2real perceive frames=debug_frames/raw out=annotated/   # camera only (calibration=FILE)

On hardware (``backend=franky``) ``calibration=`` names the file ``calibrate`` wrote and ``camera=`` the
OpenCV device (default 0).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import step_mdp

from torchrl_cebp.sim2real.calibration import TableCalibration
from torchrl_cebp.sim2real.camera import CameraLost, FrameSource, ImageFolderCamera, OpenCVCamera
from torchrl_cebp.sim2real.perception import CubeLocator, CubePerception, draw_perception
from torchrl_cebp.sim2real.policy import ScriptedPickPlace
from torchrl_cebp.sim2real.real_loop import ParallaxCorrection, RealLoopEnv, SafetyStatus
from torchrl_cebp.sim2real.robot import FrankyBackend, RobotBackend
from torchrl_cebp.training import load_policy

_BACKENDS = ("sim", "franky")


def _floats(text: str) -> tuple[float, ...]:
    return tuple(float(v) for v in text.split(","))


# Per command: key -> (converter, default). None as default means required.
_COMMANDS: dict[str, dict[str, tuple[Callable[[str], Any], Any]]] = {
    "run": {
        "backend": (str, "sim"), "policy": (str, "checkpoint"), "checkpoint": (str, ""), "episodes": (int, 5),
        "seed": (int, 0), "calibration": (str, ""), "host": (str, ""), "camera": (int, 0),
        "camera_position": (_floats, ()), "goal": (_floats, ()),
    },
    "calibrate": {"backend": (str, "sim"), "out": (str, None), "host": (str, ""), "ids": (str, "0,1,2,3")},
    "debug": {
        "backend": (str, "sim"), "out": (str, None), "steps": (int, 40), "policy": (str, "scripted"),
        "checkpoint": (str, ""), "seed": (int, 0), "calibration": (str, ""), "host": (str, ""), "camera": (int, 0),
        "camera_position": (_floats, ()), "goal": (_floats, ()),
    },
    # Camera only: recorded frames through the perception, no robot (calibration defaults to the twin's).
    "perceive": {"frames": (str, None), "out": (str, None), "calibration": (str, "")},
}


def parse_args(argv: Sequence[str]) -> tuple[str, dict[str, Any]]:
    """``COMMAND key=value ...`` -> (command, options with defaults filled); ``ValueError`` naming what is wrong.

    Example:
        >>> parse_args(["run", "policy=scripted", "episodes=2"])[1]["episodes"]
        2
    """
    if not argv or argv[0] not in _COMMANDS:
        raise ValueError(f"Expected a command ({', '.join(_COMMANDS)}), got {argv[0] if argv else 'nothing'!r}.")
    command, schema = argv[0], _COMMANDS[argv[0]]
    options: dict[str, Any] = {}
    for item in argv[1:]:
        key, sep, text = item.partition("=")
        if not sep:
            raise ValueError(f"Arguments are key=value, got {item!r}.")
        if key not in schema:
            raise ValueError(f"Unknown option {key!r} for {command}; valid: {', '.join(schema)}.")
        try:
            options[key] = schema[key][0](text)
        except ValueError:
            raise ValueError(f"Bad value for {key}: {text!r}.") from None
    for key, (_, default) in schema.items():
        if key not in options:
            if default is None:
                raise ValueError(f"{command} needs {key}=...")
            options[key] = default
    if options.get("backend", "sim") not in _BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(_BACKENDS)}, got {options['backend']!r}.")
    if options.get("policy", "scripted") not in ("scripted", "checkpoint"):
        raise ValueError(f"policy must be 'scripted' or 'checkpoint', got {options['policy']!r}.")
    if options.get("policy") == "checkpoint" and not options["checkpoint"]:
        raise ValueError("Give checkpoint=PATH (a training run directory or checkpoint.pt), or policy=scripted.")
    if options.get("backend") == "franky" and not options["host"]:
        raise ValueError("backend=franky needs host=ROBOT_IP.")
    return command, options


def build_loop(options: dict[str, Any]) -> tuple[RealLoopEnv, RobotBackend, FrameSource]:
    """The backend, camera and :class:`RealLoopEnv` an options dict describes (``sim``: the MuJoCo twin)."""
    goal = np.asarray(options["goal"]) if options["goal"] else None
    if options["backend"] == "sim":
        from torchrl_cebp.sim2real.twin import MuJoCoTwinBackend, TwinCamera

        backend = MuJoCoTwinBackend(seed=options["seed"])
        camera: FrameSource = TwinCamera(backend)
        calibration = backend.calibration
        camera_position = options["camera_position"] or tuple(backend.scene.camera_pos)
    else:
        if not options["calibration"]:
            raise ValueError("backend=franky needs calibration=FILE (write one with the calibrate command).")
        backend = FrankyBackend(options["host"])
        camera = OpenCVCamera(options["camera"])
        calibration = TableCalibration.load(options["calibration"])
        camera_position = options["camera_position"]
    locator = CubeLocator(calibration)
    parallax = (
        ParallaxCorrection(camera_position, locator.cube_size / 2, calibration.table_height) if camera_position else None
    )
    env = RealLoopEnv(backend, camera, CubePerception(locator), parallax=parallax, goal=goal)
    env.set_seed(options["seed"])
    return env, backend, camera


def _policy(options: dict[str, Any]) -> TensorDictModuleBase:
    return ScriptedPickPlace() if options["policy"] == "scripted" else load_policy(options["checkpoint"])


@torch.no_grad()
def run(options: dict[str, Any]) -> float:
    """Runs ``episodes`` episodes; prints each one's outcome and returns the success rate."""
    env, backend, camera = build_loop(options)
    policy = _policy(options)
    successes = 0
    for episode in range(options["episodes"]):
        td = env.rollout(env.max_episode_steps, policy, break_when_any_done=True)
        last = td["next"][-1]
        success = bool(last["is_success"])
        successes += success
        reasons = {SafetyStatus(int(s)).reason for s in td["next", "safety_status"].flatten()} - {"ok"}
        line = f"episode {episode}: success={success} steps={td.shape[0]} holds/stops={sorted(reasons) or 'none'}"
        if hasattr(backend, "cube_position"):
            error = np.linalg.norm(backend.cube_position() - td["desired_goal"][-1].numpy())
            line += f" true_goal_distance={error:.3f} m"
        print(line)
    camera.close()
    rate = successes / max(options["episodes"], 1)
    print(f"success rate {rate:.2f} over {options['episodes']} episodes")
    return rate


def calibrate(options: dict[str, Any]) -> TableCalibration:
    """Writes the calibration file: read off the twin's model, or measured by jogging the real arm to each marker."""
    if options["backend"] == "sim":
        from torchrl_cebp.sim2real.twin import MuJoCoTwinBackend

        calibration = MuJoCoTwinBackend().calibration
    else:
        backend = FrankyBackend(options["host"])
        positions = {}
        for marker_id in (int(i) for i in options["ids"].split(",")):
            input(f"Jog the end effector (guiding mode) onto the centre of marker {marker_id}, then press Enter: ")
            positions[marker_id] = tuple(backend.state().grip_pos[:2])
        table_height = float(backend.state().grip_pos[2])
        calibration = TableCalibration(positions, table_height=table_height)
    calibration.save(options["out"])
    print(f"wrote {options['out']}: {calibration.marker_positions}")
    return calibration


@torch.no_grad()
def debug(options: dict[str, Any]) -> list[Path]:
    """Runs one episode and writes each camera frame, annotated with what the perception saw, to ``out``.

    The frames as the camera gave them go to ``out/raw`` (replay them with the ``perceive`` command).
    """
    env, _, camera = build_loop(options)
    policy = _policy(options)
    locator = env.perception.locator
    out = Path(options["out"])
    (out / "raw").mkdir(parents=True, exist_ok=True)
    written = []
    td = env.reset()
    for step in range(options["steps"]):
        frame = camera.read()
        path = out / f"frame_{step:04d}.png"
        cv2.imwrite(str(out / "raw" / path.name), frame)
        cv2.imwrite(str(path), draw_perception(frame, locator.locate(frame)))
        written.append(path)
        td = env.step(policy(td))
        if bool(td["next", "done"]):
            break
        td = step_mdp(td)
    camera.close()
    print(f"wrote {len(written)} annotated frames to {out}")
    return written


def perceive(options: dict[str, Any]) -> list[Path]:
    """Camera-only debugging: runs the perception on a folder of recorded frames and writes them annotated."""
    if options["calibration"]:
        calibration = TableCalibration.load(options["calibration"])
    else:
        from torchrl_cebp.sim2real.twin import TWIN_CALIBRATION

        calibration = TWIN_CALIBRATION
    locator = CubeLocator(calibration)
    out = Path(options["out"])
    out.mkdir(parents=True, exist_ok=True)
    written = []
    with ImageFolderCamera(options["frames"]) as camera:
        while True:
            try:
                frame = camera.read()
            except CameraLost:
                break
            found = locator.locate(frame)
            path = out / f"frame_{len(written):04d}.png"
            cv2.imwrite(str(path), draw_perception(frame, found))
            written.append(path)
            where = np.round(found.position, 4).tolist() if found.ok else "-"
            print(f"{path.name}: {found.reason}, cube at {where}")
    print(f"wrote {len(written)} annotated frames to {out}")
    return written


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m torchrl_cebp.sim2real``."""
    try:
        command, options = parse_args(sys.argv[1:] if argv is None else argv)
    except ValueError as error:
        print(f"error: {error}\n\n{__doc__}", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    try:
        {"run": run, "calibrate": calibrate, "debug": debug, "perceive": perceive}[command](options)
    except (FileNotFoundError, ValueError) as error:  # a missing checkpoint or calibration, a bad file
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
