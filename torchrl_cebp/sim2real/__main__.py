"""Sim2Real commands: run a policy through camera -> perception -> robot, calibrate the table, write debug frames.

    python -m torchrl_cebp.sim2real run backend=sim episodes=50 compare_sim=true   # the shipped policy, beside plain simulation
    python -m torchrl_cebp.sim2real run backend=sim episodes=50 side_camera=true   # a second camera beside the table
    python -m torchrl_cebp.sim2real run policy=scripted backend=sim episodes=5
    python -m torchrl_cebp.sim2real run checkpoint=runs/.../seed0 backend=sim episodes=20   # a policy you trained
    python -m torchrl_cebp.sim2real calibrate backend=sim out=table.yaml
    python -m torchrl_cebp.sim2real calibrate backend=franky host=172.16.0.2 out=table.yaml
    python -m torchrl_cebp.sim2real debug out=debug_frames steps=40 video=episode.mp4
    python -m torchrl_cebp.sim2real perceive frames=debug_frames/raw out=annotated/   # camera only (calibration=FILE)

On hardware (``backend=franky``) ``calibration=`` names the file ``calibrate`` wrote and ``camera=`` the
OpenCV device (default 0); ``side_camera=true`` adds ``side_camera_device=`` at ``side_camera_position=``.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import step_mdp

import torchrl_cebp
from torchrl_cebp.sim2real.calibration import TableCalibration
from torchrl_cebp.sim2real.camera import CameraLost, FrameSource, ImageFolderCamera, OpenCVCamera
from torchrl_cebp.sim2real.perception import CubeLocator, PerceptionStatus, draw_perception
from torchrl_cebp.sim2real.policy import SHIPPED_POLICY, ScriptedPickPlace
from torchrl_cebp.sim2real.real_loop import CameraView, RealLoopEnv, SafetyStatus
from torchrl_cebp.sim2real.robot import FrankyBackend, RobotBackend
from torchrl_cebp.evaluate import video_path, write_video
from torchrl_cebp.training import load_policy

_BACKENDS = ("sim", "franky")


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _boolean(text: str) -> bool:
    if text.lower() in ("true", "1", "yes"):
        return True
    if text.lower() in ("false", "0", "no"):
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


# One table of options; each command takes the ones it names. (flags, argparse keyword arguments)
_OPTIONS: dict[str, dict[str, Any]] = {
    "backend": {"choices": _BACKENDS, "default": "sim", "help": "sim: the MuJoCo twin; franky: a real Franka"},
    "policy": {"choices": ("checkpoint", "scripted"), "default": "checkpoint", "help": "what acts"},
    "checkpoint": {"default": str(SHIPPED_POLICY),
                   "help": "a training run directory, its checkpoint.pt, or a policy file (default: the shipped policy)"},
    "episodes": {"type": int, "default": 5, "help": "episodes to run"},
    "compare_sim": {"type": _boolean, "default": False, "metavar": "BOOL",
                    "help": "also run each episode in plain simulation (true state, no camera) on the same cube and goal"},
    "video": {"default": "", "help": "also write the annotated frames as this MP4 file"},
    "seed": {"type": int, "default": 0, "help": "the twin's (and goals') seed"},
    "calibration": {"default": "", "help": "the table calibration file (calibrate writes it; the twin's by default)"},
    "host": {"default": "", "help": "the robot's address (backend=franky)"},
    "camera": {"type": int, "default": 0, "help": "the OpenCV camera device (backend=franky)"},
    "camera_position": {"type": _floats, "default": (), "help": "x,y,z of the camera (parallax of the cube's top face)"},
    "side_camera": {"type": _boolean, "default": False, "metavar": "BOOL",
                    "help": "a second camera, beside the table, for where the arm hides the cube from the first"},
    "side_camera_device": {"type": int, "default": 1, "help": "the side camera's OpenCV device (backend=franky)"},
    "side_camera_position": {"type": _floats, "default": (), "help": "x,y,z of the side camera (the twin's by default)"},
    "goal": {"type": _floats, "default": (), "help": "x,y,z of a fixed goal (default: drawn per episode)"},
    "out": {"required": True, "help": "where to write"},
    "steps": {"type": int, "default": 40, "help": "steps of the debug episode"},
    "ids": {"default": "0,1,2,3", "help": "the marker ids to jog to, comma-separated"},
    "frames": {"required": True, "help": "a folder of recorded frames"},
}
_LOOP = (
    "backend", "policy", "checkpoint", "seed", "calibration", "host", "camera", "camera_position", "side_camera",
    "side_camera_device", "side_camera_position", "goal",
)
_COMMANDS: dict[str, tuple[str, tuple[str, ...], dict[str, Any]]] = {
    "run": ("run a policy through camera, perception and robot", (*_LOOP, "episodes", "compare_sim"), {}),
    "debug": ("one episode, every frame annotated with what the perception saw", (*_LOOP, "out", "steps", "video"),
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
        # As the user typed it: the console script by its name, python -m by the module (not "__main__.py").
        prog="python -m torchrl_cebp.sim2real" if Path(sys.argv[0]).name == "__main__.py" else None,
        description=__doc__.split("\n\n")[0],
        epilog="Options are written key=value (as in the examples) or --key value.\n\n" + __doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"torchrl-cebp {torchrl_cebp.__version__}")
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

    Args:
        argv (sequence of str): the command line after the program name.

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
        parser.error("give checkpoint=PATH (a training run directory, its checkpoint.pt or a policy.pt), or policy=scripted")
    if options.get("backend") == "franky" and not options["host"]:
        parser.error("backend=franky needs host=ROBOT_IP")
    if options.get("compare_sim") and options["backend"] != "sim":
        parser.error("compare_sim=true needs backend=sim: only the twin has a plain simulation to compare with")
    return command, options


def build_loop(options: dict[str, Any]) -> tuple[RealLoopEnv, RobotBackend]:
    """The backend and :class:`RealLoopEnv` (with its cameras) an options dict describes (``sim``: the MuJoCo twin).

    Args:
        options (dict): the options :func:`parse_args` returns for the command.
    """
    goal = np.asarray(options["goal"]) if options["goal"] else None
    views = 1 + options["side_camera"]
    if options["backend"] == "sim":
        from torchrl_cebp.sim2real.twin import CAMERA_NAME, SIDE_CAMERA_NAME, MuJoCoTwinBackend, TwinCamera

        backend = MuJoCoTwinBackend(seed=options["seed"])
        calibration = backend.calibration
        cameras: list[FrameSource] = [TwinCamera(backend, name) for name in (CAMERA_NAME, SIDE_CAMERA_NAME)[:views]]
        known_positions = [tuple(camera.position) for camera in cameras]
    else:
        if not options["calibration"]:
            raise ValueError("backend=franky needs calibration=FILE (write one with the calibrate command).")
        backend = FrankyBackend(options["host"])
        calibration = TableCalibration.load(options["calibration"])
        cameras = [OpenCVCamera(device) for device in (options["camera"], options["side_camera_device"])[:views]]
        known_positions = [(), ()]  # a real camera's position is only known if given
    given_positions = (options["camera_position"], options["side_camera_position"])
    main_view, *more_views = (
        CameraView.calibrated(camera, calibration, given or known)
        for camera, given, known in zip(cameras, given_positions, known_positions)
    )
    env = RealLoopEnv(
        backend, main_view.camera, main_view.perception, parallax=main_view.parallax, goal=goal, more_views=more_views
    )
    env.set_seed(options["seed"])
    return env, backend


def _side_by_side(frames: list[np.ndarray]) -> np.ndarray:
    # Two real cameras need not share a resolution: scale every frame to the first one's height.
    height = frames[0].shape[0]
    return cv2.hconcat([cv2.resize(f, (round(f.shape[1] * height / f.shape[0]), height)) for f in frames])


def _close_cameras(env: RealLoopEnv) -> None:
    for view in env.views:
        view.camera.close()


def _policy(options: dict[str, Any]) -> TensorDictModuleBase:
    return ScriptedPickPlace() if options["policy"] == "scripted" else load_policy(options["checkpoint"])


def held_steps(td: TensorDictBase) -> Counter[str]:
    """Why the steps of a loop rollout that did not move the robot held it: ``{reason: steps}``.

    A step holds when the observation its action came from was not perceived (``"markers"``, ``"cube"``)
    or the action was not finite (``"invalid_action"``); a lost camera (``"camera_lost"``) stops the robot.

    Args:
        td (TensorDictBase): a rollout of :class:`RealLoopEnv`.

    Example:
        >>> td = TensorDict({"perception_ok": torch.tensor([[True], [False]]), "perception_status": torch.tensor([[0], [2]]),
        ...                  "next": {"safety_status": torch.tensor([[0], [2]])}}, [2])
        >>> held_steps(td)
        Counter({'cube': 1})
    """
    reasons: Counter[str] = Counter()
    for perceived, status, outcome in zip(
        td["perception_ok"].flatten().tolist(), td["perception_status"].flatten().tolist(),
        td["next", "safety_status"].flatten().tolist(),
    ):
        if not perceived:
            reasons[PerceptionStatus(status).reason] += 1
        elif outcome in (SafetyStatus.INVALID_ACTION, SafetyStatus.CAMERA_LOST):
            reasons[SafetyStatus(outcome).reason] += 1
    return reasons


@torch.no_grad()
def run(options: dict[str, Any]) -> dict[str, Any]:
    """Runs ``episodes`` episodes through the loop; prints each one's outcome and a summary, and returns it.

    The loop scores success by the cube it perceives; on the twin the summary also scores it by the true
    cube position. With ``compare_sim`` each episode is replayed in plain simulation (true state, no
    camera) on the same cube placement and goal: the summary then sets the loop's success rates beside the
    simulation's.

    Args:
        options (dict): the options :func:`parse_args` returns for the command.
    """
    env, backend = build_loop(options)
    knows_truth = hasattr(backend, "cube_position")  # the twin knows where the cube truly is; a real robot does not
    try:
        policy = _policy(options)
        truth = None
        if options["compare_sim"]:  # backend=sim: parse_args checked it
            from torchrl_cebp.sim2real.twin import MuJoCoTwinBackend

            truth = MuJoCoTwinBackend(seed=options["seed"])
        loop_successes, true_successes, sim_successes, held, steps = 0, 0, 0, Counter(), 0
        threshold = env.layout.distance_threshold
        for episode in range(options["episodes"]):
            td = env.rollout(env.max_episode_steps, policy, break_when_any_done=True)
            success = bool(td["next", "is_success"][-1])
            loop_successes += success
            episode_held = held_steps(td)
            held, steps = held + episode_held, steps + td.shape[0]
            goal = td["desired_goal"][0].numpy()  # one goal per episode
            line = (f"episode {episode}: success={success} steps={td.shape[0]} held={dict(episode_held) or 0} "
                    f"goal={[round(v, 3) for v in goal.tolist()]}")
            if knows_truth:
                true_distance = float(np.linalg.norm(backend.cube_position() - goal))
                true_successes += true_distance <= threshold
                line += f" true_goal_distance={true_distance:.3f} m"
            if truth is not None:
                sim_success = truth.simulate(policy, goal)
                sim_successes += sim_success
                line += f" simulation_success={sim_success}"
            print(line, flush=True)
    finally:
        _close_cameras(env)
    episodes = max(options["episodes"], 1)
    report = {
        "episodes": options["episodes"],
        "camera_loop_success": loop_successes / episodes,
        "true_success": true_successes / episodes if knows_truth else None,
        "simulation_success": None if truth is None else sim_successes / episodes,
        "steps": steps,
        "held_steps": dict(held),
    }
    print(f"success rate {report['camera_loop_success']:.2f} over {options['episodes']} episodes (camera loop, as it perceives the cube)")
    if report["true_success"] is not None:
        print(f"success rate {report['true_success']:.2f} by the twin's true cube position (camera loop)")
    if truth is not None:
        print(f"success rate {report['simulation_success']:.2f} over the same cube placements and goals (plain simulation)")
    print(f"held {sum(held.values())} of {steps} steps: {dict(held) or 'none'}")
    return report


def calibrate(options: dict[str, Any]) -> TableCalibration:
    """Writes the calibration file: read off the twin's model, or measured by jogging the real arm to each marker.

    Args:
        options (dict): the options :func:`parse_args` returns for the command.
    """
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

    The frames as the camera gave them go to ``out/raw`` (replay them with the ``perceive`` command); the
    side camera's, with ``side_camera=true``, to ``out/side`` and ``out/side/raw``, and the video shows both.

    Args:
        options (dict): the options :func:`parse_args` returns for the command.
    """
    video = video_path(options["video"]) if options["video"] else None  # a bad name fails before the episode
    env, _ = build_loop(options)
    try:
        policy = _policy(options)
        out = Path(options["out"])
        folders = [out, out / "side"][: len(env.views)]
        for folder in folders:
            (folder / "raw").mkdir(parents=True, exist_ok=True)
        written, video_frames = [], []
        td = env.reset()
        for step in range(options["steps"]):
            name = f"frame_{step:04d}.png"
            annotated = []
            # The frames behind the observation the policy acts on, not a second read.
            for view, folder, frame in zip(env.views, folders, env.last_frames):
                cv2.imwrite(str(folder / "raw" / name), frame)
                annotated.append(draw_perception(frame, view.perception.locator.locate(frame)))
                cv2.imwrite(str(folder / name), annotated[-1])
            written.append(out / name)
            video_frames.append(_side_by_side(annotated))
            td = env.step(policy(td))
            if bool(td["next", "done"]):
                break
            td = step_mdp(td)
    finally:
        _close_cameras(env)
    print(f"wrote {len(written)} annotated frames to {', '.join(map(str, folders))}")
    if video is not None:
        rgb = [cv2.cvtColor(frame, cv2.COLOR_BGR2RGB) for frame in video_frames]
        print(f"wrote {write_video(rgb, video, fps=round(1 / env.dt))}")
    return written


def perceive(options: dict[str, Any]) -> list[Path]:
    """Camera-only debugging: runs the perception on a folder of recorded frames and writes them annotated.

    Args:
        options (dict): the options :func:`parse_args` returns for the command.
    """
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
    """Entry point of ``python -m torchrl_cebp.sim2real`` (``--help`` on it and on every command).

    Args:
        argv (sequence of str, optional): the command line after the program name; ``None`` reads ``sys.argv``.
            Defaults to ``None``.

    Returns:
        the exit status.
    """
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
