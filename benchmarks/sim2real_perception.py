"""How well each of the twin's cameras places the cube, alone on the table and while the learned policy grasps it.

Two figures per camera, the main one (facing the robot, the paper's setup) and the side one (``side_camera=true``):
  * cube alone: the twin resets to ``--placements`` random cube placements; the error is the distance between the
    perceived cube (parallax-corrected) and the simulated cube;
  * during the shipped policy's camera-loop episodes (``--episodes``, both cameras, seed 0): how many steps the main
    camera lost the cube or its markers, and the side camera's error on those steps.

Example:
    $ python benchmarks/sim2real_perception.py --placements 60 --episodes 3
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from torchrl.envs.utils import step_mdp

from torchrl_cebp.sim2real import (
    CAMERA_NAME,
    SHIPPED_POLICY,
    SIDE_CAMERA_NAME,
    CameraView,
    MuJoCoTwinBackend,
    RealLoopEnv,
    TwinCamera,
)
from torchrl_cebp.training import load_policy


def _view(backend: MuJoCoTwinBackend, name: str) -> CameraView:
    camera = TwinCamera(backend, name)
    return CameraView.calibrated(camera, backend.calibration, camera.position)


def _error(view: CameraView, backend: MuJoCoTwinBackend) -> float:
    found = view.perception.locator.locate(view.camera.read())
    if not found.ok:
        return float("nan")
    return float(np.linalg.norm(view.parallax(found.position) - backend.cube_position()))


def _summary(errors: list[float]) -> str:
    found = np.asarray([e for e in errors if np.isfinite(e)]) * 1000
    if not len(found):
        return f"found in 0 of {len(errors)}"
    return (f"found in {len(found)} of {len(errors)}, error median {np.median(found):.1f} mm, "
            f"95th percentile {np.percentile(found, 95):.1f} mm, max {found.max():.1f} mm")


def placements(count: int) -> None:
    backend = MuJoCoTwinBackend(seed=0)
    views = {name: _view(backend, name) for name in (CAMERA_NAME, SIDE_CAMERA_NAME)}
    errors: dict[str, list[float]] = {name: [] for name in views}
    for _ in range(count):
        backend.reset()  # the seed's stream: a new placement each time
        for name, view in views.items():
            errors[name].append(_error(view, backend))
    for name, values in errors.items():
        print(f"cube alone, {name}: {_summary(values)}")


@torch.no_grad()
def episodes(count: int) -> None:
    backend = MuJoCoTwinBackend(seed=0)
    main, side = _view(backend, CAMERA_NAME), _view(backend, SIDE_CAMERA_NAME)
    env = RealLoopEnv(backend, main.camera, main.perception, parallax=main.parallax, more_views=[side])
    env.set_seed(0)
    policy = load_policy(SHIPPED_POLICY)
    steps, main_lost, side_when_main_lost = 0, 0, []
    for episode in range(count):
        td = env.reset()
        for _ in range(env.max_episode_steps):
            td = env.step(policy(td))
            steps += 1
            main_frame, side_frame = env.last_frames
            if not main.perception.locator.locate(main_frame).ok:
                main_lost += 1
                found = side.perception.locator.locate(side_frame)
                side_when_main_lost.append(
                    float(np.linalg.norm(side.parallax(found.position) - backend.cube_position())) if found.ok else np.nan
                )
            td = step_mdp(td)
        print(f"episode {episode}: {steps} steps so far, main camera lost the cube or markers on {main_lost}", flush=True)
    print(f"shipped policy, {count} episodes, {steps} steps: the main camera lost the cube or markers on {main_lost}")
    print(f"  the side camera on those steps: {_summary(side_when_main_lost)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--placements", type=int, default=60, help="random cube placements, cube alone")
    parser.add_argument("--episodes", type=int, default=3, help="camera-loop episodes of the shipped policy")
    args = parser.parse_args()
    torch.set_num_threads(1)
    placements(args.placements)
    episodes(args.episodes)


if __name__ == "__main__":
    main()
