"""Each sampler's episode frequencies and weights against the formulas, computed by hand."""
import copy
import functools
import pickle
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.stats import chisquare, rankdata
from tensordict import TensorDict
from torchrl.collectors import MultiAsyncCollector, MultiSyncCollector
from torchrl.data import LazyTensorStorage, PrioritizedSampler, RandomSampler, TensorDictReplayBuffer

from tests.replay.conftest import PUSH_WORKSPACE, T, make_episodes, restore, sparse_reward
from tests.replay.test_buffer import SAMPLERS
from torchrl_cebp.envs import make_env
from torchrl_cebp.replay import EpisodeMemmapStorage, EpisodeStorage, EpisodeWriter, HindsightRelabel, episode_lengths, make_replay_buffer
from torchrl_cebp.replay.episodes import valid_steps
from torchrl_cebp.replay.samplers import (
    CEBPSampler,
    InitialCEBPSampler,
    ReleasedCEBPSampler,
    CPERSampler,
    EBPSampler,
    EpisodePrioritySampler,
    MEPSampler,
    PERSampler,
    UniformEpisodeSampler,
)

N_EPISODES = 6


def hand_made(n=N_EPISODES, seed=0):
    """Episodes whose touch and object motion differ a lot between episodes."""
    g = torch.Generator().manual_seed(seed)
    steps = torch.arange(T + 1, dtype=torch.float32)
    positions = torch.zeros(n, T + 1, 3)
    touch = torch.zeros(n, T, 2)
    for e in range(n):
        speed = 0.002 * e
        positions[e, :, 0] = 1.3 + speed * steps
        positions[e, :, 1] = 0.75
        positions[e, :, 2] = 0.42 + (0.004 * e * steps.clamp(max=20) if e % 2 else 0.0)
        touch[e, 10 * (e % 3):, :] = 0.05 * e * torch.rand(T - 10 * (e % 3), 2, generator=g)
    gripper = positions.clone()
    gripper[2::3, :, 1] = 0.2  # outside the released workspace box
    return make_episodes(n, touch=touch, positions=positions, gripper=gripper, seed=seed)


@pytest.fixture(params=["tensor", "memmap"])
def either_storage(request, tmp_path):
    """A fresh episode storage of 50 rows, in memory or memory-mapped: the samplers draw the same from either."""
    if request.param == "tensor":
        return EpisodeStorage(50 * T)
    return EpisodeMemmapStorage(50 * T, scratch_dir=str(tmp_path / "scratch"))


def buffer(sampler, n=N_EPISODES, storage=None):
    storage = EpisodeStorage(50 * T) if storage is None else storage
    rb = TensorDictReplayBuffer(storage=storage, sampler=sampler, dim_extend=0, batch_size=4096)
    data = hand_made(n)
    rb.extend(data)
    return rb, data


def counts(rb, draws=60):
    torch.manual_seed(0)
    np.random.seed(0)
    rows = torch.cat([rb.sample()["index"][:, 0] for _ in range(draws)])
    return np.bincount(rows.numpy(), minlength=N_EPISODES)


def pooled(observed, expected, least=5.0):
    """The bins with ``expected`` counts under ``least`` pooled into one (joined by the next smallest while the pool
    is still under it): the chi-square statistic is only chi-square distributed for expected counts of 5 or more."""
    order = np.argsort(expected)
    observed, expected = observed[order].astype(np.float64), expected[order]
    small = int(np.searchsorted(np.cumsum(expected), least, side="left")) + 1 if expected[0] < least else 0
    small = min(small, len(expected))
    if small <= 1:
        return observed, expected
    return (np.concatenate([[observed[:small].sum()], observed[small:]]),
            np.concatenate([[expected[:small].sum()], expected[small:]]))


def assert_frequencies(observed, probabilities):
    probabilities = np.asarray(probabilities, dtype=np.float64)
    probabilities /= probabilities.sum()
    expected = probabilities * observed.sum()
    keep = expected > 0
    assert observed[~keep].sum() == 0
    observed, expected = pooled(observed[keep], expected[keep])
    assert len(expected) > 1 and chisquare(observed, expected).pvalue > 1e-3, (observed, expected)


def assert_not_uniform(observed):
    """The draws a uniform sampler would not give: a frequency test that can fail."""
    assert chisquare(observed).pvalue < 1e-6, observed


def test_pooling_keeps_every_count_and_leaves_no_bin_under_5():
    observed, expected = pooled(np.array([1, 40, 0, 59]), np.array([0.5, 45.0, 2.0, 52.5]))
    assert observed.sum() == 100 and expected.sum() == 100.0 and expected.min() >= 5
    assert expected.tolist() == [47.5, 52.5]


def np_paper_cebp(data, k, temperature):
    touch = data["next", "touch"].double().numpy().sum(-1)
    pos = np.concatenate([data["achieved_goal"][:, :1].double().numpy(), data["next", "achieved_goal"].double().numpy()], 1)
    dist = np.linalg.norm(np.diff(pos, axis=1), axis=-1)
    c = np.cumsum(touch * dist, axis=1)
    return (k / (1 + np.exp(-temperature * c))).sum(1)


def np_released_cebp(data, k, low, high):
    touch = data["next", "touch"].double().numpy().sum(-1)
    pos = np.concatenate([data["achieved_goal"][:, :1].double().numpy(), data["next", "achieved_goal"].double().numpy()], 1)
    disp = np.diff(pos, axis=1)
    grip = data["next", "observation"][..., :3].double().numpy()
    mask = np.all((grip >= low) & (grip <= high), -1)
    energy = np.cumsum(disp * touch[..., None], axis=1) * mask[..., None]
    x = energy.sum(-1) * np.linalg.norm(disp, axis=-1)
    s = 100 / (1 + np.exp(-k * x)) - 50
    return np.abs(s).sum(1) + np.finfo(np.float32).eps


def test_uniform_frequencies(either_storage):
    rb, _ = buffer(UniformEpisodeSampler(), storage=either_storage)
    assert_frequencies(counts(rb), np.ones(N_EPISODES))


@pytest.mark.parametrize("temperature", [0.01, 5.0, 50.0])
def test_cebp_paper_frequencies_and_weights(temperature, either_storage):
    sampler = CEBPSampler(temperature=temperature, beta=0.7)
    rb, data = buffer(sampler, storage=either_storage)
    priority = np_paper_cebp(data, 100.0, temperature)
    if temperature > 0.01:
        # At 0.01 the hand-made energies (a few units) leave every sigmoid near k/2: the priorities differ by under
        # 1%, which no frequency test of this size tells from uniform. Only the weights (below) test them.
        observed = counts(rb)
        assert_frequencies(observed, priority)
        assert_not_uniform(observed)
    batch = rb.sample()
    p = priority[batch["index"][:, 0].numpy()] / priority.sum()
    w = (N_EPISODES * p) ** -0.7
    np.testing.assert_allclose(batch["priority_weight"].numpy(), w / w.max(), rtol=1e-5)


def test_cebp_released_frequencies_and_weights(either_storage):
    sampler = ReleasedCEBPSampler(workspace=PUSH_WORKSPACE)
    rb, data = buffer(sampler, storage=either_storage)
    priority = np_released_cebp(data, 0.1, np.array([1.05, 0.4, 0.4]), np.array([1.55, 1.11, np.inf]))
    assert len(set(np.round(priority, 6))) > 3  # the hand-made episodes are told apart
    assert_frequencies(counts(rb), priority)
    # fewer than 256 stored episodes: the released code uses no IS correction yet
    assert torch.equal(rb.sample()["priority_weight"], torch.ones(4096))


def test_cebp_released_weights_after_warmup():
    sampler = ReleasedCEBPSampler(workspace=PUSH_WORKSPACE)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(300 * T), sampler=sampler, dim_extend=0, batch_size=512)
    data = torch.cat([hand_made(6, seed=s) for s in range(50)])
    rb.extend(data)
    priority = np_released_cebp(data, 0.1, np.array([1.05, 0.4, 0.4]), np.array([1.55, 1.11, np.inf]))
    batch = rb.sample()
    p = priority[batch["index"][:, 0].numpy()]
    np.testing.assert_allclose(batch["priority_weight"].numpy(), p.min() / p, rtol=1e-5)


def np_initial_cebp(data, low, high):
    touch = data["next", "touch"].double().numpy().sum(-1)
    pos = np.concatenate([data["achieved_goal"][:, :1].double().numpy(), data["next", "achieved_goal"].double().numpy()], 1)
    distance = np.linalg.norm(np.diff(pos, axis=1), axis=-1)
    grip = data["next", "observation"][..., :3].double().numpy()
    mask = np.all((grip >= low) & (grip <= high), -1)
    return np.abs(touch * mask * distance).sum(1) + np.finfo(np.float32).eps


def test_cebp_initial_frequencies_and_weights(either_storage):
    rb, data = buffer(InitialCEBPSampler(workspace=PUSH_WORKSPACE), storage=either_storage)
    priority = np_initial_cebp(data, np.array([1.05, 0.4, 0.4]), np.array([1.55, 1.11, np.inf]))
    assert len(set(np.round(priority, 6))) > 3
    assert_frequencies(counts(rb), priority)
    assert torch.equal(rb.sample()["priority_weight"], torch.ones(4096))


def test_cebp_initial_weights_after_warmup():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(300 * T), sampler=InitialCEBPSampler(workspace=PUSH_WORKSPACE), dim_extend=0,
                                batch_size=512)
    data = torch.cat([hand_made(6, seed=s) for s in range(50)])
    rb.extend(data)
    priority = np_initial_cebp(data, np.array([1.05, 0.4, 0.4]), np.array([1.55, 1.11, np.inf]))
    batch = rb.sample()
    p = priority[batch["index"][:, 0].numpy()]
    w = p ** -0.7
    np.testing.assert_allclose(batch["priority_weight"].numpy(), w / w.max(), rtol=1e-5)


def test_cper_episode_and_step_frequencies(either_storage):
    sampler = CPERSampler(threshold=1.0, lam=10.0)
    rb, data = buffer(sampler, storage=either_storage)
    touch = data["next", "touch"].double().numpy().sum(-1)
    weights = np.where(np.cumsum(touch, 1) > 1.0, 10.0, 1.0)
    assert len(set(weights.sum(1))) > 2
    assert_frequencies(counts(rb), weights.sum(1))
    torch.manual_seed(1)
    index = torch.cat([rb.sample()["index"] for _ in range(30)])
    episode = int(np.argmax(weights.sum(1)))
    steps = index[index[:, 0] == episode, 1].numpy()
    observed = np.bincount(steps, minlength=T)
    assert_frequencies(observed, weights[episode])
    assert "priority_weight" not in rb.sample().keys()


def test_ebp_frequencies(either_storage):
    sampler = EBPSampler(clip_energy=0.5, temperature=1.0)
    rb, data = buffer(sampler, storage=either_storage)
    pos = np.concatenate([data["achieved_goal"][:, :1].double().numpy(), data["next", "achieved_goal"].double().numpy()], 1)
    height = pos[:, 1:, 2] - pos[:, :1, 2]
    velocity = np.diff(pos, axis=1) / 0.04
    energy = 9.81 * height + 0.5 * (velocity**2).sum(-1)
    increase = np.concatenate([energy[:, :1], np.diff(energy, axis=1)], 1)
    trajectory = np.clip(increase, 0, 0.5).sum(1)
    assert_frequencies(counts(rb), trajectory ** (1 / 1.01) + np.finfo(np.float32).eps)



@pytest.mark.parametrize("name", ["cebp", "cebp_released", "cebp_initial", "ebp"])
def test_non_finite_padding_steps_leave_the_priority_unchanged(name):
    sampler, episodes = SAMPLERS[name](4 * T), _ending_at([31, 31, T, 31], seed=0)
    valid = valid_steps(episode_lengths(episodes), T)
    padded = episodes.clone()
    for key in (("next", "touch"), ("next", "achieved_goal"), ("next", "observation")):
        padded[key][0, 31:], padded[key][1, 31:], padded[key][3, 31:] = float("nan"), float("inf"), -float("inf")
    expected = sampler.episode_priority(episodes, valid)
    assert torch.equal(sampler.episode_priority(padded, valid), expected)


def test_cper_refuses_a_non_finite_touch_in_a_valid_step_and_ignores_one_in_the_padding():
    episodes = hand_made(2)
    episodes["next", "done"][1, 30:] = False
    episodes["next", "done"][1, 30] = True
    clean = CPERSampler().episode_priority(episodes, valid_steps(episode_lengths(episodes), T))
    episodes["next", "touch"][1, 40:] = float("nan")  # padding
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(4 * T), sampler=CPERSampler(), dim_extend=0, batch_size=64)
    rb.extend(episodes)
    assert torch.equal(rb.sampler.priorities()[:2], clean)
    episodes["next", "touch"][1, 7, 0] = float("nan")
    with pytest.raises(ValueError, match=r"touch \('next', 'touch'\) is \[nan\] at the \(episode, step\) \[\[1, 7\]\]"):
        rb.extend(episodes)
    assert len(rb) == 2 * T  # refused before it was stored: the buffer draws on
    rb.extend(hand_made(2, seed=1))
    rb.sample()


def mep_probabilities(scores):
    """The paper code's draw (HER_force's ``entropy`` mode): dense ranks from 0, plus 0.001, to the power 1/1.01.

    One trajectory scored in two batches differs in its last bits (here 4.5e-13 on 750): rounded to 1e-6, far above
    that noise and far below the gaps between these tests' distinct trajectories, it gets one rank, as MEP gives it.
    """
    return (rankdata(np.round(scores, 6), method="dense") - 1 + 0.001) ** (1 / 1.01)


def test_mep_ranks_rare_trajectories_higher(either_storage):
    sampler = MEPSampler(seed=0)
    rb, data = buffer(sampler, storage=either_storage)
    assert_frequencies(counts(rb), np.ones(N_EPISODES))  # before the first refit
    sampler.refit(rb.storage)
    pos = np.concatenate([data["achieved_goal"][:, :1].double().numpy(), data["next", "achieved_goal"].double().numpy()], 1)
    scores = -sampler._mixture.score_samples(pos.reshape(N_EPISODES, -1))
    assert_frequencies(counts(rb), mep_probabilities(scores))


def test_mep_reranks_the_whole_buffer_on_every_write():
    sampler = MEPSampler(seed=0)
    rb, data = buffer(sampler)
    sampler.refit(rb.storage)
    new = hand_made(3, seed=7)
    new["next", "achieved_goal"][0] += 0.5  # far from anything fitted: the rarest
    new["next", "achieved_goal"][1] += 0.25
    rb.extend(new)
    both = torch.cat([data, new])
    pos = np.concatenate([both["achieved_goal"][:, :1].double().numpy(),
                          both["next", "achieved_goal"].double().numpy()], 1).reshape(len(both), -1)
    scores = -sampler._mixture.score_samples(pos)
    fitted_lowest = scores[:N_EPISODES].min()
    # Scores below the fit's lowest tie with it at rank 0, as the paper's code clips them there.
    expected = mep_probabilities(np.clip(scores - fitted_lowest, 0, None))
    assert torch.allclose(sampler.priorities()[: len(both)], torch.from_numpy(expected))
    # The two novel episodes rank above every fitted one, each at a rank of its own.
    assert sampler.priorities()[N_EPISODES] > sampler.priorities()[N_EPISODES + 1] > sampler.priorities()[:N_EPISODES].max()


def test_mep_ties_episodes_denser_than_any_fitted_one_at_rank_0():
    sampler = MEPSampler(seed=0)
    rb, _ = buffer(sampler)
    sampler.refit(rb.storage)
    densest = hand_made(1, seed=5)
    centre = torch.from_numpy(sampler._mixture.means_[sampler._mixture.weights_.argmax()]).float().view(T + 1, 3)
    densest["achieved_goal"][0, 0], densest["next", "achieved_goal"][0] = centre[0], centre[1:]
    raw = -sampler._mixture.score_samples(centre.double().view(1, -1).numpy())
    lowest_fitted = sampler.priorities()[:N_EPISODES].argmin()
    assert raw < sampler.state_dict()["lowest_fit_score"]  # below every fitted episode: the floor applies
    rb.extend(densest)
    assert sampler.priorities()[N_EPISODES] == sampler.priorities()[lowest_fitted] == 0.001 ** (1 / 1.01)


def test_an_emptied_mep_buffer_draws_uniformly_until_its_next_refit(either_storage):
    sampler = MEPSampler(seed=0)
    rb, _ = buffer(sampler, storage=either_storage)
    sampler.refit(rb.storage)
    rb.empty()
    rb.extend(hand_made(N_EPISODES, seed=2))
    assert_frequencies(counts(rb), np.ones(N_EPISODES))


def _report_scores_held_then_empty(rb, reports):
    reports.put(rb.sampler.state_dict()["scores"].numel())
    rb.sampler._empty()


def test_a_spawned_copy_of_mep_scores_into_memory_of_its_own():
    # Torch sends the scores as shared memory: a copy scoring into them would wipe the drawing process's on an empty.
    rb = make_replay_buffer(MEPSampler(seed=0), HindsightRelabel(sparse_reward), capacity=50 * T, batch_size=64,
                            shared=True)
    rb.extend(hand_made(N_EPISODES))
    rb.sampler.refit(rb.storage)
    context = torch.multiprocessing.get_context("spawn")
    reports = context.Queue()
    child = context.Process(target=_report_scores_held_then_empty, args=(rb, reports))
    child.start()
    assert reports.get(timeout=120) == 50
    child.join(timeout=60)
    assert child.exitcode == 0
    assert rb.sampler.state_dict()["scores"][:N_EPISODES].max() > 0


def test_mep_state_round_trip_keeps_the_ranks_of_later_writes(either_storage):
    sampler = MEPSampler(seed=0)
    rb, _ = buffer(sampler, storage=either_storage)
    sampler.refit(rb.storage)
    copy_ = MEPSampler(seed=0)
    copy_.load_state_dict(sampler.state_dict())
    more = hand_made(2, seed=3)
    rb.extend(more)
    copy_.write_priorities(torch.arange(N_EPISODES, N_EPISODES + 2), more)
    assert torch.equal(copy_.priorities(), sampler.priorities())
    with pytest.raises(ValueError, match="start the run again"):
        MEPSampler().load_state_dict({k: v for k, v in sampler.state_dict().items() if k != "scores"})


def test_mep_ranks_after_writes_are_those_of_a_whole_rerank():
    # Ties, overwrites, a floor at 0 and a skipped row included.
    sampler = MEPSampler(seed=0)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(12 * T), sampler=sampler, dim_extend=0, batch_size=16)
    rb.extend(hand_made())
    sampler.refit(rb.storage)
    sampler.write_priorities(torch.tensor([8]), hand_made(1, seed=9))  # rows 6 and 7 are stored at score 0 too
    scores = sampler.state_dict()["scores"][:9].numpy()
    assert torch.allclose(sampler.priorities()[:9], torch.from_numpy(mep_probabilities(scores)))
    noise = torch.Generator().manual_seed(0)
    for i in range(24):
        episodes = hand_made(1 + i % 3, seed=i)  # the same trajectories as stored: ties
        if i % 3:
            episodes["next", "achieved_goal"] += 0.01 * torch.randn(episodes.shape + (3,), generator=noise)
        if i % 7 == 0:
            episodes["next", "achieved_goal"] *= 0  # denser than any fitted one: rank 0
        rb.extend(episodes)
        whole = MEPSampler(seed=0)
        whole.load_state_dict(sampler.state_dict())  # ranks its first write from the scores alone
        whole.write_priorities(torch.tensor([0]), rb.storage.get(torch.tensor([0])))
        assert torch.equal(whole.priorities(), sampler.priorities())
    assert sampler.n_episodes == 12
    scores = sampler.state_dict()["scores"].numpy()
    assert torch.allclose(sampler.priorities(), torch.from_numpy(mep_probabilities(scores)))


def test_mep_gives_one_trajectory_one_rank_whichever_batch_brought_it():
    sampler = MEPSampler(seed=0)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(20 * T), sampler=sampler, dim_extend=0, batch_size=16)
    rb.extend(hand_made(8))
    sampler.refit(rb.storage)
    batch = hand_made(8, seed=5)  # rows 8-15, its row 3 (row 11) is also written alone (row 16)
    rb.extend(batch)
    rb.extend(batch[3:4])
    priorities = sampler.priorities()
    assert priorities[11] == priorities[16]
    # As a CPU whose BLAS sums the batch in another order scores it: one trajectory's score a few ulps apart.
    state = sampler.state_dict()
    state["scores"][16] = float(np.nextafter(np.nextafter(state["scores"][11].item(), np.inf), np.inf))
    rescored = MEPSampler(seed=0)
    rescored.load_state_dict(state)
    rescored.write_priorities(torch.tensor([0]), rb.storage.get(torch.tensor([0])))  # ranks the buffer again
    assert torch.equal(rescored.priorities(), priorities)
    # Scores that differ beyond float noise keep their own ranks.
    state["scores"][16] = state["scores"][11] * (1 + 1e-6)
    rescored.load_state_dict(state)
    rescored.write_priorities(torch.tensor([0]), rb.storage.get(torch.tensor([0])))
    assert rescored.priorities()[16] > rescored.priorities()[11]


def test_per_new_transitions_at_max_priority_then_td_error():
    sampler = PERSampler(50 * T, beta_anneal_draws=4)
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(50 * T), sampler=sampler, dim_extend=0, batch_size=256,
                                priority_key="td_error")
    rb.extend(hand_made())
    batch = rb.sample()
    assert torch.allclose(batch["priority_weight"], torch.ones(256))
    # one transition gets a huge TD error: it then dominates the draws
    batch = batch[:1]
    batch.set("td_error", torch.tensor([1e6]))
    rb.update_tensordict_priority(batch)
    target = batch["index"][0]
    drawn = rb.sample()["index"]
    assert (drawn == target).all(-1).float().mean() > 0.9

    scheduler = sampler.beta_scheduler()
    betas = []
    for _ in range(5):
        rb.sample()
        scheduler.step()
        betas.append(sampler.beta)
    assert sampler.beta_end == 1.0
    assert betas[0] == pytest.approx(0.4 + 0.6 / 4) and betas[-1] == pytest.approx(1.0)
    restarted = PERSampler(50 * T, beta_anneal_draws=4).beta_scheduler()
    restarted.load_state_dict(scheduler.state_dict())
    assert restarted._step_cnt == 5


def test_a_draw_never_returns_unwritten_rows():
    for sampler in (UniformEpisodeSampler(), CEBPSampler(), CPERSampler(), EBPSampler()):
        rb = TensorDictReplayBuffer(storage=EpisodeStorage(1000 * T), sampler=sampler, dim_extend=0, batch_size=4096)
        rb.extend(hand_made(3))
        assert rb.sample()["index"][:, 0].max() <= 2


def test_released_cebp_mask_from_the_named_layout_repeats_the_recorded_priorities():
    # Six scripted pushes on the extended mocap Push, recorded with the priorities the released form
    # gave before the observation layout was named (gripper slice hard-coded); one episode leaves the
    # workspace box, so the mask decides part of it.
    recorded = torch.load(Path(__file__).parent / "data" / "released_cebp_mocap_push.pt", weights_only=True)
    episodes = TensorDict(recorded["episodes"], [6, T])
    valid = valid_steps(episode_lengths(episodes), T)
    assert valid.all()
    priority = ReleasedCEBPSampler(workspace=PUSH_WORKSPACE).episode_priority(episodes, valid)
    torch.testing.assert_close(priority, recorded["priority"], rtol=1e-12, atol=0.0)
    assert priority.min() < 1e-4 < priority.max()


def tensors_of(state, path=()):
    """Every tensor of a nested state, by its path."""
    if isinstance(state, torch.Tensor):
        return {path: state}
    if isinstance(state, dict):
        return {p: t for key, value in state.items() for p, t in tensors_of(value, (*path, key)).items()}
    if isinstance(state, (tuple, list)):
        return {p: t for i, value in enumerate(state) for p, t in tensors_of(value, (*path, i)).items()}
    return {}


def scribble_over(state):
    for tensor in tensors_of(state).values():
        if tensor.is_floating_point():
            tensor.mul_(3.0).add_(1.0)


def assert_same_state(got, expected):
    got, expected = tensors_of(got), tensors_of(expected)
    assert got.keys() == expected.keys()
    for path, tensor in expected.items():
        assert torch.equal(got[path], tensor), path


@pytest.mark.parametrize("name", sorted(SAMPLERS))
def test_a_sampler_state_is_a_copy_both_ways(name):
    def filled():
        rb = make_replay_buffer(SAMPLERS[name](20 * T), HindsightRelabel(sparse_reward), capacity=20 * T, batch_size=64)
        rb.extend(make_episodes(6))
        if isinstance(rb.sampler, MEPSampler):
            rb.sampler.refit(rb.storage)
        batch = rb.sample()
        batch.set("td_error", torch.rand(64))
        rb.update_tensordict_priority(batch)  # PER: a running maximum priority
        return rb.sampler

    sampler = filled()
    state = sampler.state_dict()
    expected = copy.deepcopy(state)
    scribble_over(state)  # what the saved state goes through does not reach the sampler...
    assert_same_state(sampler.state_dict(), expected)
    loaded = filled()
    given = copy.deepcopy(expected)
    loaded.load_state_dict(given)
    scribble_over(given)  # ...nor what the loaded state goes through afterwards
    assert_same_state(loaded.state_dict(), expected)


@pytest.mark.parametrize("how", ["state_dict", "dumps"])
def test_a_resumed_per_beta_anneal_goes_on_where_it_stopped(how, tmp_path):
    def buffer():
        rb = make_replay_buffer(PERSampler(10 * T, beta_anneal_draws=10), HindsightRelabel(sparse_reward),
                                capacity=10 * T)
        rb.extend(make_episodes(2))
        return rb

    original = buffer()
    scheduler = original.sampler.beta_scheduler()
    for _ in range(4):
        scheduler.step()
    restored = buffer()
    restore(original, restored, how, tmp_path)
    resumed = restored.sampler.beta_scheduler()
    for _ in range(3):
        scheduler.step()
        resumed.step()
    assert restored.sampler.beta == pytest.approx(original.sampler.beta) == pytest.approx(0.4 + 0.6 * 7 / 10)


def prioritized_buffer(sampler):
    rb = make_replay_buffer(sampler, HindsightRelabel(sparse_reward), capacity=10 * T, batch_size=64)
    rb.extend(make_episodes(3))
    return rb


@pytest.mark.parametrize("how", ["state_dict", "dumps"])
@pytest.mark.parametrize("direction", ["ours_to_torchrl", "torchrl_to_ours"])
def test_per_and_torchrl_prioritized_sampler_load_each_others_state(how, direction, tmp_path):
    ours, torchrl = PERSampler(10 * T, alpha=0.7, beta=0.5), PrioritizedSampler(10 * T, alpha=0.7, beta=0.5)
    source, target = (ours, torchrl) if direction == "ours_to_torchrl" else (torchrl, ours)
    saved, loaded = prioritized_buffer(source), prioritized_buffer(target)
    batch = saved.sample()
    batch.set("td_error", torch.linspace(0.1, 5.0, 64))
    saved.update_tensordict_priority(batch)
    if how == "dumps":
        source.dumps(tmp_path)
        target.loads(tmp_path)
    else:  # TorchRL's sampler reads the TorchRL form of ours: its C++ trees are no state a weights_only load takes
        target.load_state_dict(PrioritizedSampler.state_dict(source) if source is ours else source.state_dict())
    assert target.beta == source.beta and target.alpha == source.alpha
    for rb in (saved, loaded):
        rb.set_rng(torch.Generator().manual_seed(3))
    drawn, again = saved.sample(), loaded.sample()
    assert torch.equal(drawn["index"], again["index"])
    torch.testing.assert_close(drawn["priority_weight"], again["priority_weight"])


@pytest.mark.parametrize("name", sorted(SAMPLERS))
def test_an_empty_buffer_says_what_torchrl_samplers_say(name):
    torchrl = TensorDictReplayBuffer(storage=EpisodeStorage(10 * T), sampler=RandomSampler(), dim_extend=0,
                                     batch_size=4)
    with pytest.raises(RuntimeError) as theirs:
        torchrl.sample()
    rb = make_replay_buffer(SAMPLERS[name](10 * T), HindsightRelabel(sparse_reward), capacity=10 * T, batch_size=4)
    with pytest.raises(RuntimeError) as ours:
        rb.sample()
    assert str(ours.value) == str(theirs.value) == "Cannot sample from an empty storage."
    rb.extend(make_episodes(2))
    rb.empty()
    with pytest.raises(RuntimeError, match=re.escape(str(theirs.value))):
        rb.sample()


@pytest.mark.parametrize("collector_class", [MultiSyncCollector, MultiAsyncCollector])
def test_an_episode_sampler_scores_what_a_collectors_processes_write(collector_class):
    # The workers get copies of the buffer: the episodes they write reach the learner's sampler through the storage.
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=4 * T, batch_size=64,
                            writer=EpisodeWriter(T))
    rb.extend(make_env("push", seed=0).rollout(T))  # TorchRL shares only an initialised storage
    collector = collector_class([functools.partial(make_env, "push", seed=seed) for seed in (1, 2)], None,
                                frames_per_batch=2 * 60, total_frames=2 * 4 * 60, replay_buffer=rb,
                                auto_register_policy_transforms=False)
    try:
        for _ in collector:  # 240 frames per worker: four episodes each, written over 1 + 8 rows of 4
            pass
    finally:
        collector.shutdown()
    drawn = rb.sample()
    # An async collector's workers may finish one more batch, and write it, before the shutdown reaches them.
    assert rb.write_count == 9 if collector_class is MultiSyncCollector else rb.write_count >= 9
    assert rb.sampler.n_episodes == 4
    new = TensorDictReplayBuffer(storage=rb.storage, sampler=CEBPSampler(), dim_extend=0, batch_size=64)
    new.sample()  # scores the rows as they are now
    torch.testing.assert_close(rb.sampler.state_dict()["priorities"], new.sampler.state_dict()["priorities"])
    assert set(drawn["next", "reward"].unique().tolist()) <= {-1.0, 0.0}


EPISODE_SAMPLERS = sorted(name for name in SAMPLERS if name != "per")  # PER's priorities are TD errors, fed back


@pytest.mark.parametrize("first", ["sample", "extend"])
@pytest.mark.parametrize("name", EPISODE_SAMPLERS)
def test_a_new_sampler_scores_the_episodes_its_storage_already_holds(name, first):
    seen, data = buffer(SAMPLERS[name](50 * T))  # saw every write
    new = TensorDictReplayBuffer(storage=seen.storage, sampler=SAMPLERS[name](50 * T), dim_extend=0, batch_size=64)
    if first == "extend":
        more = hand_made(2, seed=1)
        seen.extend(more)  # the shared storage: the new sampler is told of this write only
        new.sampler.mark_update(torch.arange(N_EPISODES, N_EPISODES + 2), storage=new.storage)
    new.sample()
    assert new.sampler.n_episodes == seen.sampler.n_episodes
    torch.testing.assert_close(new.sampler.state_dict()["priorities"], seen.sampler.state_dict()["priorities"])



@pytest.mark.parametrize("storage", [EpisodeStorage, functools.partial(LazyTensorStorage, ndim=2)],
                         ids=["an episode storage", "TorchRL's storage"])
@pytest.mark.parametrize("name", EPISODE_SAMPLERS)
def test_a_sampler_reused_in_a_second_buffer_is_refused_unless_given_its_state(name, storage):
    def buffer_of(sampler):
        return TensorDictReplayBuffer(storage=storage(50 * T), sampler=sampler, dim_extend=0, batch_size=64)

    first = buffer_of(SAMPLERS[name](50 * T))
    first.extend(hand_made(N_EPISODES))
    first.sample()
    second = buffer_of(first.sampler)  # same capacity: the first buffer's priorities would fit its rows
    with pytest.raises(ValueError, match="scores the episodes of another storage, not of this .*: use one sampler per buffer"):
        second.extend(hand_made(2, seed=1))
    second.load_state_dict(first.state_dict())  # restored from a state, it takes the storage it meets
    assert set(second.sample()["index"][:, 0].tolist()) <= set(range(N_EPISODES)) and second.sampler.n_episodes == 6
    with pytest.raises(ValueError, match="use one sampler per buffer"):
        first.sample()


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_buffer_scores_and_draws_the_writes_into_its_own_storage(how):
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(8 * T), sampler=ScoredByValue(), dim_extend=0, batch_size=256)
    rb.extend(valued(1, 1))
    rb.sample()
    copied = copy.deepcopy(rb) if how == "deepcopy" else pickle.loads(pickle.dumps(rb))
    copied.extend(valued(0, 0, 5))
    assert copied.sampler.state_dict()["priorities"][:5].tolist() == [1, 1, 0, 0, 5]
    assert set(copied.sample()["index"][:, 0].tolist()) == {0, 1, 4}
    assert rb.sampler.n_episodes == 2

def _extend_reporting_errors(rb, errors):
    try:
        rb.extend(hand_made(2, seed=1))
    except RuntimeError as error:
        errors.put(str(error))
    else:
        errors.put(None)


@pytest.mark.parametrize("storage", [EpisodeStorage, functools.partial(LazyTensorStorage, ndim=2)],
                         ids=["an episode storage", "TorchRL's storage"])
def test_a_sampler_scores_the_episodes_a_spawned_process_writes(storage):
    rb = TensorDictReplayBuffer(storage=storage(50 * T), sampler=CEBPSampler(), dim_extend=0, batch_size=64,
                                shared=True)
    rb.extend(hand_made(N_EPISODES))
    context = torch.multiprocessing.get_context("spawn")
    errors = context.Queue()
    child = context.Process(target=_extend_reporting_errors, args=(rb, errors))
    child.start()
    assert errors.get(timeout=120) is None
    child.join(timeout=60)
    rb.sample()  # scores the rows the child wrote
    assert rb.sampler.n_episodes == N_EPISODES + 2
    new = TensorDictReplayBuffer(storage=rb.storage, sampler=CEBPSampler(), dim_extend=0, batch_size=64)
    new.sample()
    torch.testing.assert_close(rb.sampler.state_dict()["priorities"], new.sampler.state_dict()["priorities"])


def _ending_at(lengths: list[int], seed: int) -> TensorDict:
    """Episodes of these valid lengths, whose padding steps are marked: observation -1, achieved goal 1e3."""
    episodes = make_episodes(len(lengths), seed=seed)
    episodes["next", "done"][:] = False
    for episode, length in enumerate(lengths):
        episodes["next", "done"][episode, length - 1] = True
        episodes["observation"][episode, length:] = -1.0
        episodes["next", "achieved_goal"][episode, length:] = 1e3
    return episodes


def _overwrite_while_drawn(rb, writes, started):
    started.set()
    for write in range(writes):  # every row flips between a whole episode and a 5-step one
        rb.extend(_ending_at([5, T] if write % 4 < 2 else [T, 5], seed=write))


def test_draws_while_another_process_overwrites_the_rows_return_no_padding_step():
    # Not shared=True: TorchRL's process lock would keep the child's writes and these draws apart. The storage's
    # memory is shared all the same. Without the recheck of the drawn rows, about 2% of the draws held padding.
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=4 * T, batch_size=256)
    rb.extend(_ending_at([T, T, T, T], seed=0))
    context = torch.multiprocessing.get_context("spawn")
    started = context.Event()
    child = context.Process(target=_overwrite_while_drawn, args=(rb, 400, started))
    child.start()
    assert started.wait(timeout=120)
    draws = 0
    while child.is_alive():
        batch = rb.sample()
        assert bool((batch["observation"] >= 0).all()), "a padding step was drawn"
        assert bool((batch["desired_goal"] < 1e3).all()), "a goal came from a padding step"
        draws += 1
    assert child.exitcode == 0 and draws > 10


def _write_episodes_that_end_early(rb, lengths):
    episodes = hand_made(len(lengths), seed=3)
    episodes["next", "done"][:] = False
    for episode, length in enumerate(lengths):
        episodes["next", "done"][episode, length - 1] = True
    rb.extend(episodes)


def test_episodes_a_spawned_process_writes_are_scored_and_drawn_within_their_length():
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=4 * T, batch_size=4096,
                            shared=True)
    rb.extend(hand_made(4))  # every row full: episodes of one length, the storage says
    assert rb.storage.common_length() == T
    child = torch.multiprocessing.get_context("spawn").Process(target=_write_episodes_that_end_early,
                                                               args=(rb, [10, 20]))
    child.start()
    child.join(timeout=120)
    assert child.exitcode == 0
    drawn = rb.sample()  # rows 0 and 1 overwritten
    lengths = torch.tensor([10, 20, T, T])
    assert torch.equal(rb.storage.valid_lengths(torch.arange(4)), lengths) and rb.storage.common_length() is None
    rows, steps = drawn["index"].unbind(-1)
    assert set(rows.tolist()) == set(range(4)) and bool((steps < lengths[rows]).all())
    new = TensorDictReplayBuffer(storage=rb.storage, sampler=CEBPSampler(), dim_extend=0, batch_size=64)
    new.sample()
    torch.testing.assert_close(rb.sampler.state_dict()["priorities"], new.sampler.state_dict()["priorities"])


class ScoredByValue(EpisodePrioritySampler):
    """Scores each episode by its ``"value"`` entry: priorities a test can predict."""

    def episode_priority(self, episodes, valid):
        return episodes["value"][:, 0].double()


def valued(*values: float) -> TensorDict:
    """One episode per value, each step holding it."""
    return TensorDict({"value": torch.tensor(values)[:, None].expand(-1, T).clone()}, [len(values), T])


@pytest.mark.parametrize("storage", [EpisodeStorage, functools.partial(LazyTensorStorage, ndim=2)],
                         ids=["an episode storage", "TorchRL's storage"])
def test_a_restored_sampler_scores_the_first_write_after_the_restore(storage):
    def buffer():
        return TensorDictReplayBuffer(storage=storage(4 * T), sampler=ScoredByValue(), dim_extend=0, batch_size=64)

    saved = buffer()
    saved.extend(valued(1, 1))
    saved.extend(valued(1, 1))
    restored = buffer()
    restored.load_state_dict(saved.state_dict())
    restored.extend(valued(0, 0))  # rows 0 and 1: episodes of priority 0
    assert restored.sampler.state_dict()["priorities"].tolist() == [0, 0, 1, 1]
    assert set(restored.sample(return_info=True)[1]["index"][0].tolist()) <= {2, 3}


def _overwrite_with_short_episodes(rb):
    rb.extend(_ending_at([2] * 4, seed=1))


def test_a_reloaded_storage_sent_to_a_spawned_process_shares_its_writes():
    # Before its first write or draw, a reloaded storage's blocks, lengths and write counts must already exist:
    # built later, each process would build its own, and the child's writes would never reach the parent.
    saved = make_replay_buffer(UniformEpisodeSampler(), HindsightRelabel(sparse_reward), capacity=4 * T,
                               batch_size=256)
    saved.extend(_ending_at([T] * 4, seed=0))
    rb = make_replay_buffer(UniformEpisodeSampler(), HindsightRelabel(sparse_reward), capacity=4 * T,
                            batch_size=256)
    rb.load_state_dict(saved.state_dict())
    child = torch.multiprocessing.get_context("spawn").Process(target=_overwrite_with_short_episodes, args=(rb,))
    child.start()
    rb.sample()  # the parent draws while the child writes
    child.join(timeout=120)
    assert child.exitcode == 0
    assert rb.storage.write_counts[:4].tolist() == [1, 1, 1, 1]
    assert torch.equal(rb.storage.valid_lengths(torch.arange(4)), torch.full((4,), 2))
    assert bool((rb.storage.get(slice(0, 4))["observation"][:, 2:] == -1).all())  # the child's padding
    assert bool((rb.sample()["observation"] >= 0).all())


@pytest.mark.parametrize(("lengths", "common"), [([T] * 4, T), ([T, 7, T, T], None), ([7] * 4, 7), ([7, 7, 9, 7], None)],
                         ids=["whole", "some short", "all short alike", "all short unlike"])
def test_the_storage_names_the_length_its_episodes_share(lengths, common):
    storage = EpisodeStorage(4 * T)
    storage.set(torch.arange(4), _ending_at(lengths, seed=0))
    assert storage.common_length() == common
    storage.set(torch.arange(2), _ending_at([T, T], seed=1))  # rows 0 and 1 whole again
    assert storage.common_length() == (T if lengths[2:] == [T, T] else None)


@pytest.mark.parametrize(("make_saved", "make_loaded", "named"), [
    # The two: CPER's step weights into HER's uniform draws, CEBP's priorities into another temperature.
    (CPERSampler, UniformEpisodeSampler, "saved by CPERSampler(threshold=1.0, lam=10.0, touch_key=('next', 'touch'), "
     "end_key=('next', 'done')), but is loaded into UniformEpisodeSampler(end_key=('next', 'done'))"),
    (lambda: CEBPSampler(temperature=0.01), lambda: CEBPSampler(temperature=0.05), "temperature=0.01, beta=1.0"),
    (MEPSampler, CPERSampler, "saved by MEPSampler("),
    (CPERSampler, MEPSampler, "saved by CPERSampler("),  # not blamed on an older MEP state
    (lambda: PERSampler(10 * T, alpha=0.6), lambda: PERSampler(10 * T, alpha=0.7), "loaded into PERSampler(alpha=0.7"),
], ids=["cper_to_uniform", "cebp_temperature", "mep_to_cper", "cper_to_mep", "per_alpha"])
@pytest.mark.parametrize("how", ["state_dict", "dumps"])
def test_a_state_loaded_into_a_sampler_of_another_kind_or_arguments_is_refused_naming_both(
        make_saved, make_loaded, named, how, tmp_path):
    saved = make_saved()
    if how == "dumps" and isinstance(saved, PERSampler):
        pytest.skip("PER dumps TorchRL's own files, which name no sampler")
    rb = make_replay_buffer(saved, HindsightRelabel(sparse_reward), capacity=10 * T, batch_size=8)
    rb.extend(make_episodes(3))
    rb.sample()
    with pytest.raises(ValueError, match=re.escape(named)):
        restore(saved, make_loaded(), how, tmp_path)
    restore(saved, make_saved(), how, tmp_path)  # one built as the saved one was loads it
