"""Goal concatenation after HER: replay_cat_tensors as the buffer's transform, against CatTensors on the env."""
from __future__ import annotations

import functools

import pytest
import torch
from tensordict import TensorDictBase
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs import CatTensors, EnvBase, SerialEnv, TransformedEnv

from torchrl_cebp.envs import compute_reward_of, make_env
from torchrl_cebp.replay import EpisodeStorage, HindsightRelabel
from torchrl_cebp.replay.transforms import replay_cat_tensors

CAT = dict(in_keys=["observation", "desired_goal"], out_key="observation_goal")


def draw(env: EnvBase, **buffer) -> TensorDictBase:
    """A batch of HER-relabelled transitions (every one relabelled) from two episodes of ``env``."""
    env.set_seed(0)
    her = HindsightRelabel(compute_reward_of(env), future_p=1.0)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(10 * 50), sample_unit=her, collate_fn=her.collate,
                                generator=torch.Generator().manual_seed(0), batch_size=64, dim_extend=0, **buffer)
    rb.extend(env.rollout(50))
    return rb.sample()


def test_the_goal_concatenated_by_the_buffer_transform_is_the_relabelled_one():
    # The env concatenates too (keeping its inputs), as a policy acting on the vector needs; the buffer rebuilds it.
    env = TransformedEnv(SerialEnv(2, functools.partial(make_env, "push")), CatTensors(**CAT, del_keys=False, sort=False))
    stale = draw(env)
    fresh = draw(env, transform=replay_cat_tensors(**CAT, del_keys=False))

    # In the order given, the goal last: replay_cat_tensors does not sort (CatTensors does by default).
    assert not torch.equal(stale["observation_goal"][:, -3:], stale["desired_goal"])  # the env's kept the old goal
    for root in ((), ("next",)):
        expected = torch.cat([fresh[(*root, "observation")], fresh[(*root, "desired_goal")]], dim=-1)
        assert torch.equal(fresh[(*root, "observation_goal")], expected)


def test_sorting_is_still_available_as_catTensors_offers_it():
    env = TransformedEnv(SerialEnv(2, functools.partial(make_env, "push")), CatTensors(**CAT, del_keys=False))
    fresh = draw(env, transform=replay_cat_tensors(**CAT, del_keys=False, sort=True))
    expected = torch.cat([fresh["desired_goal"], fresh["observation"]], dim=-1)  # sorted: the goal first
    assert torch.equal(fresh["observation_goal"], expected)


def test_an_env_that_concatenates_and_drops_the_goal_names_the_missing_key():
    env = TransformedEnv(SerialEnv(2, functools.partial(make_env, "push")), CatTensors(**CAT))  # del_keys=True
    with pytest.raises(KeyError, match="desired_goal"):
        draw(env)
