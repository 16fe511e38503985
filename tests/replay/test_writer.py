"""EpisodeWriter: a collector's frames, in any layout, become whole episode rows; rows that cannot be episodes are refused."""
import functools
import itertools

import pytest
import torch
from torchrl.collectors import Collector, MultiAsyncCollector, MultiSyncCollector
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs import TransformedEnv

from tests.replay.conftest import T, make_episodes, restore, sparse_reward
from tests.replay.test_episodes import EndAboveHeight
from torchrl_cebp.envs import make_env
from torchrl_cebp.replay import EpisodeStorage, EpisodeWriter, HindsightRelabel, episode_lengths, make_replay_buffer
from torchrl_cebp.replay.samplers import CEBPSampler

TRAJECTORY = ("collector", "traj_ids")


def buffer(rows=40, writer=None, dim_extend=0):
    return TensorDictReplayBuffer(storage=EpisodeStorage(rows * T), writer=writer or EpisodeWriter(T),
                                  dim_extend=dim_extend, batch_size=64)


def collected(env, frames_per_batch, batches):
    torch.manual_seed(0)  # the random actions
    collector = Collector(env, None, frames_per_batch=frames_per_batch, total_frames=-1,
                          auto_register_policy_transforms=False)
    collector.set_seed(0)
    iterator = iter(collector)
    out = [next(iterator) for _ in range(batches)]
    collector.shutdown()
    return out


def stored_episodes(rb):
    episodes = rb.storage.get(slice(None))
    return episodes, episode_lengths(episodes)


def assert_whole_episodes(rb):
    """Every row is one episode: each step starts where the last one ended, and it stops at its one end flag."""
    episodes, lengths = stored_episodes(rb)
    for episode, length in zip(episodes, lengths.tolist()):
        assert torch.equal(episode["next", "observation"][: length - 1], episode["observation"][1:length])
        assert episode["next", "done"][:length].sum() == 1 and episode["next", "done"][length - 1]


def assert_each_trajectory_stored_whole(rb, batches):
    """Each trajectory that ended is one row, holding its frames in their order; the others wait."""
    frames = torch.cat([batch.reshape(-1) for batch in batches])
    ended = frames[TRAJECTORY][frames["next", "done"].squeeze(-1)]
    episodes, lengths = stored_episodes(rb)
    assert sorted(episodes[TRAJECTORY][:, 0].tolist()) == sorted(ended.tolist())
    for episode, length in zip(episodes, lengths.tolist()):
        own = frames[frames[TRAJECTORY] == episode[TRAJECTORY][0]]
        assert own.shape[0] == length
        for key in ("observation", "action", ("next", "achieved_goal")):
            assert torch.equal(episode[key][:length], own[key])


@pytest.mark.parametrize("num_envs, frames_per_batch, batches", [(None, 70, 4), (2, 2 * 30, 5)], ids=["flat", "envs"])
def test_collector_frames_become_whole_episodes_across_batches(num_envs, frames_per_batch, batches):
    batches_ = collected(make_env("push", seed=0, num_envs=num_envs), frames_per_batch, batches)
    rb = buffer()
    for batch in batches_:
        rb.extend(batch)
    assert rb.storage.shape[1] == T and len(rb) == T * (frames_per_batch * batches // T)
    assert_whole_episodes(rb)
    assert_each_trajectory_stored_whole(rb, batches_)


# cat_results=0 yields one flat [frames] batch: the envs' frames one after another, told apart by trajectory id.
@pytest.mark.parametrize("collector_class", [MultiSyncCollector, MultiAsyncCollector,
                                             functools.partial(MultiSyncCollector, cat_results=0)],
                         ids=["sync", "async", "sync-flat"])
def test_env_processes_fill_one_prioritised_buffer_that_the_learner_extends(collector_class):
    # The supported way to collect in other processes: they yield frames, and the process that draws extends the
    # buffer, so that its sampler scores every episode. Their episodes run across batches and interleave.
    collector = collector_class([functools.partial(make_env, "push", seed=seed) for seed in (0, 1)], None,
                                frames_per_batch=2 * 30, total_frames=-1, auto_register_policy_transforms=False)
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward, future_p=1.0), capacity=40 * T,
                            batch_size=64, writer=EpisodeWriter(T))
    batches = []
    try:
        for batch in itertools.islice(collector, 6):
            rb.extend(batch)
            batches.append(batch.clone())  # the collector may write its next batch into the same memory
    finally:
        collector.shutdown()
    assert rb.storage.shape[0] >= 2 and rb.sampler.n_episodes == rb.storage.shape[0]
    assert_whole_episodes(rb)
    assert_each_trajectory_stored_whole(rb, batches)
    drawn = rb.sample()
    assert drawn["priority_weight"].shape == (64,) and set(drawn["next", "reward"].unique().tolist()) <= {-1.0, 0.0}


def test_episodes_that_end_early_in_collector_batches():
    env = TransformedEnv(make_env("push", seed=0, num_envs=4), EndAboveHeight(0.5))
    batches = collected(env, 4 * 20, 6)
    rb = buffer()
    for batch in batches:
        rb.extend(batch)
    lengths = stored_episodes(rb)[1]
    assert (lengths < T).any()
    assert_whole_episodes(rb)
    assert_each_trajectory_stored_whole(rb, batches)


def test_nodes_of_batched_envs_are_lanes():
    rollouts = torch.stack([make_env("push", seed=seed, num_envs=3).rollout(T) for seed in (0, 10)])  # [2, 3, T]
    rb = buffer()
    index = rb.extend(rollouts)
    assert rb.storage.shape == (6, T)
    assert torch.equal(rb.storage.get(slice(None))["observation"], rollouts["observation"].reshape(6, T, -1))
    assert index.shape == (2, 3, T) and torch.equal(index.flatten(), torch.arange(6 * T))


def test_the_index_says_where_each_frame_went_and_minus_one_while_it_waits():
    env = TransformedEnv(make_env("push", seed=0, num_envs=3), EndAboveHeight(0.5))
    torch.manual_seed(0)  # the random actions
    frames = env.rollout(T, break_when_any_done=False)
    rb = buffer()
    index = rb.extend(frames)
    stored = index >= 0
    assert stored.any() and not stored.all()  # ended episodes, and the ones still running
    flat = rb.storage.get(slice(None)).reshape(-1)
    assert torch.equal(flat["observation"][index[stored]], frames["observation"][stored])


def test_a_rollout_after_a_rollout_drops_the_cut_episodes_instead_of_merging_them():
    env = TransformedEnv(make_env("push", seed=0, num_envs=4), EndAboveHeight(0.5))
    torch.manual_seed(0)
    rb = buffer()
    for _ in range(3):  # no trajectory ids: lanes; each rollout starts with a reset
        rb.extend(env.rollout(T, break_when_any_done=False))
    assert len(rb) > 0
    assert_whole_episodes(rb)


@pytest.mark.parametrize("how", ["state_dict", "dumps"])
def test_waiting_frames_survive_a_save_and_load(how, tmp_path):
    batches = collected(make_env("push", seed=0, num_envs=2), 2 * 30, 4)
    straight, saved, restored = buffer(), buffer(), buffer()
    for batch in batches:
        straight.extend(batch.clone())
    for batch in batches[:2]:
        saved.extend(batch.clone())
    restore(saved, restored, how, tmp_path)
    for batch in batches[2:]:
        restored.extend(batch.clone())
    assert (restored.storage.get(slice(None)) == straight.storage.get(slice(None))).all()


def test_emptying_the_buffer_drops_the_waiting_frames():
    batches = collected(make_env("push", seed=0, num_envs=2), 2 * 30, 1)
    rb = buffer()
    rb.extend(batches[0])
    assert len(rb.state_dict()["_writer"]["partial_episodes"]) == 2
    rb.empty()
    assert rb.state_dict()["_writer"]["partial_episodes"] == {}


def test_a_batch_transposed_by_the_buffer_is_refused_with_the_fix():
    rollout = make_env("push", seed=0, num_envs=12).rollout(T)  # [12, 50], time last
    for writer in (None, EpisodeWriter(T)):
        rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), writer=writer, batch_size=8)  # dim_extend=1
        with pytest.raises(ValueError, match=r"\[50, 12\].*'time' dimension at 0.*dim_extend=0"):
            rb.extend(rollout.clone())


def test_several_episodes_in_one_row_are_refused_with_the_fix():
    batch = collected(make_env("push", seed=0), 1000, 1)[0].unsqueeze(0)  # [1, 1000]: 20 episodes in a row
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), dim_extend=0, batch_size=8)
    with pytest.raises(ValueError, match=r"row 0 of the batch of shape \[1, 1000\] holds 20 episode ends.*EpisodeWriter"):
        rb.extend(batch)
    with pytest.raises(ValueError, match=r"\[1000\].*EpisodeWriter"):  # the frames as the collector gave them
        rb.extend(batch[0])
    buffer().extend(batch)  # what the message says works


def test_an_episode_longer_than_the_rows_is_refused():
    rb = buffer(writer=EpisodeWriter(30))
    with pytest.raises(ValueError, match=r"\[2, 50\] runs 50 steps.*max_episode_steps=30"):
        rb.extend(make_episodes(2))  # 50-step episodes


def test_whole_episode_rows_are_written_as_they_are():
    episodes = make_episodes(3)
    written = buffer()
    written.extend(episodes.clone())
    reference = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), dim_extend=0)
    reference.extend(episodes.clone())
    assert (written.storage.get(slice(None)) == reference.storage.get(slice(None))).all()
