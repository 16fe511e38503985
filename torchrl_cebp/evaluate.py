"""Evaluate a trained policy: success rate over N deterministic episodes, and a video of a few.

    python -m torchrl_cebp.evaluate --task push --episodes 100 --video push.mp4     # the agent shipped for Push
    python -m torchrl_cebp.evaluate runs/push-standard/cebp/default/seed0 --episodes 50

The policy is a shipped agent (``--task``), a run directory, its checkpoint.pt, or a policy file (policy.pt). The env
(task and goal space) comes from the file's config; ``--video`` writes an MP4 or a GIF (by extension) rendered
offscreen (``MUJOCO_GL=osmesa`` on a CPU-only machine).
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import torch

import torchrl_cebp

from torchrl_cebp.agents.shipped import SHIPPED_AGENTS, shipped_agent
from torchrl_cebp.training.checkpoint import UnreadableFileError, read_policy

VIDEO_SUFFIXES = (".mp4", ".gif")


def _policy_and_env(checkpoint: str | Path, episode_steps: int | None = None, **kwargs):
    """The policy and the env its run trained on (task, goal space, robot), from one read of the file.

    ``episode_steps`` replaces the length its episodes had; ``kwargs`` go to ``make_env``.
    """
    from torchrl_cebp.envs import make_env_from_config

    policy, state = read_policy(checkpoint)
    env = state["env"] if episode_steps is None else {**state["env"], "episode_steps": episode_steps}
    return policy, make_env_from_config(env, **kwargs)


def success_rate(
    checkpoint: str | Path, episodes: int = 10, seed: int = 1234, episode_steps: int | None = None
) -> float:
    """Fraction of ``episodes`` deterministic episodes that end within the goal threshold (the trainer's measure).

    Args:
        checkpoint (str or Path): a run directory, its ``checkpoint.pt``, or a policy file.
        episodes (int, optional): the test episodes, run side by side. Defaults to ``10``.
        seed (int, optional): seeds the envs. Defaults to ``1234``.
        episode_steps (int, optional): the episodes' length. Defaults to ``None``, the length the policy trained on.

    Raises:
        FileNotFoundError: there is no such file.
        UnreadableFileError: the file does not hold a policy.
    """
    from torchrl_cebp.training.evaluation import evaluate_success_rate

    policy, env = _policy_and_env(checkpoint, episode_steps, seed=seed, num_envs=episodes)
    return evaluate_success_rate(env, policy, episodes)


@torch.no_grad()
def render_episodes(
    checkpoint: str | Path, episodes: int = 2, seed: int = 1234, size: tuple[int, int] = (480, 360),
    episode_steps: int | None = None,
) -> list[np.ndarray]:
    """The RGB frames of ``episodes`` deterministic episodes, one after the other, rendered offscreen.

    Args:
        checkpoint (str or Path): a run directory, its ``checkpoint.pt``, or a policy file.
        episodes (int, optional): the episodes rendered. Defaults to ``2``.
        seed (int, optional): seeds the env. Defaults to ``1234``.
        size (tuple of int, optional): the frames' ``(width, height)``. Defaults to ``(480, 360)``.
        episode_steps (int, optional): the episodes' length. Defaults to ``None``, the length the policy trained on.
    """
    policy, env = _policy_and_env(checkpoint, episode_steps, seed=seed, render_size=size)
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
    return frames


def record_video(
    checkpoint: str | Path,
    path: str | Path,
    episodes: int = 2,
    seed: int = 1234,
    size: tuple[int, int] = (480, 360),
    fps: int = 25,
    episode_steps: int | None = None,
) -> Path:
    """Renders ``episodes`` deterministic episodes to ``path`` (``.mp4`` or ``.gif``).

    Args:
        checkpoint (str or Path): a run directory, its ``checkpoint.pt``, or a policy file.
        path (str or Path): the video, ``.mp4`` or ``.gif``.
        episodes (int, optional): the episodes recorded, one after the other. Defaults to ``2``.
        seed (int, optional): seeds the env. Defaults to ``1234``.
        size (tuple of int, optional): the frames' ``(width, height)``. Defaults to ``(480, 360)``.
        fps (int, optional): frames per second. Defaults to ``25``.
        episode_steps (int, optional): the episodes' length. Defaults to ``None``, the length the policy trained on.

    Returns:
        the video's path.
    """
    path = video_path(path)
    return write_video(render_episodes(checkpoint, episodes, seed, size, episode_steps), path, fps)


def video_path(path: str | Path) -> Path:
    """``path`` as a Path, after checking that its extension is a video format :func:`write_video` writes.

    Args:
        path (str or Path): the video's path.

    Raises:
        ValueError: an extension other than ``.mp4`` and ``.gif``.

    Example:
        >>> video_path("push.mp4").name
        'push.mp4'
    """
    path = Path(path)
    if path.suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"video {str(path)!r}: unknown format {path.suffix!r}; valid: {list(VIDEO_SUFFIXES)}")
    return path


def write_video(frames: list[np.ndarray], path: str | Path, fps: int = 25) -> Path:
    """Writes RGB frames ``[H, W, 3]`` to ``path``: an H.264 MP4 or a looping GIF, by its extension.

    Args:
        frames (list of np.ndarray): uint8 RGB frames of one size.
        path (str or Path): the video, ``.mp4`` or ``.gif``.
        fps (int, optional): frames per second. Defaults to ``25``.

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
    """The command line: ``python -m torchrl_cebp.evaluate (RUN | --task TASK) [--episodes N] [--video PATH]``.

    Args:
        argv (list of str, optional): the arguments; ``None`` reads ``sys.argv``. Defaults to ``None``.
    """
    os.environ.setdefault("MUJOCO_GL", "osmesa")
    parser = argparse.ArgumentParser(
        description="Success rate of a trained policy (a shipped agent, or your own run), and a video of a few episodes."
    )
    parser.add_argument("--version", action="version", version=f"torchrl-cebp {torchrl_cebp.__version__}")
    parser.add_argument(
        "checkpoint", nargs="?", help="a run directory, its checkpoint.pt, or a policy file (policy.pt)"
    )
    parser.add_argument(
        "--task", choices=sorted(SHIPPED_AGENTS), help="evaluate the agent shipped for this task instead of a file"
    )
    parser.add_argument("--episodes", type=int, default=10, help="test episodes for the success rate")
    parser.add_argument("--video", help="write a video of a few episodes here (.mp4 or .gif)")
    parser.add_argument("--video-episodes", type=int, default=2, help="episodes in the video, one after the other")
    parser.add_argument("--seed", type=int, default=1234, help="seeds the episodes: episode i gets SEED + i")
    parser.add_argument(
        "--episode-steps", type=int,
        help="the episodes' length (default: the length the policy trained on; the Franka card's is 100, the loop's)",
    )
    args = parser.parse_args(argv)
    for option in ("episodes", "video_episodes", "episode_steps"):
        value = getattr(args, option)
        if value is not None and value < 1:
            parser.error(f"--{option.replace('_', '-')} must be at least 1, got {value}")
    if (args.checkpoint is None) == (args.task is None):
        parser.error("give either a policy (a run directory or a file) or --task, not both or neither")
    try:
        if args.video:
            video_path(args.video)  # a wrong extension is refused before the episodes run, not after
    except ValueError as error:
        parser.error(str(error))
    try:
        checkpoint = shipped_agent(args.task) if args.task else args.checkpoint
        rate = success_rate(checkpoint, args.episodes, args.seed, args.episode_steps)
    except (FileNotFoundError, UnreadableFileError) as error:
        parser.exit(2, f"error: {error}\n")
    length = "" if args.episode_steps is None else f" of {args.episode_steps} steps"
    print(f"{checkpoint}: success rate over {args.episodes} episodes{length}: {rate:.3f}")
    if args.video:
        video = record_video(checkpoint, args.video, args.video_episodes, args.seed, episode_steps=args.episode_steps)
        print(f"wrote {video}")


if __name__ == "__main__":
    main()
