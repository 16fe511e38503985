"""compute_reward_of: the env's goal reward through TorchRL's env wrappers."""

from __future__ import annotations

import functools

import pytest
import torch
from torchrl.envs import ParallelEnv, SerialEnv, StepCounter, TransformedEnv

from torchrl_cebp.envs import compute_reward_of, make_env

PUSH = functools.partial(make_env, "push", num_envs=2)
WRAPPED = {
    "plain": lambda: PUSH(),
    "TransformedEnv": lambda: TransformedEnv(PUSH(), StepCounter()),
    "TransformedEnv(SerialEnv)": lambda: TransformedEnv(SerialEnv(2, PUSH), StepCounter()),
    "TransformedEnv(ParallelEnv)": lambda: TransformedEnv(ParallelEnv(2, PUSH), StepCounter()),
    "SerialEnv(TransformedEnv)": lambda: SerialEnv(2, lambda: TransformedEnv(PUSH(), StepCounter())),
}


@pytest.mark.parametrize("wrapping", list(WRAPPED))
def test_compute_reward_of_reaches_the_goal_reward_through_torchrl_wrappers(wrapping):
    env = WRAPPED[wrapping]()
    achieved = torch.zeros(3, 3)
    desired = torch.tensor([[0.0, 0.0, 0.04], [0.0, 0.06, 0.0], [0.0, 0.0, 0.0]])  # Push's threshold is 0.05

    reward = compute_reward_of(env)(achieved, desired)

    assert torch.equal(reward, torch.tensor([[0.0], [-1.0], [0.0]]))  # one tensor, not one per worker
    assert getattr(env, "is_closed", True)  # a batched env was neither started nor asked
