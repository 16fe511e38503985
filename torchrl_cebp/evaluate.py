"""Evaluate a trained policy: success rate over N deterministic episodes, and a video of a few.

    python -m torchrl_cebp.evaluate runs/push-standard/cebp/default/seed0 --episodes 50 --video push.mp4

The policy is a run directory, its checkpoint.pt, or a policy file (policy.pt). The env (task and
goal space) comes from the file's config; ``--video`` writes an MP4 or a
GIF (by extension) rendered offscreen (``MUJOCO_GL=osmesa`` on a CPU-only machine).
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import torch

from torchrl_cebp.training.checkpoint import read_policy_state

VIDEO_SUFFIXES = (".mp4", ".gif")


def _policy_and_env(checkpoint: str | Path, **kwargs):
    """The policy and the env its run trained on (task, goal space, robot), from one read of the file.

    ``kwargs`` go to ``make_env``.
    """
    from torchrl_cebp.envs import make_env_from_config
    from torchrl_cebp.training.checkpoint import policy_from_state

    state = read_policy_state(checkpoint)
    return policy_from_state(state), make_env_from_config(state["env"], **kwargs)


def success_rate(checkpoint: str | Path, episodes: int = 10, seed: int = 1234) -> float:
    """Fraction of ``episodes`` deterministic episodes that end within the goal threshold (the trainer's measure)."""
    from torchrl_cebp.training.evaluation import evaluate_success_rate

    policy, env = _policy_and_env(checkpoint, seed=seed, num_envs=episodes)
    return evaluate_success_rate(env, policy, episodes)


@torch.no_grad()
def record_video(
    checkpoint: str | Path,
    path: str | Path,
    episodes: int = 2,
    seed: int = 1234,
    size: tuple[int, int] = (480, 360),
    fps: int = 25,
) -> Path:
    """Renders ``episodes`` deterministic episodes to ``path`` (``.mp4`` or ``.gif``)."""
    path = video_path(path)
    policy, env = _policy_and_env(checkpoint, seed=seed, render_size=size)
    frames = []
    try:
        for _ in range(episodes):
            td = env.reset()
            frames.append(env.render())
            for _ in range(env.max_episode_steps):
                td = env.step(policy(td))
                frames.append(env.render())
                td = td["next"].exclude("reward", "done", "terminated", "truncated")
    finally:
        env.close()
    return write_video(frames, path, fps)


def video_path(path: str | Path) -> Path:
    """``path`` as a Path, after checking that its extension is a video format :func:`write_video` writes."""
    path = Path(path)
    if path.suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"video {str(path)!r}: unknown format {path.suffix!r}; valid: {list(VIDEO_SUFFIXES)}")
    return path


def write_video(frames: list[np.ndarray], path: str | Path, fps: int = 25) -> Path:
    """Writes RGB frames ``[H, W, 3]`` to ``path``: an H.264 MP4 or a looping GIF, by its extension.

    Example:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     write_video([np.zeros((48, 64, 3), np.uint8)] * 5, Path(d) / "black.gif").suffix
        '.gif'
    """
    import imageio.v3 as iio

    path = video_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".gif":
        iio.imwrite(path, np.stack(frames), duration=1000 / fps, loop=0)
    else:
        # yuv420p needs even sides, nothing more: the writer's default 16-pixel blocks would rescale 360 rows to 368.
        iio.imwrite(path, np.stack(frames), fps=fps, codec="libx264", macro_block_size=2)
    return path


def main(argv: list[str] | None = None) -> None:
    os.environ.setdefault("MUJOCO_GL", "osmesa")
    parser = argparse.ArgumentParser(description="Success rate of a checkpoint, and a video of a few episodes.")
    parser.add_argument("checkpoint", help="a run directory, its checkpoint.pt, or a policy file (policy.pt)")
    parser.add_argument("--episodes", type=int, default=10, help="test episodes for the success rate")
    parser.add_argument("--video", help="write a video of a few episodes here (.mp4 or .gif)")
    parser.add_argument("--video-episodes", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1234)
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")
    rate = success_rate(args.checkpoint, args.episodes, args.seed)
    print(f"success rate over {args.episodes} episodes: {rate:.3f}")
    if args.video:
        print(f"wrote {record_video(args.checkpoint, args.video, args.video_episodes, args.seed)}")


if __name__ == "__main__":
    main()
