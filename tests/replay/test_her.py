"""HER relabelling: goals from later next-states of the same episode, rewards recomputed, before the transforms."""
import copy
import pickle
import re

import numpy as np
import pytest
import torch
from torchrl.data import LazyTensorStorage, PrioritizedSampler, RandomSampler, SliceSampler, TensorDictReplayBuffer
from torchrl.envs import Compose, ObservationNorm, RewardScaling

from tests.replay.conftest import T, make_episodes, sparse_reward
from torchrl_cebp.replay import EpisodeStorage, HindsightRelabel, make_replay_buffer
from torchrl_cebp.replay.samplers import CEBPSampler, CPERSampler, EBPSampler, MEPSampler, PERSampler, UniformEpisodeSampler


def labelled_episodes(n, length=T, first_id=0):
    """The object's position encodes (episode id, state index): x = id, y = state / 100."""
    ids = torch.arange(first_id, first_id + n, dtype=torch.float32)
    positions = torch.zeros(n, length + 1, 3)
    positions[..., 0] = ids[:, None]
    positions[..., 1] = torch.arange(length + 1) / 100
    return make_episodes(n, length, positions=positions)


def decode(goal):
    return goal[:, 0].round().long(), (goal[:, 1] * 100).round().long()


ALL_SAMPLERS = [UniformEpisodeSampler, lambda: CEBPSampler(), CPERSampler, EBPSampler, MEPSampler,
                lambda: PERSampler(20 * T), RandomSampler, lambda: PrioritizedSampler(20 * T, alpha=0.6, beta=0.4)]


@pytest.mark.parametrize("make_sampler", ALL_SAMPLERS)
def test_future_goals_come_from_a_later_state_of_the_same_episode(make_sampler):
    her = HindsightRelabel(sparse_reward, future_p=1.0)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(20 * T), sampler=make_sampler(), dim_extend=0, batch_size=2048,
                                sample_unit=her, collate_fn=her.collate)
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
    her = HindsightRelabel(sparse_reward, future_p=1.0)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(4 * T), sampler=UniformEpisodeSampler(), dim_extend=0,
                                batch_size=50_000, sample_unit=her, collate_fn=her.collate)
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
    rb = make_replay_buffer(None, HindsightRelabel(sparse_reward, future_p=0.8), capacity=10 * T, batch_size=20_000)
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
    rb = make_replay_buffer(None, HindsightRelabel(sparse_reward, future_p=1.0, strategy=strategy), capacity=10 * T, batch_size=4096)
    rb.extend(labelled_episodes(4))
    batch = rb.sample()
    episode, state = decode(batch["desired_goal"])
    assert torch.equal(episode, decode(batch["achieved_goal"])[0])
    if strategy == "final":
        assert (state == T).all()
    else:
        assert state.min() == 1 and state.max() == T


def test_past_strategy_replays_an_earlier_transition_towards_the_drawn_steps_goal():
    """CPER's published draw: the drawn step t gives the goal (state t + 1); the transition is t' = floor(U t)."""
    her = HindsightRelabel(sparse_reward, future_p=1.0, strategy="past")
    rb = make_replay_buffer(None, her, capacity=10 * T, batch_size=4096, generator=torch.Generator().manual_seed(0))
    rb.extend(labelled_episodes(4))
    batch = rb.sample()
    episode, goal_state = decode(batch["desired_goal"])
    transition_episode, transition_state = decode(batch["achieved_goal"])
    assert torch.equal(episode, transition_episode) and torch.equal(batch["index"][:, 1], transition_state)
    drawn = goal_state - 1  # the uniform sampler's step
    assert drawn.min() == 0 and drawn.max() == T - 1
    assert (transition_state <= drawn).all() and (transition_state < drawn)[drawn > 0].all()
    # floor(U t) is uniform on {0, ..., t - 1} (0 for t = 0), and t uniform on {0, ..., T - 1}: its exact law.
    law = np.zeros(T)
    for t in range(1, T):
        law[:t] += 1.0 / (t * T)
    law[0] += 1.0 / T
    values = np.arange(T) / T
    mean, sd = (law * values).sum(), np.sqrt((law * values**2).sum() - (law * values).sum() ** 2)
    assert mean == pytest.approx((T - 2) * (T - 1) / (4 * T * T))  # 0.2352 for T = 50, not T / 4
    tolerance = 5 * sd / np.sqrt(transition_state.numel())  # five standard errors of a mean of 4,096 draws
    assert abs((transition_state.double() / T).mean().item() - mean) < tolerance
    unrelabelled = make_replay_buffer(None, HindsightRelabel(sparse_reward, future_p=0.0, strategy="past"),
                                      capacity=10 * T, batch_size=4096)
    unrelabelled.extend(labelled_episodes(4))
    assert (unrelabelled.sample()["index"][:, 1].float() / T).mean() < 0.3  # its transitions too come early


def test_bad_strategy_and_probability_are_named():
    with pytest.raises(ValueError, match="'futur'.*future"):
        HindsightRelabel(sparse_reward, strategy="futur")
    with pytest.raises(ValueError, match="future_p"):
        HindsightRelabel(sparse_reward, future_p=1.5)


def test_slide_length_episodes():
    rb = make_replay_buffer(None, HindsightRelabel(sparse_reward, future_p=1.0), capacity=10 * 70, batch_size=4096)
    rb.extend(labelled_episodes(3, length=70))
    batch = rb.sample()
    _, state = decode(batch["desired_goal"])
    assert (state >= batch["index"][:, 1] + 1).all() and state.max() == 70


@pytest.mark.parametrize("make_sampler", [UniformEpisodeSampler, RandomSampler, lambda: PrioritizedSampler(20 * T, 0.6, 0.4)])
def test_stock_transforms_see_the_relabelled_reward_and_goal(make_sampler):
    her = HindsightRelabel(sparse_reward, future_p=1.0)
    transform = Compose(
        RewardScaling(loc=0.0, scale=10.0, in_keys=[("next", "reward")]),
        ObservationNorm(loc=0.0, scale=2.0, in_keys=["desired_goal"], standard_normal=False),
    )
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(20 * T), sampler=make_sampler(), dim_extend=0, batch_size=2048,
                                sample_unit=her, collate_fn=her.collate, transform=transform)
    rb.extend(labelled_episodes(8))
    batch = rb.sample()
    goal = batch["desired_goal"] / 2  # the transform doubled the relabelled goal
    episode, state = decode(goal)
    assert torch.equal(episode, decode(batch["achieved_goal"])[0])
    assert (state >= batch["index"][:, 1] + 1).all()
    reward = batch["next", "reward"]
    assert set(reward.unique().tolist()) == {-10.0, 0.0}  # scaled after relabelling: successes and failures
    assert torch.equal(reward, 10 * sparse_reward(batch["next", "achieved_goal"], goal))
    assert batch["her_relabelled"].all()


def test_the_buffer_generator_drives_every_draw_of_a_sample():
    def batch(seed, global_seed):
        rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward, future_p=0.5), capacity=10 * T,
                                batch_size=512, generator=torch.Generator().manual_seed(seed))
        rb.extend(labelled_episodes(6))
        torch.manual_seed(global_seed)
        return rb.sample()

    first, again, other = batch(3, global_seed=0), batch(3, global_seed=1), batch(4, global_seed=0)
    for key in ("index", "desired_goal", "her_relabelled"):
        assert torch.equal(first[key], again[key])  # the global RNG played no part
    assert not torch.equal(first["desired_goal"], other["desired_goal"])


def test_a_buffer_given_her_only_as_sample_unit_fails_loudly():
    her = HindsightRelabel(sparse_reward)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(10 * T), dim_extend=0, batch_size=8, sample_unit=her)
    rb.extend(labelled_episodes(2))
    rb.sample()
    with pytest.raises(RuntimeError, match="collate_fn=her.collate"):
        rb.sample()


def test_indexing_the_buffer_reads_the_stored_transitions_unrelabelled():
    her = HindsightRelabel(sparse_reward, future_p=1.0)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(10 * T), dim_extend=0, batch_size=8, sample_unit=her,
                                collate_fn=her.collate)
    rb.extend(labelled_episodes(3))
    stored, rows, steps = rb.storage.get(slice(None)), torch.tensor([0, 2]), torch.tensor([3, 7])
    assert (rb[0:2] == stored[0:2]).all() and (rb[rows] == stored[rows]).all()
    assert (rb[(rows, steps)] == stored[rows, steps]).all()
    assert rb.sample()["her_relabelled"].all()  # a draw still relabels


def test_a_buffer_given_her_only_as_collate_fn_fails_loudly():
    her = HindsightRelabel(sparse_reward)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(10 * T), dim_extend=0, batch_size=8, collate_fn=her.collate)
    rb.extend(labelled_episodes(2))
    with pytest.raises(RuntimeError, match=r"batch of shape \[8\] without a draw.*sample_unit=her"):
        rb.sample()


def pickled(rb):
    return pickle.loads(pickle.dumps(rb))


@pytest.mark.parametrize("copy_buffer", [pickled, copy.deepcopy], ids=["pickle", "deepcopy"])
@pytest.mark.parametrize("make_sampler", [UniformEpisodeSampler, CEBPSampler, lambda: PERSampler(10 * T)])
def test_a_buffer_with_her_copies_and_the_copy_draws_what_the_original_draws(copy_buffer, make_sampler):
    rb = make_replay_buffer(make_sampler(), HindsightRelabel(sparse_reward, future_p=0.5), capacity=10 * T,
                            batch_size=256, generator=torch.Generator().manual_seed(0))
    rb.extend(labelled_episodes(4))
    rb.sample()  # a draw has run: its expand/collate hand-over is over
    copied = copy_buffer(rb)
    for _ in range(2):
        expected, got = rb.sample(), copied.sample()
        assert (expected == got).all()


def test_her_draws_from_the_buffer_generator_whose_state_the_buffer_state_keeps():
    def buffer(seed):
        rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward, future_p=0.5), capacity=10 * T,
                                batch_size=256, generator=torch.Generator().manual_seed(seed))
        rb.extend(labelled_episodes(4))
        return rb

    original = buffer(0)
    original.sample()
    restored = buffer(1)
    restored.load_state_dict(original.state_dict())
    for _ in range(2):
        assert (original.sample() == restored.sample()).all()
    with pytest.raises(TypeError, match="generator"):  # no generator of its own, which the buffer's state would miss
        HindsightRelabel(sparse_reward, generator=torch.Generator())


class ReadFailsOnce(EpisodeStorage):
    """An episode storage whose next batch read fails (a disk error, a Ctrl-C): a draw interrupted after HER's part."""

    fail_next_read = False

    def get(self, index):
        if self.fail_next_read:
            self.fail_next_read = False
            raise OSError("the read of the batch failed")
        return super().get(index)


@pytest.mark.parametrize("drawn_before", [True, False])
def test_a_draw_interrupted_after_her_leaves_the_next_draws_whole(drawn_before):
    her = HindsightRelabel(sparse_reward, future_p=1.0)
    rb = TensorDictReplayBuffer(storage=ReadFailsOnce(10 * T), dim_extend=0, batch_size=512, sample_unit=her,
                                collate_fn=her.collate)
    rb.extend(labelled_episodes(4))
    if drawn_before:
        rb.sample()
    rb.storage.fail_next_read = True
    with pytest.raises(OSError):
        rb.sample()
    if not drawn_before:  # no batch has shown yet that the buffer hands its batches to HER
        with pytest.raises(RuntimeError, match="collate_fn=her.collate.*interrupted"):
            rb.sample()
    for _ in range(2):
        batch = rb.sample()
        episode, state = decode(batch["desired_goal"])
        assert torch.equal(episode, decode(batch["achieved_goal"])[0])
        assert (state > batch["index"][:, 1]).all()


@pytest.mark.parametrize("key", ["desired_goal", ("next", "achieved_goal")])
def test_a_missing_goal_key_is_named(key):
    episodes = labelled_episodes(2)
    del episodes[key]
    her = HindsightRelabel(sparse_reward)
    rb = make_replay_buffer(None, her, capacity=10 * T)
    rb.extend(episodes)
    with pytest.raises(KeyError) as in_the_buffer:
        rb.sample()
    with pytest.raises(KeyError) as in_a_relabelling:
        her.relabel(episodes, torch.tensor([0, 1]), torch.tensor([3, 4]))
    for error in (in_the_buffer, in_a_relabelling):
        assert re.search(rf"no key {re.escape(repr(key))}.*present keys", error.value.args[0])


def test_the_stored_goals_success_flag_is_dropped_from_a_drawn_batch_or_kept_on_request():
    episodes = labelled_episodes(4)
    episodes["next", "is_success"] = torch.zeros(4, T, 1)  # the stored goal's success
    dropped = make_replay_buffer(None, HindsightRelabel(sparse_reward, future_p=1.0), capacity=10 * T, batch_size=256)
    dropped.extend(episodes)
    batch = dropped.sample()
    assert ("next", "is_success") not in batch.keys(True, True)
    assert (batch["next", "reward"] == 0).any()  # relabelled goals are reached: the stored flag would say otherwise
    kept = make_replay_buffer(None, HindsightRelabel(sparse_reward, future_p=1.0, success_key=None), capacity=10 * T,
                              batch_size=256)
    kept.extend(episodes)
    assert (kept.sample()["next", "is_success"] == 0).all()  # as stored


def flat_sparse_reward(achieved_goal, desired_goal):  # gymnasium-robotics' compute_reward: [B], float64
    return -(torch.linalg.vector_norm(achieved_goal - desired_goal, dim=-1) > 0.05).double()


def test_a_reward_fn_returning_one_reward_per_transition_gets_the_stored_rewards_shape_and_dtype():
    flat, kept = (make_replay_buffer(None, HindsightRelabel(reward, future_p=1.0), capacity=10 * T, batch_size=64)
                  for reward in (flat_sparse_reward, sparse_reward))
    for rb in (flat, kept):
        rb.extend(make_episodes(3))
        rb.set_rng(torch.Generator().manual_seed(0))
    batch = flat.sample()
    assert batch["next", "reward"].shape == (64, 1) and batch["next", "reward"].dtype == torch.float32
    assert torch.equal(batch["next", "reward"], kept.sample()["next", "reward"])  # the same draw, the same rewards
    her = HindsightRelabel(flat_sparse_reward, future_p=1.0)  # relabel() outside a buffer: the same
    entries = her.relabel(make_episodes(2), torch.tensor([0, 1, 1]), torch.tensor([0, 5, 9]))
    assert entries[("next", "reward")].shape == (3, 1) and entries[("next", "reward")].dtype == torch.float32


@pytest.mark.parametrize(("reward_fn", "message"), [
    (lambda ag, g: torch.zeros(ag.shape[0], 2), "returned a reward of shape [64, 2] for 64 transitions, whose stored "
     "('next', 'reward') has shape [64, 1]: return one reward per transition"),
    (lambda ag, g: torch.zeros(ag.shape[0], 1, dtype=torch.bool), "returned torch.bool rewards, whose stored "
     "('next', 'reward') is torch.float32: return float rewards"),
])
def test_a_reward_fn_whose_rewards_cannot_take_the_stored_shape_or_dtype_is_refused(reward_fn, message):
    rb = make_replay_buffer(None, HindsightRelabel(reward_fn), capacity=10 * T, batch_size=64)
    rb.extend(make_episodes(3))
    with pytest.raises(ValueError, match=re.escape(message)):
        rb.sample()


def test_her_over_a_flat_storage_is_refused_naming_the_episode_storage_it_needs():
    her = HindsightRelabel(sparse_reward)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * T), sampler=SliceSampler(slice_len=10), batch_size=20,
                                sample_unit=her, collate_fn=her.collate)
    rb.extend(make_episodes(3).reshape(-1))  # frames one after another, as a flat buffer holds them
    with pytest.raises(ValueError, match=re.escape("needs an episode storage of [episode, t] rows (ndim=2), got "
                                                   "LazyTensorStorage with ndim=1: use EpisodeStorage(capacity)")):
        rb.sample()
