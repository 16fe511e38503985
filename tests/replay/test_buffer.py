"""Episode storage and buffer: wrap-around, checkpoints, and errors that name the key."""
from pathlib import Path

import numpy as np
import pytest
import torch
from torchrl.data import RoundRobinWriter

from tests.modules import load_module
from tests.replay.conftest import PUSH_WORKSPACE, T, make_episodes, restore, sparse_reward
from tests.replay.test_her import decode, labelled_episodes
from torchrl_cebp.replay import EpisodeReplayBuffer, EpisodeStorage, HindsightRelabel, make_replay_buffer
from torchrl_cebp.replay.samplers import CEBPSampler, InitialCEBPSampler, ReleasedCEBPSampler, CPERSampler, EBPSampler, MEPSampler, PERSampler, UniformEpisodeSampler

SAMPLERS = {  # each built for a buffer of the given capacity
    "uniform": lambda capacity: UniformEpisodeSampler(),
    "cebp": lambda capacity: CEBPSampler(),
    "cebp_released": lambda capacity: ReleasedCEBPSampler(workspace=PUSH_WORKSPACE),
    "cebp_initial": lambda capacity: InitialCEBPSampler(workspace=PUSH_WORKSPACE),
    "cper": lambda capacity: CPERSampler(),
    "ebp": lambda capacity: EBPSampler(),
    "mep": lambda capacity: MEPSampler(),
    "per": PERSampler,
}


@pytest.mark.parametrize("kind", ["tensor", "memmap"])
@pytest.mark.parametrize("name", sorted(SAMPLERS))
def test_wrap_around_keeps_episodes_whole_and_priorities_fresh(name, kind, tmp_path):
    sampler = SAMPLERS[name](5 * T)
    rb = make_replay_buffer(sampler, HindsightRelabel(sparse_reward, future_p=1.0), capacity=5 * T, batch_size=4096,
                            storage=kind, scratch_dir=str(tmp_path / "scratch"))
    for first in range(0, 8, 2):  # 8 episodes into 5 rows, two at a time
        rb.extend(labelled_episodes(2, first_id=first))
    stored_ids = rb.storage[torch.arange(5)]["achieved_goal"][..., 0]
    assert torch.equal(stored_ids, torch.tensor([5.0, 6, 7, 3, 4])[:, None].expand(5, T))
    if isinstance(sampler, MEPSampler):
        sampler.refit(rb.storage)
    batch = rb.sample()
    episode, state = decode(batch["desired_goal"])
    assert set(episode.tolist()) <= {3, 4, 5, 6, 7}
    assert torch.equal(episode, decode(batch["achieved_goal"])[0])
    assert (state > batch["index"][:, 1]).all()
    if hasattr(sampler, "probabilities"):
        fresh = make_replay_buffer(SAMPLERS[name](5 * T), HindsightRelabel(sparse_reward), capacity=5 * T)
        fresh.extend(rb.storage[torch.arange(5)])
        if isinstance(sampler, MEPSampler):
            fresh.sampler.refit(fresh.storage)
        rows = torch.arange(5)
        torch.testing.assert_close(sampler.probabilities(rows), fresh.sampler.probabilities(rows))


@pytest.mark.parametrize("kind", ["tensor", "memmap"])
@pytest.mark.parametrize("name", sorted(SAMPLERS))
def test_save_load_then_draw_gives_the_same_batches(name, kind, tmp_path):
    def new_buffer(scratch):
        return make_replay_buffer(SAMPLERS[name](20 * T), HindsightRelabel(sparse_reward), capacity=20 * T,
                                  batch_size=64, storage=kind, scratch_dir=str(tmp_path / scratch))

    def filled():
        rb = new_buffer("saved")
        rb.extend(make_episodes(12, seed=3))
        if isinstance(rb.sampler, MEPSampler):
            rb.sampler.refit(rb.storage)
        return rb

    def draws(rb):
        torch.manual_seed(11)
        np.random.seed(11)
        return [rb.sample() for _ in range(3)]

    original = filled()
    original.dumps(tmp_path / "dump")
    expected = draws(original)
    restored = new_buffer("restored")
    restored.loads(tmp_path / "dump")
    got = draws(restored)
    for a, b in zip(expected, got):
        assert torch.equal(a["index"], b["index"])
        assert torch.equal(a["desired_goal"], b["desired_goal"])
        assert (a == b).all()
    restored.extend(make_episodes(2, seed=9))  # the restored buffer keeps writing where it stopped
    assert len(restored) == 14 * T


def test_sampler_state_dict_round_trip_without_pickled_code(tmp_path):
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=20 * T)
    rb.extend(make_episodes(5))
    torch.save(rb.sampler.state_dict(), tmp_path / "s.pt")
    sampler = CEBPSampler()
    sampler.load_state_dict(torch.load(tmp_path / "s.pt", weights_only=True))
    torch.testing.assert_close(sampler.probabilities(torch.arange(5)), rb.sampler.probabilities(torch.arange(5)))


@pytest.mark.parametrize(
    "sampler, key, shape",
    [
        (lambda: CEBPSampler(), ("next", "touch"), "[n_episodes, T, 2]"),
        (lambda: ReleasedCEBPSampler(workspace=PUSH_WORKSPACE), ("next", "observation"), "[n_episodes, T, *]"),
        (CPERSampler, ("next", "touch"), "[n_episodes, T, 2]"),
        (EBPSampler, ("next", "achieved_goal"), "[n_episodes, T, 3]"),
    ],
)
def test_missing_key_is_named_with_its_expected_shape(sampler, key, shape):
    data = make_episodes(2)
    del data[key]
    rb = make_replay_buffer(sampler(), HindsightRelabel(sparse_reward), capacity=10 * T)
    with pytest.raises(KeyError) as error:
        rb.extend(data)
    message = error.value.args[0]
    assert str(key) in message and shape in message


def test_misshaped_key_is_named_with_its_expected_shape():
    data = make_episodes(2)
    data["next", "touch"] = torch.zeros(2, T, 3)
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=10 * T)
    with pytest.raises(ValueError, match=r"\('next', 'touch'\).*\[2, 50, 3\].*\[n_episodes, T, 2\]"):
        rb.extend(data)


def test_episodes_of_another_length_are_refused():
    rb = make_replay_buffer(None, HindsightRelabel(sparse_reward), capacity=10 * T)
    rb.extend(make_episodes(2))
    with pytest.raises(ValueError, match="70 steps.*50-step"):
        rb.extend(make_episodes(1, length=70))


def test_bad_storage_kind_lists_the_valid_ones():
    with pytest.raises(ValueError, match="'ssd'.*memmap.*tensor"):
        make_replay_buffer(None, HindsightRelabel(sparse_reward), storage="ssd")


def test_memmap_storage(tmp_path):
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=10 * T, storage="memmap", scratch_dir=str(tmp_path), batch_size=32)
    rb.extend(make_episodes(3))
    assert rb.sample()["priority_weight"].shape == (32,)


def test_per_state_dict_loads_with_weights_only(tmp_path):
    rb = make_replay_buffer(PERSampler(10 * T), HindsightRelabel(sparse_reward), capacity=10 * T, batch_size=16)
    rb.extend(make_episodes(3))
    batch = rb.sample()
    batch.set("td_error", torch.linspace(0.1, 5.0, 16))
    rb.update_tensordict_priority(batch)
    torch.save(rb.sampler.state_dict(), tmp_path / "per.pt")
    restored = PERSampler(10 * T)
    restored.load_state_dict(torch.load(tmp_path / "per.pt", weights_only=True))
    assert restored.beta == rb.sampler.beta
    every = torch.arange(10 * T)
    assert torch.equal(torch.as_tensor(restored._sum_tree[every]), torch.as_tensor(rb.sampler._sum_tree[every]))


def test_prefetched_batches_are_relabelled_in_their_own_threads():
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward, future_p=1.0), capacity=10 * T,
                            batch_size=512, prefetch=3)
    rb.extend(labelled_episodes(4))
    for _ in range(6):  # the first draw fills the queue; the next ones come from the prefetching threads
        batch = rb.sample()
        episode, state = decode(batch["desired_goal"])
        assert torch.equal(episode, decode(batch["achieved_goal"])[0])
        assert (state > batch["index"][:, 1]).all()


def test_writer_and_sharing_reach_the_buffer():
    writer = RoundRobinWriter()
    rb = make_replay_buffer(None, HindsightRelabel(sparse_reward), capacity=10 * T, writer=writer, shared=True)
    rb.extend(make_episodes(3))
    assert rb.writer is writer and rb.write_count == 3
    assert rb.shared


def test_pin_memory_pins_the_batches():
    rb = make_replay_buffer(None, HindsightRelabel(sparse_reward), capacity=10 * T, batch_size=8, pin_memory=True)
    rb.extend(make_episodes(2))
    if not torch.cuda.is_available():
        with pytest.raises(RuntimeError, match="NVIDIA driver"):  # pinning needs one: the option reached the buffer
            rb.sample()
        return
    assert rb.sample()["observation"].is_pinned()


@pytest.mark.parametrize("name", ["cebp", "per"])
@pytest.mark.parametrize("saved_rows, rows", [(20, 10), (10, 20)])
@pytest.mark.parametrize("how", ["state_dict", "dumps"])
def test_a_state_of_another_capacity_is_refused_with_the_capacity_it_needs(name, saved_rows, rows, how, tmp_path):
    saved = make_replay_buffer(SAMPLERS[name](saved_rows * T), HindsightRelabel(sparse_reward), capacity=saved_rows * T)
    saved.extend(make_episodes(5))
    other = make_replay_buffer(SAMPLERS[name](rows * T), HindsightRelabel(sparse_reward), capacity=rows * T)
    expected = rf"holds {saved_rows} episodes of {T} steps.*this one {rows}.*capacity={saved_rows * T}"
    with pytest.raises(ValueError, match=expected):
        restore(saved, other, how, tmp_path)


@pytest.mark.parametrize("how", ["state_dict", "dumps"])
def test_a_capacity_that_is_not_whole_episodes_resumes_and_wraps_as_before(how, tmp_path):
    # 70-step Slide in 1e6 transitions: TorchRL rounds the rows up (here 4.5 rows of T give 5) on the first write.
    capacity = 4 * T + T // 2

    def buffer():
        return make_replay_buffer(SAMPLERS["cebp_initial"](capacity), HindsightRelabel(sparse_reward), capacity=capacity)

    saved = buffer()
    saved.extend(labelled_episodes(4))
    restored = buffer()
    restore(saved, restored, how, tmp_path)
    assert restored.storage.max_size == saved.storage.max_size == 5 * T
    for rb in (saved, restored):
        rb.extend(labelled_episodes(3, first_id=4))  # rows 4, 0, 1: the restored buffer wraps where the saved one does
        stored_ids = rb.storage[torch.arange(5)]["achieved_goal"][..., 0]
        assert torch.equal(stored_ids, torch.tensor([5.0, 6, 2, 3, 4])[:, None].expand(5, T))


def test_a_per_smaller_than_its_storage_rounded_to_whole_episodes_is_refused_at_the_first_write():
    capacity = 4 * T + T // 2  # the storage rounds it up to 5 rows on the first write; the sum tree cannot grow
    rb = make_replay_buffer(PERSampler(capacity), HindsightRelabel(sparse_reward), capacity=capacity)
    with pytest.raises(ValueError, match=rf"holds {capacity} transitions, but its storage holds {5 * T} .*capacity={5 * T}"):
        rb.extend(make_episodes(2))


# The benchmark's reader, so that the test and the benchmark measure memory alike.
_resident_mib = load_module(Path(__file__).resolve().parents[2] / "benchmarks" / "replay_memory.py").resident_mib


@pytest.mark.parametrize("how", ["written", "restored"])
def test_the_rows_not_yet_filled_take_no_memory(how):
    # A storage of ~600 MiB holding 2 episodes, as a run's 8e6-transition replay (replay.capacity_per=worker) starts
    # out: only the written rows may become resident, after a write or after a restore from a checkpoint's state.
    episodes = make_episodes(2)
    transition_bytes = sum(leaf[0, 0].numel() * leaf.element_size() for leaf in episodes.values(True, True))
    capacity = (600 * 2**20 // transition_bytes // T) * T

    def buffer():
        return make_replay_buffer(None, HindsightRelabel(sparse_reward), capacity=capacity, batch_size=64)

    saved = buffer()
    before = _resident_mib()
    saved.extend(episodes)
    if how == "restored":
        state = saved.state_dict()
        restored = buffer()
        before = _resident_mib()
        restored.load_state_dict(state)
        saved = restored
    saved.sample()
    added = _resident_mib() - before
    assert added < 60, f"{added:.0f} MiB resident for 2 episodes"
    assert saved.storage.max_size == capacity and len(saved) == 2 * T


def test_a_write_that_never_finished_stops_the_draws_with_how_to_recover():
    rb = EpisodeReplayBuffer(storage=EpisodeStorage(4 * T), dim_extend=0, batch_size=8)
    rb.extend(make_episodes(2))
    rb.storage.write_counts[-1] += 1  # a writer killed between the start and the end of its write
    rb.write_timeout_s = 0.2
    with pytest.raises(RuntimeError, match=r"stayed odd \(3\) for over 0.2 s.*died mid-write.*from a checkpoint"):
        rb.sample()
    recovered = EpisodeReplayBuffer(storage=EpisodeStorage(4 * T), dim_extend=0, batch_size=8)
    recovered.load_state_dict(rb.state_dict())
    assert recovered.sample()["observation"].shape == (8, 25)


def test_an_unknown_storage_kind_is_refused_with_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown storage kind 'disk'; valid kinds: \['memmap', 'tensor'\]"):
        make_replay_buffer(None, HindsightRelabel(sparse_reward), capacity=4 * T, storage="disk")


@pytest.mark.filterwarnings("ignore:Got conflicting batch_sizes")  # TorchRL's, for a draw of another size
@pytest.mark.parametrize("name", sorted(SAMPLERS))
def test_a_draw_of_no_transitions_is_an_empty_batch_as_torchrls_samplers_give(name):
    rb = make_replay_buffer(SAMPLERS[name](10 * T), HindsightRelabel(sparse_reward), capacity=10 * T)
    rb.extend(make_episodes(3))
    batch = rb.sample(0)
    assert batch.shape == (0,) and batch["observation"].shape == (0, 25) and batch["next", "reward"].shape == (0, 1)
