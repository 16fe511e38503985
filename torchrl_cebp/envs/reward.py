"""An env's goal reward reached through TorchRL's env wrappers, for HER."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torchrl.envs import EnvBase, ParallelEnv, SerialEnv, TransformedEnv


def compute_reward_of(env: EnvBase) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """The ``compute_reward(achieved_goal, desired_goal)`` of the env inside TorchRL's wrappers: HER's ``reward_fn``.

    TorchRL forwards an attribute a ``TransformedEnv`` lacks to its base env, so ``env.compute_reward``
    works on a transformed :class:`~torchrl_cebp.envs.TouchFetchEnv`. A batched env (``SerialEnv``,
    ``ParallelEnv``) instead dispatches the attribute to each of its workers: called, it returns a list
    with one result per worker, and on a ``SerialEnv`` that has not started yet the lookup recurses
    until Python's ``RecursionError``. This unwraps instead, through the wrappers' public attributes: a
    ``TransformedEnv`` to its ``base_env``, a batched env to its first worker's env, built here from
    ``create_env_fn[0](**create_env_kwargs[0])`` (once, at that constructor's cost; a batched env's
    workers run one task). The batched env is neither started nor asked anything.

    Args:
        env (EnvBase): a :class:`~torchrl_cebp.envs.TouchFetchEnv`, possibly inside ``TransformedEnv``,
            ``SerialEnv`` or ``ParallelEnv``.

    Returns:
        the innermost env's ``compute_reward``.

    Example:
        >>> import functools
        >>> from torchrl.envs import SerialEnv, StepCounter, TransformedEnv
        >>> from torchrl_cebp.envs import make_env
        >>> env = TransformedEnv(SerialEnv(2, functools.partial(make_env, "push")), StepCounter())
        >>> reward = compute_reward_of(env)
        >>> reward(torch.zeros(4, 3), torch.tensor([[0.0, 0.0, 0.01], [0.0, 0.0, 0.1]]).repeat(2, 1)).squeeze(-1)
        tensor([ 0., -1.,  0., -1.])
    """
    while isinstance(env, (TransformedEnv, SerialEnv, ParallelEnv)):
        env = env.base_env if isinstance(env, TransformedEnv) else env.create_env_fn[0](**env.create_env_kwargs[0])
    return env.compute_reward
