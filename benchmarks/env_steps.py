"""Env steps per second with random actions: our TorchRL touch-sensing Push vs gymnasium-robotics, both robots.

One torch thread; the envs take turns in short rounds and each reports its best round, so load
from other processes on a shared machine skews the ratios less:
  * plain gymnasium-robotics ``FetchPush-v4`` (``gym.make``, no touch sensing),
  * our touch-sensing gymnasium env ``TouchFetchPush-v0`` (``gym.make``: the simulation's share),
  * the extended Push on both robots through ``gym.make``: the mocap Fetch and the released code's
    joint-controlled Fetch with table-blind pads (``TouchFetchPushJointExtended-v0``),
  * ``TouchFetchEnv`` (our ``EnvBase`` driving the MuJoCo env directly), one simulation and a
    batch of 16 (``num_envs=16``: one TorchRL step drives 16 simulations, as the trainer uses it),
    on both robots,
  * TorchRL ``GymEnv`` + ``DoubleToFloat`` + an info-dict reader on the same touch env
    (the generic way to get the same keys), for comparison.

A second table (``--contact-episodes N``) counts, over N random-action episodes of extended Push per
robot, how often the object moved more than 1 cm and how often touch fired: what the contact-energy
samplers have to work with.

Example:
    $ python benchmarks/env_steps.py --steps 200 --rounds 10 --contact-episodes 100
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import torchrl_cebp.envs  # noqa: F401, I001  (first: it keeps gymnasium-robotics' Adroit notice off the terminal)
import gymnasium as gym
import gymnasium_robotics
import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Categorical, Unbounded
from torchrl.envs import DoubleToFloat, EnvBase, GymEnv, TransformedEnv
from torchrl.envs.gym_like import default_info_dict_reader

from torchrl_cebp.envs import gym_id, make_env


def gymnasium_round(env_id: str, seed: int = 0, **kwargs) -> Callable[[int], float]:
    """A function timing ``steps`` random-action steps (seconds) of a ``gym.make`` env, resetting on episode end.

    Example:
        >>> gymnasium_round("FetchPush-v4")(20) > 0
        True
    """
    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)

    def run(steps: int) -> float:
        actions = rng.uniform(-1, 1, size=(steps, *env.action_space.shape)).astype(np.float32)
        start = time.perf_counter()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run


def torchrl_round(env: EnvBase) -> Callable[[int], float]:
    """A function timing ``steps`` simulation steps (seconds) of ``env.rollout`` with random actions.

    A batched env advances ``batch`` simulations per rollout step, so it rolls out ``steps / batch`` steps.

    Example:
        >>> torchrl_round(make_env("push", seed=0))(20) > 0
        True
    """
    batch = env.batch_size.numel()

    def random_policy(td: TensorDictBase) -> TensorDictBase:
        return td.set("action", env.action_spec.rand())

    def run(steps: int) -> float:
        start = time.perf_counter()
        env.rollout(max(1, steps // batch), random_policy, break_when_any_done=False)
        return time.perf_counter() - start

    return run


def gymenv_with_transforms(task: str = "push") -> EnvBase:
    """The same touch env through TorchRL's generic ``GymEnv`` + transforms.

    Example:
        >>> "touch" in gymenv_with_transforms().reset().keys()
        True
    """
    env = GymEnv(gym_id(task))
    reader = default_info_dict_reader(
        ["is_success", "touch"],
        spec={"is_success": Categorical(2, (1,), dtype=torch.bool), "touch": Unbounded((2,), dtype=torch.float64)},
    )
    env.set_info_dict_reader(reader)
    return TransformedEnv(env, DoubleToFloat())


ROBOTS = {
    "mocap Fetch": {},
    "mocap Fetch, table-blind pads": {"touch_ignores_table": True},
    "joint Fetch, table-blind pads (released)": {"control": "joint", "touch_ignores_table": True},
}


def contact_under_random_actions(episodes: int, seed: int = 0, **robot) -> tuple[float, float]:
    """Fractions of random-action extended-Push episodes in which the object moved > 1 cm, and touch fired.

    Example:
        >>> contact_under_random_actions(4)[1]  # the stock pads: fingertips in the table from the first step
        1.0
    """
    torch.manual_seed(seed)
    env = make_env("push", "extended", seed=seed, num_envs=episodes, **robot)
    rollout = env.rollout(env.max_episode_steps, break_when_any_done=False)
    start = rollout["achieved_goal"][:, :1]
    moved = torch.linalg.vector_norm(rollout["next", "achieved_goal"] - start, dim=-1).amax(1) > 0.01
    touched = (rollout["next", "touch"].sum(-1) > 0).any(1)
    return moved.float().mean().item(), touched.float().mean().item()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=320, help="simulation steps per round")
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--contact-episodes", type=int, default=100, help="random-action episodes per robot (0: skip)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    gym.register_envs(gymnasium_robotics)

    contenders = {
        "gymnasium FetchPush-v4 (plain, no touch)": gymnasium_round("FetchPush-v4"),
        "gymnasium TouchFetchPush-v0 (ours, no torch)": gymnasium_round("TouchFetchPush-v0"),
        "torchrl_cebp make_env('push') (EnvBase)": torchrl_round(make_env("push", seed=0)),
        "torchrl_cebp make_env('push', num_envs=16)": torchrl_round(make_env("push", seed=0, num_envs=16)),
        "gymnasium TouchFetchPushExtended-v0 (mocap)": gymnasium_round("TouchFetchPushExtended-v0"),
        "gymnasium TouchFetchPushJointExtended-v0 (joint)": gymnasium_round(
            "TouchFetchPushJointExtended-v0", touch_ignores_table=True
        ),
        "make_env('push', 'extended', num_envs=16) mocap": torchrl_round(
            make_env("push", "extended", seed=0, num_envs=16)
        ),
        "make_env('push', 'extended', num_envs=16) joint": torchrl_round(
            make_env("push", "extended", seed=0, num_envs=16, control="joint", touch_ignores_table=True)
        ),
        "GymEnv(TouchFetchPush-v0) + DoubleToFloat": torchrl_round(gymenv_with_transforms("push")),
    }
    best = {name: float("inf") for name in contenders}
    for name, run in contenders.items():
        run(10)  # warm-up
    for _ in range(args.rounds):
        for name, run in contenders.items():
            best[name] = min(best[name], run(args.steps))
    plain = args.steps / next(iter(best.values()))
    print(f"{'env':<50} {'steps/s':>9} {'vs plain':>9}")
    for name, seconds in best.items():
        rate = args.steps / seconds
        print(f"{name:<50} {rate:9.0f} {rate / plain:9.2f}")
    if args.contact_episodes:
        print(f"\n{args.contact_episodes} random-action episodes of extended Push per robot")
        print(f"{'robot':<44} {'object moved > 1 cm':>20} {'touch fired':>12}")
        for name, robot in ROBOTS.items():
            moved, touched = contact_under_random_actions(args.contact_episodes, **robot)
            print(f"{name:<44} {moved:20.2f} {touched:12.2f}")


if __name__ == "__main__":
    main()
