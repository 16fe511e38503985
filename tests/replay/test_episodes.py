"""Episodes that end before their row: no padding drawn, no goal past the end, priorities blind to the padding."""
import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage
from torchrl.envs import Transform, TransformedEnv

from tests.replay.conftest import T, sparse_reward
from tests.replay.test_buffer import SAMPLERS
from tests.replay.test_her import decode, labelled_episodes
from torchrl_cebp.envs import make_env
from torchrl_cebp.envs.layout import FETCH_OBSERVATION
from torchrl_cebp.replay import EpisodeStorage, EpisodeWriter, HindsightRelabel, episode_lengths, make_replay_buffer
from torchrl_cebp.replay.episodes import (
    common_length,
    end_flags,
    next_key,
    require_time_at,
    shared_length,
    stored_lengths,
    valid_steps,
)
from torchrl_cebp.replay.samplers import (
    CEBPSampler,
    MEPSampler,
    PERSampler,
    UniformEpisodeSampler,
)



def ending_early(n, lengths, first_id=0, padding="garbage"):
    """Labelled episodes whose ``("next", "done")`` comes at ``lengths``; after it, ``padding``."""
    episodes = labelled_episodes(n, first_id=first_id)
    episodes["next", "done"][:] = False
    for row, length in enumerate(lengths):
        episodes["next", "done"][row, length - 1] = True
        if padding == "garbage":  # what an auto-reset env leaves there: another episode, touching hard
            tail = slice(length, T)
            episodes["next", "touch"][row, tail] = 50.0
            episodes["next", "achieved_goal"][row, tail] = torch.rand(T - length, 3) + 5.0
            episodes["next", "observation"][row, tail, :3] = torch.tensor([1.3, 0.75, 0.5])
    return episodes


@pytest.mark.parametrize("name", sorted(SAMPLERS))
def test_no_padding_drawn_and_no_goal_past_the_end_with_wrap_around(name):
    sampler = SAMPLERS[name](6 * T)
    rb = make_replay_buffer(sampler, HindsightRelabel(sparse_reward, future_p=1.0), capacity=6 * T, batch_size=4096)
    rb.extend(ending_early(4, [50, 7, 30, 1]))
    rb.extend(ending_early(4, [12, 50, 3, 40], first_id=4))  # rows 0 and 1 overwritten by shorter/longer episodes
    lengths_by_episode = {0: 50, 1: 7, 2: 30, 3: 1, 4: 12, 5: 50, 6: 3, 7: 40}
    if isinstance(sampler, MEPSampler):
        sampler.refit(rb.storage)
    for _ in range(3):
        batch = rb.sample()
        episode, state = decode(batch["desired_goal"])
        steps = batch["index"][:, 1]
        length = torch.tensor([lengths_by_episode[e] for e in episode.tolist()])
        assert (steps < length).all(), "a padding step was drawn"
        assert (state >= steps + 1).all() and (state <= length).all(), "a goal came from past the episode's end"
        assert set(episode.tolist()) <= {2, 3, 4, 5, 6, 7} and len(set(episode.tolist())) >= 4
        # the one-step episode's only transition has its final state as goal
        assert (state[episode == 3] == 1).all()
    if hasattr(sampler, "probabilities"):  # ...and it stays drawable
        assert sampler.probabilities(torch.tensor([3]))[0] > 0  # row 3 holds it


@pytest.mark.parametrize("name", sorted(SAMPLERS))
def test_episodes_of_one_shared_short_length_then_mixed_lengths(name):
    # Draws take a cheaper path while every stored episode has the same length: it must still stop there.
    sampler = SAMPLERS[name](4 * T)
    rb = make_replay_buffer(sampler, HindsightRelabel(sparse_reward, future_p=1.0), capacity=4 * T, batch_size=4096)
    rb.extend(ending_early(4, [9, 9, 9, 9]))
    if isinstance(sampler, MEPSampler):
        sampler.refit(rb.storage)
    batch = rb.sample()
    episode, state = decode(batch["desired_goal"])
    assert batch["index"][:, 1].max() == 8 and state.max() == 9
    rb.extend(ending_early(1, [50], first_id=4))  # row 0: now one long episode among short ones
    if isinstance(sampler, MEPSampler):
        sampler.refit(rb.storage)
    # MEP may rank the long episode lowest (about one draw in 6,000): draw until it came often enough.
    batches = []
    while sum(int((decode(b["desired_goal"])[0] == 4).sum()) for b in batches) < 20 and len(batches) < 100:
        batches.append(rb.sample())
    batch = torch.cat(batches)
    episode, state = decode(batch["desired_goal"])
    steps = batch["index"][:, 1]
    long_episode = episode == 4
    assert (steps[~long_episode] < 9).all() and (state[~long_episode] <= 9).all()
    assert steps[long_episode].max() > 9


@pytest.mark.parametrize("name", ["cebp", "cebp_released", "cebp_initial", "cper", "ebp", "mep"])
def test_priorities_ignore_the_padding(name):
    lengths = [50, 20, 35, 10, 44, 27]
    def priorities(padding):
        rb = make_replay_buffer(SAMPLERS[name](10 * T), HindsightRelabel(sparse_reward), capacity=10 * T)
        episodes = ending_early(6, lengths, padding=padding)
        episodes["next", "touch"][:, :, :] += torch.linspace(0, 1, 6)[:, None, None]  # episodes differ
        rb.extend(episodes)
        if isinstance(rb.sampler, MEPSampler):
            rb.sampler.refit(rb.storage)
        return rb.sampler.probabilities(torch.arange(6))

    clean, garbage = priorities("none"), priorities("garbage")
    torch.testing.assert_close(garbage, clean)


def test_per_gives_padding_probability_zero():
    rb = make_replay_buffer(PERSampler(6 * T), HindsightRelabel(sparse_reward), capacity=6 * T, batch_size=8192)
    rb.extend(ending_early(3, [5, 50, 2]))
    index = rb.sample()["index"]
    length = torch.tensor([5, 50, 2])[index[:, 0]]
    assert (index[:, 1] < length).all()


class EndAboveHeight(Transform):
    """Ends an episode once the gripper rises above ``height``: a real env that terminates early."""

    def __init__(self, height: float) -> None:
        super().__init__()
        self.height = height

    def _step(self, tensordict, next_tensordict):
        gripper = next_tensordict["observation"][..., FETCH_OBSERVATION.gripper_position]
        high = gripper[..., 2:3] > self.height
        next_tensordict.set("terminated", next_tensordict["terminated"] | high)
        next_tensordict.set("done", next_tensordict["done"] | high)
        return next_tensordict


def test_a_fetch_env_that_ends_early_is_replayed_within_its_episodes():
    env = TransformedEnv(make_env("push", num_envs=8), EndAboveHeight(0.5))
    env.set_seed(0)
    torch.manual_seed(0)  # the random actions
    frames = env.rollout(T, break_when_any_done=False)  # ended envs auto-reset: a lane runs on into its next episode
    env.close()
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(env.base_env.compute_reward, future_p=1.0),
                            capacity=20 * T, batch_size=4096, writer=EpisodeWriter(T))
    rb.extend(frames)
    episodes = rb.storage.get(slice(None))  # the episodes that ended, one a row
    lengths = episode_lengths(episodes)
    assert (lengths < T).any() and (lengths == T).any()
    batch = rb.sample()
    rows, steps = batch["index"].unbind(-1)
    assert (steps < lengths[rows]).all()
    # each relabelled goal is the achieved goal of a next-state in [t, L - 1] of its own episode
    achieved = episodes["next", "achieved_goal"][rows]  # [B, T, 3]
    match = (achieved == batch["desired_goal"][:, None]).all(-1)  # [B, T]
    j = torch.arange(T)
    allowed = (j >= steps[:, None]) & (j < lengths[rows][:, None])
    assert (match & allowed).any(-1).all()
    np.testing.assert_array_equal(
        batch["next", "reward"].numpy(),
        env.base_env.compute_reward(batch["next", "achieved_goal"], batch["desired_goal"]).numpy(),
    )


def test_valid_lengths_survive_a_save_and_load(tmp_path):
    def buffer():
        return make_replay_buffer(UniformEpisodeSampler(), HindsightRelabel(sparse_reward, future_p=1.0),
                                  capacity=6 * T, batch_size=4096)

    rb = buffer()
    rb.extend(ending_early(3, [9, 50, 4]))
    rb.dumps(tmp_path)
    restored = buffer()
    restored.loads(tmp_path)
    restored.extend(ending_early(1, [20], first_id=3))  # a write after the restore keeps the restored lengths
    batch = restored.sample()
    episode, state = decode(batch["desired_goal"])
    length = torch.tensor([9, 50, 4, 20])[episode]
    assert (batch["index"][:, 1] < length).all() and (state <= length).all()
    assert torch.equal(restored.storage.valid_lengths(torch.arange(4)), torch.tensor([9, 50, 4, 20]))


@pytest.mark.parametrize("older", [False, True])
def test_a_sampler_state_leaves_the_lengths_to_the_storage_and_older_states_still_load(older):
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=6 * T, batch_size=4096)
    rb.extend(ending_early(3, [9, 50, 4]))
    state = rb.sampler.state_dict()
    assert "lengths" not in state  # the storage keeps them, and answers every sampler
    if older:  # as the states of earlier versions held them
        state["lengths"] = torch.tensor([9, 50, 4, 0, 0, 0])
    restored = CEBPSampler()
    restored.load_state_dict(state)
    rows, steps = restored.sample(rb.storage, 4096)[0]
    assert (steps < torch.tensor([9, 50, 4])[rows]).all()
    rb.sampler.load_state_dict(state)
    rb.extend(ending_early(3, [5, 6, 7], first_id=3))
    assert rb.storage.valid_lengths(torch.arange(6)).tolist() == [9, 50, 4, 5, 6, 7]
    rows, steps = rb.sample()["index"].unbind(-1)
    assert (steps < torch.tensor([9, 50, 4, 5, 6, 7])[rows]).all()


def test_the_row_helpers_read_flags_lengths_and_time_as_documented():
    done = torch.zeros(2, 4, 1, dtype=torch.bool)
    done[0, 1] = True
    rows = TensorDict({"next": {"done": done}}, [2, 4])
    assert next_key("achieved_goal") == ("next", "achieved_goal") and next_key(("a", "b")) == ("next", "a", "b")
    assert end_flags(rows).int().tolist() == [[0, 1, 0, 0], [0, 0, 0, 0]] and end_flags(rows, "absent") is None
    storage = LazyTensorStorage(8, ndim=2)  # not an episode storage: read at the rows' flags
    storage.set(torch.arange(2), rows)
    assert stored_lengths(storage, torch.tensor([1, 0])).tolist() == [4, 2] and shared_length(storage) is None
    episode_storage_ = EpisodeStorage(4 * T)
    whole = torch.zeros(2, T, 1, dtype=torch.bool)
    episode_storage_.set(torch.arange(2), TensorDict({"next": {"done": whole}}, [2, T]))
    assert shared_length(episode_storage_) == T and shared_length(episode_storage_, "other") is None
    assert valid_steps(torch.tensor([2, 4]), 4).int().tolist() == [[1, 1, 0, 0], [1, 1, 1, 1]]
    assert common_length(torch.tensor([50, 50])) == 50 and common_length(torch.tensor([50, 7])) is None
    assert common_length(torch.tensor([], dtype=torch.long)) is None


def test_require_time_at_blames_the_buffer_or_the_layout_and_reads_dim_extends_only_to_refuse():
    frames = TensorDict(batch_size=[12, 50], names=[None, "time"])
    require_time_at(frames, 1, dim_extends=lambda: pytest.fail("read without an error"))
    causes = {(1,): "the buffer transposed it.*dim_extend=0$", (0,): "the batch is laid out with time first.*"
              r"batch.transpose\(0, 1\)$", (): "either the buffer transposed it.*, or the batch is laid out"}
    for dim_extends, cause in causes.items():
        for given in (dim_extends, lambda: dim_extends):
            with pytest.raises(ValueError, match=rf"shape \[50, 12\] has its 'time' dimension at 0, not 1: {cause}"):
                require_time_at(frames.transpose(0, 1), 1, given)
