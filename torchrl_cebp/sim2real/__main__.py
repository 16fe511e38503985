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

import argparse
import sys
from collections.abc import Sequence
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
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


# One table of options; each command takes the ones it names. (flags, argparse keyword arguments)
_OPTIONS: dict[str, dict[str, Any]] = {
    "backend": {"choices": _BACKENDS, "default": "sim", "help": "sim: the MuJoCo twin; franky: a real Franka"},
    "policy": {"choices": ("checkpoint", "scripted"), "default": "checkpoint", "help": "what acts"},
    "checkpoint": {"default": "", "help": "a training run directory, its checkpoint.pt, or a policy file"},
    "episodes": {"type": int, "default": 5, "help": "episodes to run"},
    "seed": {"type": int, "default": 0, "help": "the twin's (and goals') seed"},
    "calibration": {"default": "", "help": "the table calibration file (calibrate writes it; the twin's by default)"},
    "host": {"default": "", "help": "the robot's address (backend=franky)"},
    "camera": {"type": int, "default": 0, "help": "the OpenCV camera device (backend=franky)"},
    "camera_position": {"type": _floats, "default": (), "help": "x,y,z of the camera (parallax of the cube's top face)"},
    "goal": {"type": _floats, "default": (), "help": "x,y,z of a fixed goal (default: drawn per episode)"},
    "out": {"required": True, "help": "where to write"},
    "steps": {"type": int, "default": 40, "help": "steps of the debug episode"},
    "ids": {"default": "0,1,2,3", "help": "the marker ids to jog to, comma-separated"},
    "frames": {"required": True, "help": "a folder of recorded frames"},
}
_LOOP = ("backend", "policy", "checkpoint", "seed", "calibration", "host", "camera", "camera_position", "goal")
_COMMANDS: dict[str, tuple[str, tuple[str, ...], dict[str, Any]]] = {
    "run": ("run a policy through camera, perception and robot", (*_LOOP, "episodes"), {}),
    "debug": ("one episode, every frame annotated with what the perception saw", (*_LOOP, "out", "steps"),
              {"policy": "scripted"}),
    "calibrate": ("write the table calibration (marker positions in the robot frame)", ("backend", "out", "host", "ids"),
                  {}),
    "perceive": ("camera only: recorded frames through the perception", ("frames", "out", "calibration"), {}),
}


def build_parser() -> argparse.ArgumentParser:
    """The command line: one subcommand per entry of ``_COMMANDS``, options from one table.

    Example:
        >>> build_parser().parse_args(["run", "--policy", "scripted"]).episodes
        5
    """
    parser = argparse.ArgumentParser(
        prog="python -m torchrl_cebp.sim2real",
        description=__doc__.split("\n\n")[0],
        epilog="Options are written key=value (as in the examples) or --key value.\n\n" + __doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (summary, options, defaults) in _COMMANDS.items():
        command = commands.add_parser(name, help=summary, description=summary)
        for option in options:
            command.add_argument(f"--{option.replace('_', '-')}", dest=option, **_OPTIONS[option])
        command.set_defaults(**defaults)
    return parser


def _as_flag(item: str) -> str:
    key, sep, value = item.partition("=")
    return f"--{key.replace('_', '-')}={value}" if sep and not item.startswith("-") else item


def parse_args(argv: Sequence[str]) -> tuple[str, dict[str, Any]]:
    """``COMMAND key=value ...`` (or ``--key value``) -> (command, options); exits with usage on a bad one.

    Example:
        >>> parse_args(["run", "policy=scripted", "episodes=2"])[1]["episodes"]
        2
        >>> parse_args(["run", "checkpoint=runs/franka_pick_place-standard/seed0"])[1]["checkpoint"]
        'runs/franka_pick_place-standard/seed0'
    """
    parser = build_parser()
    # key=value is the documented form; argparse reads it as --key=value.
    args = parser.parse_args([_as_flag(item) for item in argv])
    options = vars(args)
    command = options.pop("command")
    if options.get("policy") == "checkpoint" and not options["checkpoint"]:
        parser.error("give checkpoint=PATH (a training run directory or checkpoint.pt), or policy=scripted")
    if options.get("backend") == "franky" and not options["host"]:
        parser.error("backend=franky needs host=ROBOT_IP")
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
        frame = env.last_frame  # the frame behind the observation the policy acts on, not a second read
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
    """Entry point of ``python -m torchrl_cebp.sim2real`` (``--help`` on it and on every command)."""
    command, options = parse_args(sys.argv[1:] if argv is None else argv)
    torch.set_num_threads(1)
    try:
        {"run": run, "calibrate": calibrate, "debug": debug, "perceive": perceive}[command](options)
    except (FileNotFoundError, ValueError) as error:  # a missing checkpoint or calibration, a bad file
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
