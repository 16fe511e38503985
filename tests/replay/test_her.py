"""HER relabelling: goals from later next-states of the same episode, rewards recomputed."""
import pytest
import torch
from tensordict import TensorDict
from torchrl.data import RandomSampler, TensorDictReplayBuffer

from tests.replay.conftest import T, make_episodes, sparse_reward
from torchrl_cebp.replay import EpisodeStorage, HindsightRelabel, make_replay_buffer
from torchrl_cebp.samplers import CEBPSampler, CPERSampler, EBPSampler, MEPSampler, PERSampler, UniformEpisodeSampler


def labelled_episodes(n, length=T, first_id=0):
    """The object's position encodes (episode id, state index): x = id, y = state / 100."""
    ids = torch.arange(first_id, first_id + n, dtype=torch.float32)
    positions = torch.zeros(n, length + 1, 3)
    positions[..., 0] = ids[:, None]
    positions[..., 1] = torch.arange(length + 1) / 100
    return make_episodes(n, length, positions=positions)


def decode(goal):
    return goal[:, 0].round().long(), (goal[:, 1] * 100).round().long()


ALL_SAMPLERS = [UniformEpisodeSampler, lambda: CEBPSampler("push"), CPERSampler, EBPSampler, MEPSampler,
                lambda: PERSampler(20 * T), RandomSampler]


@pytest.mark.parametrize("make_sampler", ALL_SAMPLERS)
def test_future_goals_come_from_a_later_state_of_the_same_episode(make_sampler):
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(20 * T), sampler=make_sampler(), dim_extend=0, batch_size=2048,
                                sample_unit=HindsightRelabel(sparse_reward, future_p=1.0))
    rb.extend(labelled_episodes(8))
    torch.manual_seed(0)
    batch = rb.sample()
    rows, steps = batch["index"].unbind(-1)
    episode, state = decode(batch["desired_goal"])
    own_episode, own_state = decode(batch["achieved_goal"])
    assert torch.equal(episode, own_episode)
    assert torch.equal(own_state, steps)
    assert (state >= steps + 1).all() and (state <= T).all()
    assert (state == T).any()  # the final state can be drawn
    assert torch.equal(batch["next", "desired_goal"], batch["desired_goal"])
    assert torch.equal(batch["next", "reward"], sparse_reward(batch["next", "achieved_goal"], batch["desired_goal"]))
    assert (batch["next", "reward"] == 0).any()  # t' = t + 1 gives successes


def test_future_goal_distribution_is_uniform_over_later_states():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(4 * T), sampler=UniformEpisodeSampler(), dim_extend=0,
                                batch_size=50_000, sample_unit=HindsightRelabel(sparse_reward, future_p=1.0))
    rb.extend(labelled_episodes(2))
    torch.manual_seed(0)
    batch = rb.sample()
    steps = batch["index"][:, 1]
    _, state = decode(batch["desired_goal"])
    chosen = steps == 40  # 10 later states: 41..50
    counts = torch.bincount(state[chosen] - 41, minlength=10).float()
    assert counts.numel() == 10
    assert (counts / counts.sum() - 0.1).abs().max() < 0.04


def test_future_p_is_a_per_sample_coin():
    rb = make_replay_buffer(reward_fn=sparse_reward, capacity=10 * T, batch_size=20_000, future_p=0.8)
    rb.extend(labelled_episodes(4))
    torch.manual_seed(0)
    batch = rb.sample()
    relabelled = batch["her_relabelled"]
    assert abs(relabelled.float().mean().item() - 0.8) < 0.01
    kept = ~relabelled
    stored = rb.storage[(batch["index"][kept, 0], batch["index"][kept, 1])]
    assert torch.equal(batch["desired_goal"][kept], stored["desired_goal"])


@pytest.mark.parametrize("strategy", ["final", "episode"])
def test_final_and_episode_strategies(strategy):
    rb = make_replay_buffer(reward_fn=sparse_reward, capacity=10 * T, batch_size=4096, future_p=1.0, strategy=strategy)
    rb.extend(labelled_episodes(4))
    batch = rb.sample()
    episode, state = decode(batch["desired_goal"])
    assert torch.equal(episode, decode(batch["achieved_goal"])[0])
    if strategy == "final":
        assert (state == T).all()
    else:
        assert state.min() == 1 and state.max() == T


def test_bad_strategy_and_probability_are_named():
    with pytest.raises(ValueError, match="'futur'.*future"):
        HindsightRelabel(sparse_reward, strategy="futur")
    with pytest.raises(ValueError, match="future_p"):
        HindsightRelabel(sparse_reward, future_p=1.5)


def test_slide_length_episodes():
    rb = make_replay_buffer(reward_fn=sparse_reward, capacity=10 * 70, batch_size=4096, future_p=1.0)
    rb.extend(labelled_episodes(3, length=70))
    batch = rb.sample()
    _, state = decode(batch["desired_goal"])
    assert (state >= batch["index"][:, 1] + 1).all() and state.max() == 70
