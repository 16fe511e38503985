"""Baselines' per-worker replay: routing, per-worker draws and IS weights, equivalence for uniform HER, state."""
import copy
import pickle

import numpy as np
import pytest
import torch
from scipy.stats import chi2_contingency
from torchrl.data import PrioritizedSampler, RandomSampler, TensorDictReplayBuffer
from torchrl.data.replay_buffers.scheduler import LinearScheduler

from tests.replay.conftest import PUSH_WORKSPACE, T, make_episodes, sparse_reward
from tests.replay.test_samplers import ScoredByValue, hand_made, np_initial_cebp, valued
from torchrl_cebp.replay import EpisodeReplayBuffer, EpisodeStorage, HindsightRelabel, make_replay_buffer
from torchrl_cebp.replay.samplers import (
    InitialCEBPSampler,
    MEPSampler,
    PERSampler,
    PerWorkerSampler,
    UniformEpisodeSampler,
    WorkerLayout,
    WorkerRows,
)

WORKERS, PER_WORKER = 4, 2  # 8 episodes a cycle: worker w's envs are 2w and 2w + 1
CYCLE = WORKERS * PER_WORKER
LOW, HIGH = np.array([1.05, 0.4, 0.4]), np.array([1.55, 1.11, np.inf])


def initial_cebp_workers(workers=WORKERS):
    return PerWorkerSampler(*[InitialCEBPSampler(workspace=PUSH_WORKSPACE) for _ in range(workers)],
                            episodes_per_worker=PER_WORKER)


def cycles(n_cycles):
    return torch.cat([hand_made(CYCLE, seed=s) for s in range(n_cycles)])


def test_each_worker_gets_its_own_envs_episodes_and_draws_its_share_of_the_batch():
    sampler = initial_cebp_workers()
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * CYCLE * T), sampler=sampler, dim_extend=0, batch_size=64)
    for data in cycles(3).split(CYCLE):
        rb.extend(data)
    assert [shard.n_episodes for shard in sampler.samplers] == [3 * PER_WORKER] * WORKERS
    rows = rb.sample()["index"][:, 0]
    worker_of_row = rows % CYCLE // PER_WORKER
    assert worker_of_row.tolist() == sum(([w] * 16 for w in range(WORKERS)), [])


def test_the_layout_maps_rows_to_workers_and_back_and_counts_uneven_shares():
    layout = WorkerLayout(workers=8, episodes_per_worker=2)
    rows = torch.tensor([0, 3, 17])
    workers = layout.worker_of(rows)
    assert workers.tolist() == [0, 1, 0]
    assert layout.global_rows(layout.local_rows(rows), workers).tolist() == [0, 3, 17]
    assert [layout.rows_of_worker(14286, w) for w in (0, 7)] == [1786, 1784]  # 70-step Slide's rows: uneven


def test_worker_rows_read_only_that_workers_episodes():
    storage = EpisodeStorage(4 * CYCLE * T)
    data = cycles(2)
    storage.set(torch.arange(2 * CYCLE), data)
    view = WorkerRows(storage, worker=3, layout=WorkerLayout(WORKERS, PER_WORKER))
    assert view.shape == (4, T) and view.max_size == 8 * T and len(view) == 4 * T
    expected = data[torch.tensor([6, 7, 14, 15])]
    assert (view.get(slice(None)) == expected).all()
    assert (view.get(torch.tensor([2, 0])) == expected[torch.tensor([2, 0])]).all()


def test_importance_weights_are_normalised_within_each_workers_draw():
    sampler = initial_cebp_workers(workers=2)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(1200 * T), sampler=sampler, dim_extend=0, batch_size=1024)
    data = torch.cat([hand_made(4, seed=s) for s in range(150)])  # 300 episodes per worker, past the 256 warm-up
    rb.extend(data)
    batch = rb.sample()
    priority = np_initial_cebp(data, LOW, HIGH)
    for part in batch.split(512):
        p = priority[part["index"][:, 0].numpy()]
        w = p ** -0.7
        np.testing.assert_allclose(part["priority_weight"].numpy(), w / w.max(), rtol=1e-5)
        assert part["priority_weight"].max() == 1.0


def test_weights_switch_on_at_256_episodes_per_worker_not_in_all():
    data = torch.cat([hand_made(4, seed=s) for s in range(75)])  # 300 episodes: 150 per worker of 2
    merged = TensorDictReplayBuffer(storage=EpisodeStorage(1200 * T), sampler=InitialCEBPSampler(workspace=PUSH_WORKSPACE),
                                    dim_extend=0, batch_size=512)
    per_worker = TensorDictReplayBuffer(storage=EpisodeStorage(1200 * T), sampler=initial_cebp_workers(workers=2),
                                        dim_extend=0, batch_size=512)
    merged.extend(data)
    per_worker.extend(data)
    assert merged.sample()["priority_weight"].min() < 0.5
    assert torch.equal(per_worker.sample()["priority_weight"], torch.ones(512))


def test_uniform_her_draws_the_merged_buffers_distribution():
    """Chi-square homogeneity of the episode and step counts of the two layouts (both are uniform)."""
    data = cycles(12)
    draws = {}
    for layout in ("merged", "per_worker"):
        sampler = (UniformEpisodeSampler() if layout == "merged"
                   else PerWorkerSampler(*[UniformEpisodeSampler() for _ in range(WORKERS)], episodes_per_worker=PER_WORKER))
        her = HindsightRelabel(sparse_reward, future_p=0.8)
        rb = make_replay_buffer(sampler, her, capacity=12 * CYCLE * T, batch_size=2048,
                                generator=torch.Generator().manual_seed(1 if layout == "merged" else 2))
        rb.extend(data)
        draws[layout] = torch.cat([rb.sample()["index"] for _ in range(20)])
    for column, bins in ((0, 12 * CYCLE), (1, T)):
        table = np.stack([np.bincount(draws[layout][:, column].numpy(), minlength=bins) for layout in draws])
        assert chi2_contingency(table).pvalue > 1e-3, table


def per_workers(capacity):
    return PerWorkerSampler(*[PERSampler(capacity // WORKERS, beta_anneal_draws=10) for _ in range(WORKERS)],
                            episodes_per_worker=PER_WORKER)


def test_per_shards_route_td_errors_and_anneal_together():
    capacity = 8 * CYCLE * T
    sampler = per_workers(capacity)
    rb = make_replay_buffer(sampler, HindsightRelabel(sparse_reward), capacity=capacity, batch_size=32)
    for _ in range(4):
        rb.extend(make_episodes(CYCLE))  # 400 transitions per worker
    batch = rb.sample()
    batch["td_error"] = torch.zeros(32)
    batch["td_error"][:8] = 1e6  # 8 of worker 0's transitions
    rb.update_tensordict_priority(batch)
    hot = {tuple(pair) for pair in batch["index"][:8].tolist()}
    drawn = torch.cat([rb.sample()["index"][:8] for _ in range(20)]).tolist()
    # uniform draws would hit these 8 of worker 0's 400 transitions 2% of the time
    assert sum(tuple(pair) in hot for pair in drawn) / len(drawn) > 0.9
    # and the other workers, all of whose drawn errors were 0, now avoid their drawn transitions
    cold = {tuple(pair) for pair in batch["index"][8:].tolist()}
    drawn_elsewhere = torch.cat([rb.sample()["index"][8:] for _ in range(20)]).tolist()
    assert not any(tuple(pair) in cold for pair in drawn_elsewhere)
    scheduler = LinearScheduler(sampler, "beta", final_value=1.0, num_steps=10)
    for _ in range(10):
        scheduler.step()
    assert [shard.beta for shard in sampler.samplers] == pytest.approx([1.0] * WORKERS)


def test_torchrls_tensordict_priority_update_reaches_every_per_shard():
    sampler = per_workers(4 * CYCLE * T)
    assert isinstance(sampler, PrioritizedSampler)  # what TorchRL's update_tensordict_priority feeds
    rb = make_replay_buffer(sampler, HindsightRelabel(sparse_reward), capacity=4 * CYCLE * T, batch_size=32)
    rb.extend(make_episodes(CYCLE))
    batch = rb.sample()
    batch["td_error"] = torch.full((32,), 1e6)
    rb.update_tensordict_priority(batch)
    assert [float(shard["max_priority"]) for shard in sampler.state_dict()["shards"]] == [1e6] * WORKERS


def test_a_per_worker_sampler_of_pers_answers_every_public_attribute_of_a_prioritized_sampler():
    sampler = per_workers(4 * CYCLE * T)
    public = [name for name in dir(PrioritizedSampler) if not name.startswith("_")]
    for name in public:  # every one TorchRL or a user may read of a PrioritizedSampler
        getattr(sampler, name)
    assert (sampler.max_size, sampler.alpha, sampler.device) == (4 * CYCLE * T, 0.6, torch.device("cpu"))
    sampler.alpha = 0.7
    assert [shard.alpha for shard in sampler.samplers] == [0.7] * WORKERS


@pytest.mark.parametrize("make_shard", [RandomSampler, lambda: PrioritizedSampler(2 * CYCLE * T // WORKERS, 0.6, 0.4)])
def test_torchrls_stock_samplers_work_as_the_workers_samplers(make_shard):
    sampler = PerWorkerSampler(*[make_shard() for _ in range(WORKERS)], episodes_per_worker=PER_WORKER)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(2 * CYCLE * T), sampler=sampler, dim_extend=0, batch_size=64,
                                priority_key="td_error")
    rb.extend(cycles(2))
    batch = rb.sample()
    worker_of_row = batch["index"][:, 0] % CYCLE // PER_WORKER
    assert worker_of_row.tolist() == sum(([w] * 16 for w in range(WORKERS)), [])
    if isinstance(sampler, PrioritizedSampler):
        batch["td_error"] = torch.zeros(64)
        batch["td_error"][:16] = 1e6  # worker 0's draw
        rb.update_tensordict_priority(batch)
        hot = {tuple(pair) for pair in batch["index"][:16].tolist()}
        drawn = rb.sample()["index"][:16].tolist()
        assert sum(tuple(pair) in hot for pair in drawn) > 12


def test_a_write_that_does_not_deal_out_to_the_workers_is_refused_and_stores_nothing():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), sampler=initial_cebp_workers(), dim_extend=0, batch_size=8)
    with pytest.raises(ValueError, match=rf"write a multiple of {CYCLE} episodes at a time.*got 3"):
        rb.extend(make_episodes(3))
    assert len(rb) == 0
    rb.extend(make_episodes(CYCLE))
    with pytest.raises(ValueError, match=rf"write a multiple of {CYCLE} episodes at a time.*got 3"):
        rb.sampler.mark_update(torch.arange(3), storage=rb.storage)  # as a storage without the check reports


def test_a_per_shard_smaller_than_its_workers_rows_is_refused():
    sampler = PerWorkerSampler(PERSampler(10 * T), PERSampler(10 * T))
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), sampler=sampler, dim_extend=0, batch_size=4)
    with pytest.raises(ValueError, match="worker 0's PERSampler holds 500 transitions, but the worker owns 1000"):
        rb.extend(make_episodes(2))



def test_a_storage_with_fewer_rows_than_a_write_deals_out_is_refused_with_the_capacity_it_needs():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(7 * T), sampler=initial_cebp_workers(), dim_extend=0, batch_size=8)
    with pytest.raises(ValueError, match=rf"4 workers of episodes_per_worker=2 take {CYCLE} episode rows a write, but "
                                         rf"the storage has 7: give it a capacity of at least {CYCLE * T} transitions"):
        rb.extend(make_episodes(CYCLE))


@pytest.mark.parametrize("make_shard", [UniformEpisodeSampler, lambda: PERSampler(4 * T)], ids=["uniform", "per"])
def test_a_per_worker_sampler_reused_over_a_second_storage_is_refused_unless_given_its_state(make_shard):
    sampler = PerWorkerSampler(make_shard(), make_shard())
    first, second = (TensorDictReplayBuffer(storage=EpisodeStorage(8 * T), sampler=sampler, dim_extend=0, batch_size=8)
                     for _ in range(2))
    first.extend(make_episodes(4))
    first.sample()
    with pytest.raises(ValueError, match="rows of another storage, not of this EpisodeStorage: use one sampler per buffer"):
        second.extend(make_episodes(2, seed=1))
    second.load_state_dict(first.state_dict())  # restored from a state, it takes the storage it meets
    assert set(second.sample()["index"][:, 0].tolist()) <= set(range(4))



@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_per_worker_buffer_scores_the_writes_into_its_own_storage(how):
    sampler = PerWorkerSampler(ScoredByValue(), ScoredByValue())
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(6 * T), sampler=sampler, dim_extend=0, batch_size=4)
    rb.extend(valued(1, 2))
    rb.sample()
    copied = copy.deepcopy(rb) if how == "deepcopy" else pickle.loads(pickle.dumps(rb))
    copied.extend(valued(3, 4))
    copied.sample()
    assert [shard.state_dict()["priorities"][:2].tolist() for shard in copied.sampler.samplers] == [[1, 3], [2, 4]]
    assert sampler.n_episodes == 2

def test_the_per_worker_beta_schedule_is_one_scheduler_whose_step_states_and_copies_keep():
    def build():
        rb = make_replay_buffer(per_workers(4 * CYCLE * T), HindsightRelabel(sparse_reward), capacity=4 * CYCLE * T)
        rb.extend(make_episodes(CYCLE))
        return rb

    original, restored = build(), build()
    held = restored.sampler.beta_scheduler()  # as the trainer holds it, from before the restore
    for _ in range(4):
        original.sampler.beta_scheduler().step()
    restored.load_state_dict(original.state_dict())
    copies = [restored, copy.deepcopy(original), pickle.loads(pickle.dumps(original))]
    for rb in [original, *copies]:
        for _ in range(3):
            rb.sampler.beta_scheduler().step()
        rb.sample()  # every worker draws with the schedule's beta
    assert restored.sampler.beta_scheduler() is held
    betas = [shard.beta for rb in [original, *copies] for shard in rb.sampler.samplers]
    assert betas == pytest.approx([0.4 + 0.6 * 7 / 10] * 4 * WORKERS)


def test_mep_refits_each_worker_on_its_own_episodes():
    sampler = PerWorkerSampler(*[MEPSampler(seed=w) for w in range(2)])
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(100 * T), sampler=sampler, dim_extend=0, batch_size=8)
    rb.extend(make_episodes(40))
    sampler.refit(rb.storage)
    assert all(shard.n_episodes == 20 for shard in sampler.samplers)


@pytest.mark.parametrize("make_shard", [lambda: InitialCEBPSampler(workspace=PUSH_WORKSPACE), lambda: PERSampler(6 * CYCLE * T // WORKERS)])
def test_state_and_files_restore_every_worker_and_the_same_draws(tmp_path, make_shard):
    def build():
        sampler = PerWorkerSampler(*[make_shard() for _ in range(WORKERS)], episodes_per_worker=PER_WORKER)
        return make_replay_buffer(sampler, HindsightRelabel(sparse_reward), capacity=6 * CYCLE * T, batch_size=64,
                                  generator=torch.Generator().manual_seed(0))

    original = build()
    for data in cycles(3).split(CYCLE):
        original.extend(data)
    from_state, from_files = build(), build()
    from_state.load_state_dict(original.state_dict())
    original.dumps(tmp_path)
    from_files.loads(tmp_path)
    assert [p.name for p in tmp_path.joinpath("sampler").iterdir()] == ["sampler_state.pt"]  # one file, all workers
    for rb in (from_state, from_files):
        rb.set_rng(torch.Generator().manual_seed(5))
    original.set_rng(torch.Generator().manual_seed(5))
    expected = original.sample()["index"]
    assert torch.equal(from_state.sample()["index"], expected)
    assert torch.equal(from_files.sample()["index"], expected)


def test_a_state_of_another_worker_layout_is_refused():
    saved = initial_cebp_workers(workers=2).state_dict()
    with pytest.raises(ValueError, match="the saved replay has 2 workers of 2 episodes per cycle; this PerWorkerSampler has 4 of 2"):
        initial_cebp_workers().load_state_dict(saved)


def test_a_batch_that_does_not_split_over_the_workers_is_refused():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), sampler=initial_cebp_workers(), dim_extend=0, batch_size=30)
    rb.extend(make_episodes(CYCLE))
    with pytest.raises(ValueError, match="batch_size=30 must be a multiple of workers=4"):
        rb.sample()


def test_one_sampler_instance_for_two_workers_is_refused():
    shared = UniformEpisodeSampler()
    with pytest.raises(ValueError, match="separate sampler instance"):
        PerWorkerSampler(shared, shared)


def _extend(rb, episodes):
    rb.extend(episodes)


def test_the_workers_score_the_episodes_a_spawned_process_writes():
    # Sent to a spawned process with a shared EpisodeStorage, the buffer's writes there reach every worker's sampler.
    sampler = PerWorkerSampler(UniformEpisodeSampler(), UniformEpisodeSampler(), episodes_per_worker=PER_WORKER)
    rb = make_replay_buffer(sampler, HindsightRelabel(sparse_reward), capacity=8 * T, batch_size=512, shared=True)
    rb.extend(hand_made(4, seed=0))  # rows 0-3: two episodes per worker
    child = torch.multiprocessing.get_context("spawn").Process(target=_extend, args=(rb, hand_made(4, seed=1)))
    child.start()
    child.join(timeout=120)
    assert child.exitcode == 0
    rows = rb.sample()["index"][:, 0]
    assert set(rows.tolist()) == set(range(8))  # rows 4-7, written in the child, are drawn too
    assert (rows[:256] % 4 < 2).all() and (rows[256:] % 4 >= 2).all()  # each worker from its own rows
    assert [shard.n_episodes for shard in sampler.samplers] == [4, 4]


def test_a_write_into_none_of_a_workers_rows_after_the_wrap_keeps_it_drawing():
    # 5 rows, not a multiple of the 2-episode cycle: the third write wraps to rows 4 and 0, both worker 0's
    # (rows 0, 2, 4; worker 1 has rows 1 and 3), so worker 1 sees the write count change but none of its rows.
    sampler = PerWorkerSampler(ScoredByValue(), ScoredByValue())
    rb = EpisodeReplayBuffer(storage=EpisodeStorage(5 * T), sampler=sampler, dim_extend=0, batch_size=4)
    for values in [(1, 2), (3, 4), (5, 6)]:
        rb.extend(valued(*values))
        rb.sample()
    assert [shard.state_dict()["priorities"].tolist() for shard in sampler.samplers] == [[6, 3, 5], [2, 4]]
    rb.extend(valued(7, 8))  # rows 1 and 2: one of each worker's, scored at the next draw
    rb.sample()
    assert [shard.state_dict()["priorities"].tolist() for shard in sampler.samplers] == [[6, 8, 5], [7, 4]]


@pytest.mark.parametrize("make_shard", [UniformEpisodeSampler, lambda: PERSampler(8 * T)], ids=["uniform", "per"])
def test_an_empty_per_worker_buffer_refuses_a_draw_in_torchrl_words(make_shard):
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(16 * T), sampler=PerWorkerSampler(make_shard(), make_shard()),
                                dim_extend=0, batch_size=4)
    with pytest.raises(RuntimeError, match="Cannot sample from an empty storage"):
        rb.sample()
