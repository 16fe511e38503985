"""Pins every private TorchRL / tensordict attribute the package reaches (torchrl_cebp/_upstream.py).

Each test fails, by name, if an upgrade moves or changes one of them.
"""
import numpy as np
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, PrioritizedSampler, RandomSampler, TensorDictReplayBuffer

from tests.replay.conftest import T, make_episodes
from torchrl_cebp import _upstream
from torchrl_cebp.replay import EpisodeStorage
from torchrl_cebp.replay.samplers import UniformEpisodeSampler, WorkerLayout, WorkerRows


def test_the_buffer_generator_reaches_the_storage():
    generator = torch.Generator().manual_seed(0)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * T, ndim=2), dim_extend=0, batch_size=4,
                                generator=generator)
    rb.extend(make_episodes(2))
    assert _upstream.buffer_generator(rb.storage) is generator
    other = torch.Generator()
    rb.set_rng(other)
    assert _upstream.buffer_generator(rb.storage) is other


def test_the_buffer_generator_reaches_the_sampler_and_none_means_the_global_rng():
    sampler = UniformEpisodeSampler()
    generator = torch.Generator().manual_seed(0)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(10 * T), sampler=sampler, dim_extend=0, batch_size=4,
                                generator=generator)
    assert _upstream.sampler_generator(sampler) is generator
    other = torch.Generator()
    rb.set_rng(other)
    assert _upstream.sampler_generator(sampler) is other
    TensorDictReplayBuffer(storage=EpisodeStorage(10 * T), sampler=sampler, dim_extend=0, batch_size=4)
    assert _upstream.sampler_generator(sampler) is None  # a buffer without a generator clears it


def test_torchrls_random_sampler_draws_a_storage_view_with_the_buffers_generator():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(4 * T), dim_extend=0, batch_size=4)
    rb.extend(make_episodes(4))
    view = WorkerRows(rb.storage, worker=1, layout=WorkerLayout(workers=2))  # an _upstream.StorageView: 2 rows
    rb.set_rng(torch.Generator().manual_seed(0))
    rows, steps = RandomSampler().sample(view, 100)[0]
    generator = torch.Generator().manual_seed(0)
    assert torch.equal(rows, torch.randint(2, (100,), generator=generator))
    assert torch.equal(steps, torch.randint(T, (100,), generator=generator))


def test_the_storage_state_keeps_the_stored_tensordict_under_its_key():
    storage = LazyTensorStorage(10 * T, ndim=2)
    storage.set(torch.arange(2), make_episodes(2))
    saved = TensorDict().load_state_dict(storage.state_dict()[_upstream.STORAGE_STATE_KEY], strict=False)
    # Rows 2-9 were never written: torch.empty memory, which may hold NaN, so NaN must equal NaN here.
    torch.testing.assert_close(
        saved["action"], _upstream.stored_tensordict(storage)["action"], rtol=0, atol=0, equal_nan=True
    )


def test_the_buffer_state_keeps_the_storage_state_under_its_key():
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * T, ndim=2), dim_extend=0, batch_size=4)
    rb.extend(make_episodes(2))
    assert rb.state_dict()[_upstream.BUFFER_STORAGE_KEY].keys() == rb.storage.state_dict().keys()


def test_a_saved_buffer_names_its_writers_next_row_and_count():
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(3 * T, ndim=2), dim_extend=0, batch_size=4)
    for _ in range(5):
        rb.extend(make_episodes(1))
    assert _upstream.round_robin_position(rb.state_dict()) == (2, 5)


def test_the_stored_tensordict_is_what_the_storage_reads_and_writes():
    storage = LazyTensorStorage(10 * T, ndim=2)
    storage.set(torch.arange(2), make_episodes(2))
    stored = _upstream.stored_tensordict(storage)
    assert stored.shape == torch.Size([10, T])
    assert stored["action"].data_ptr() == storage.get(slice(None))["action"].data_ptr()
    replacement = stored.clone()
    replacement["action"].fill_(7.0)
    _upstream.replace_stored_tensordict(storage, replacement)
    assert (storage.get((torch.tensor([1]), torch.tensor([3])))["action"] == 7.0).all()
    storage.set(torch.tensor([0]), make_episodes(1, seed=5))
    assert torch.equal(replacement["action"][0], make_episodes(1, seed=5)["action"][0])


def test_an_unchecked_tensordict_equals_a_checked_one():
    source = {"a": torch.ones(4, 2), "b": torch.zeros(4), "next": {"a": torch.full((4, 2), 2.0)}}
    built = _upstream.unchecked_tensordict(source, torch.Size([4]), torch.device("cpu"))
    assert (built == TensorDict(source, [4])).all()
    nested = built.get("next")  # the episode storage's read hands nested dicts over as they are
    assert isinstance(nested, TensorDict) and nested.batch_size == torch.Size([4])
    assert nested.device == torch.device("cpu")
    assert list(built.keys(True, True)) == ["a", "b", ("next", "a")]


def prioritized_buffer() -> TensorDictReplayBuffer:
    """Three episodes under TorchRL's prioritized sampler, with priorities updated once."""
    sampler = PrioritizedSampler(10 * T, alpha=0.7, beta=0.5)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * T, ndim=2), sampler=sampler, dim_extend=0,
                                batch_size=64, priority_key="td_error")
    rb.extend(make_episodes(3))
    batch = rb.sample()
    batch.set("td_error", torch.linspace(0.0, 3.0, 64))
    rb.update_tensordict_priority(batch)
    return rb


def test_a_prioritized_sampler_round_trips_through_plain_tensors():
    rb = prioritized_buffer()
    state = _upstream.prioritized_state(rb.sampler)
    assert all(isinstance(v, (torch.Tensor, float)) for v in state.values() if v is not None)
    copy = PrioritizedSampler(10 * T, alpha=0.1, beta=0.1)
    _upstream.load_prioritized_state(copy, state)
    assert (copy.alpha, copy.beta) == (0.7, 0.5)
    every = torch.arange(10 * T)
    assert torch.equal(torch.as_tensor(copy._sum_tree[every]), torch.as_tensor(rb.sampler._sum_tree[every]))
    storage = rb.storage
    np.random.seed(0)  # TorchRL's prioritized draw uses numpy's global RNG when the buffer has no generator
    expected = rb.sampler.sample(storage, 256)
    np.random.seed(0)
    got = copy.sample(storage, 256)
    assert all(torch.equal(a, b) for a, b in zip(expected[0], got[0]))  # (rows, steps)
    assert torch.equal(expected[1]["priority_weight"], got[1]["priority_weight"])
    assert [float(v) for v in copy._max_priority] == [float(v) for v in rb.sampler._max_priority]
    fresh = torch.arange(3 * T, 4 * T)  # new transitions enter at the restored running maximum
    for sampler in (rb.sampler, copy):
        sampler.mark_update(fresh)
    assert torch.equal(torch.as_tensor(copy._sum_tree[fresh]), torch.as_tensor(rb.sampler._sum_tree[fresh]))
    assert (torch.as_tensor(copy._sum_tree[fresh]) > 0).all()


def test_torchrls_own_prioritized_state_reads_as_the_plain_one():
    rb = prioritized_buffer()
    ours, theirs = _upstream.prioritized_state(rb.sampler), _upstream.prioritized_state_of(rb.sampler.state_dict())
    assert ours.keys() == theirs.keys()
    for key, value in ours.items():
        assert torch.equal(torch.as_tensor(value), torch.as_tensor(theirs[key])), key


def test_excluded_transitions_are_never_drawn():
    sampler = PrioritizedSampler(4 * T, alpha=0.6, beta=0.4)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(4 * T, ndim=2), sampler=sampler, dim_extend=0,
                                batch_size=20_000)
    rb.extend(make_episodes(2))
    excluded = torch.arange(10, 2 * T)  # all of row 0 past step 10, and all of row 1
    _upstream.exclude_from_draws(sampler, excluded)
    flat = rb.sample()["index"]
    flat = flat[:, 0] * T + flat[:, 1]
    assert (flat < 10).all()


def test_a_round_robin_writers_position_reads_back_and_restores():
    # RoundRobinWriter has no public cursor setter: a refused write must leave the writer where it was.
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10), batch_size=2)
    before = _upstream.writer_position(rb.writer)
    rb.extend(TensorDict({"x": torch.zeros(3)}, [3]))
    assert [int(v) for v in _upstream.writer_position(rb.writer)] == [3, 3]
    _upstream.restore_writer_position(rb.writer, before)
    rb.extend(TensorDict({"x": torch.ones(2)}, [2]))
    assert [int(v) for v in _upstream.writer_position(rb.writer)] == [2, 2]
    assert rb.storage[0]["x"] == 1  # the next write went where the restored cursor pointed


def test_a_recorded_write_leaves_the_storage_as_torchrls_own_write_does():
    written, recorded = LazyTensorStorage(8 * T, ndim=2), LazyTensorStorage(8 * T, ndim=2)
    first = TensorDict({"x": torch.zeros(2, T)}, [2, T])
    for storage in (written, recorded):
        storage.set(torch.arange(2), first)
    more, cursor = TensorDict({"x": torch.ones(3, T)}, [3, T]), torch.arange(2, 5)
    written.set(cursor, more)
    _upstream.record_write(recorded, cursor, more, set_cursor=True)
    assert len(recorded) == len(written) == 5 * T
    assert recorded.shape == written.shape
    assert int(recorded._last_cursor[-1]) == int(written._last_cursor[-1]) == 4
    assert recorded._mutation_revision == written._mutation_revision


def test_every_draw_of_a_buffer_goes_through_its_sample_hook():
    # EpisodeReplayBuffer redraws inside TorchRL's private ``_sample``, which sample() and the prefetching threads
    # call; nothing public wraps one draw.
    class Counting(TensorDictReplayBuffer):
        calls = 0

        def _sample(self, batch_size):
            Counting.calls += 1
            return super()._sample(batch_size)

    rb = Counting(storage=LazyTensorStorage(100), batch_size=4, prefetch=2)
    rb.extend(TensorDict({"x": torch.arange(10.0)}, [10]))
    for _ in range(3):
        rb.sample()
    assert Counting.calls >= 3


def test_a_generator_given_to_a_sampler_drives_its_draws_as_the_buffers_does():
    # TorchRL's PrioritizedSampler draws with the generator its buffer gave it.
    by_buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(100), sampler=PrioritizedSampler(100, 0.6, 0.4),
                                       batch_size=8, generator=torch.Generator().manual_seed(3))
    given = TensorDictReplayBuffer(storage=LazyTensorStorage(100), sampler=PrioritizedSampler(100, 0.6, 0.4),
                                   batch_size=8)
    _upstream.give_sampler_generator(given.sampler, torch.Generator().manual_seed(3))
    for rb in (by_buffer, given):
        rb.extend(TensorDict({"x": torch.arange(50.0)}, [50]))
    for _ in range(3):
        assert torch.equal(by_buffer.sample()["index"], given.sample()["index"])
