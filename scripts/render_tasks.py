"""Render the three touch-sensing Fetch tasks side by side into ``docs/img/tasks.png``.

The camera sits close to the gripper so the green touch-sensing pads on the fingers show.

Example:
    $ MUJOCO_GL=osmesa python scripts/render_tasks.py --goal-space extended --out docs/img/tasks.png
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "osmesa")

import imageio.v3 as iio  # noqa: E402
import numpy as np  # noqa: E402

from torchrl_cebp.envs import TASKS, make_touch_fetch  # noqa: E402  (imports tensordict before mujoco)


def render_task(task: str, goal_space: str = "standard", size: int = 480, seed: int = 0) -> np.ndarray:
    """An RGB frame of ``task`` after reset with the gripper opened, the camera framing gripper and object.

    Example:
        >>> render_task("push", size=64).shape
        (64, 64, 3)
    """
    env = make_touch_fetch(task, goal_space, render_mode="rgb_array", width=size, height=size)
    env.reset(seed=seed)
    for _ in range(5):  # open the fingers (a no-op where the gripper is blocked) to show both pads
        env.step(np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32))
    gripper, block = env._get_gripper_xpos(), env.data.site("object0").xpos
    env.mujoco_renderer.default_cam_config = {
        "lookat": (gripper + block) / 2,
        "distance": 0.45 + 0.6 * float(np.linalg.norm(gripper - block)),
        "azimuth": 160.0,
        "elevation": -18.0,
    }
    frame = env.render()
    env.close()
    return frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal-space", default="standard")
    parser.add_argument("--size", type=int, default=480)
    parser.add_argument("--out", default="docs/img/tasks.png")
    args = parser.parse_args()
    frames = [render_task(task, args.goal_space, args.size) for task in TASKS]
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    iio.imwrite(args.out, np.concatenate(frames, axis=1))
    print(f"wrote {args.out} ({', '.join(TASKS)})")


if __name__ == "__main__":
    main()
