"""The test episodes: success rate of the deterministic policy, the one measure every report uses."""

from __future__ import annotations

import math

import torch
from tensordict.nn import TensorDictSequential
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type


@torch.no_grad()
def evaluate_success_rate(env: EnvBase, policy: TensorDictSequential, n_episodes: int) -> float:
    """Success at the last step of ``n_episodes`` deterministic episodes on the batched ``env``, as a fraction.

    Args:
        env (EnvBase): a batched env (batch size ``[n]``); it runs ``ceil(n_episodes / n)`` rollouts.
        policy (TensorDictSequential): the policy, run under ``ExplorationType.DETERMINISTIC``.
        n_episodes (int): how many episodes count.

    Example:
        >>> from torchrl_cebp.envs import make_env
        >>> from torchrl_cebp.training.collection import make_policy
        >>> policy, _ = make_policy(25, 3, 4, [32])
        >>> 0.0 <= evaluate_success_rate(make_env("push", num_envs=2, seed=0), policy, 3) <= 1.0
        True
    """
    successes = []
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        for _ in range(math.ceil(n_episodes / env.batch_size[0])):
            rollout = env.rollout(env.max_episode_steps, policy, break_when_any_done=False)
            successes.append(rollout["next", "is_success"][:, -1].reshape(-1))
    return torch.cat(successes)[:n_episodes].float().mean().item()
