"""What a user's pipeline could get wrong without a word: each is now read right or refused with the fix."""
import copy
import pickle
import re
from pathlib import Path

import pytest
import torch
from tensordict import NonTensorData, TensorDict
from torchrl.data import LazyTensorStorage, RandomSampler, TensorDictReplayBuffer

from tests.modules import load_module
from tests.replay.conftest import PUSH_WORKSPACE, T, make_episodes, sparse_reward
from torchrl_cebp import _upstream
from torchrl_cebp.envs import make_env
from torchrl_cebp.replay import EpisodeMemmapStorage, EpisodeStorage, EpisodeWriter, HindsightRelabel, make_replay_buffer
from torchrl_cebp.replay.samplers import (
    CEBPSampler,
    CPERSampler,
    EBPSampler,
    InitialCEBPSampler,
    MEPSampler,
    PERSampler,
    ReleasedCEBPSampler,
)


def storages(tmp_path):
    return {"tensor": EpisodeStorage(40 * T), "memmap": EpisodeMemmapStorage(40 * T, scratch_dir=str(tmp_path))}


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
@pytest.mark.parametrize("kind", ["tensor", "memmap"])
def test_a_copied_buffer_draws_what_it_stores(how, kind, tmp_path):
    rb = TensorDictReplayBuffer(storage=storages(tmp_path)[kind], sampler=RandomSampler(), dim_extend=0,
                                batch_size=4096)
    rb.extend(make_episodes(8))
    copied = copy.deepcopy(rb) if how == "deepcopy" else pickle.loads(pickle.dumps(rb))
    copied.extend(make_episodes(8, seed=1))
    batch = copied.sample()
    rows, steps = batch["index"].unbind(-1)
    stored = copied.storage.get(rows)  # the whole rows, read apart from the (rows, steps) read of a draw
    assert torch.equal(batch["observation"], stored["observation"][torch.arange(4096), steps])
    assert torch.equal(copied.storage.get(torch.arange(8, 16))["observation"], make_episodes(8, seed=1)["observation"])


def test_an_unnamed_batch_laid_out_time_first_is_refused_with_the_fix():
    rollout = make_env("push", seed=0, num_envs=3).rollout(T)  # [3, T], time last
    unnamed = rollout.transpose(0, 1).clone()  # [T, 3], no names
    unnamed.names = [None, None]
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), writer=EpisodeWriter(T), dim_extend=0, batch_size=8)
    with pytest.raises(ValueError, match=r"\[50, 3\] do not follow each other along its last dimension.*transpose"):
        rb.extend(unnamed)
    assert len(rb) == 0
    time_last = rollout.clone()
    time_last.names = [None, None]
    rb.extend(time_last)  # the same frames time last, unnamed: read as they are
    assert rb.storage.shape == (3, T)


def test_a_batch_the_user_laid_out_time_first_is_not_blamed_on_dim_extend():
    rollout = make_env("push", seed=0, num_envs=3).rollout(T).transpose(0, 1)  # names ["time", None]
    for writer in (None, EpisodeWriter(T)):
        rb = TensorDictReplayBuffer(storage=EpisodeStorage(40 * T), writer=writer, dim_extend=0, batch_size=8)
        with pytest.raises(ValueError, match=r"'time' dimension at 0.*laid out with time first.*transpose") as error:
            rb.extend(rollout.clone())
        assert "dim_extend" not in str(error.value)


def test_a_write_lacking_a_stored_entry_is_refused_and_stores_nothing():
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=10 * T)
    rb.extend(make_episodes(2))
    partial = make_episodes(2, seed=1)
    del partial["next", "touch"]
    lacks_touch = "must hold every stored entry and no other: it lacks [('next', 'touch')]"
    with pytest.raises(KeyError, match=re.escape(lacks_touch)):
        rb.extend(partial)
    assert len(rb) == 2 * T


def _feature_moved_to_the_goal(episodes):
    # The same floats a step, which the blocks would shift.
    episodes["desired_goal"] = torch.cat([episodes["desired_goal"], episodes["observation"][..., -1:]], -1)
    episodes["observation"] = episodes["observation"][..., :-1]
    return "entry 'observation' has torch.float32 values of shape [24] per step, but the storage holds torch.float32 of [25]"


def _action_as_a_matrix(episodes):
    # The same width, which the blocks would store as the flat action.
    episodes["action"] = episodes["action"].reshape(*episodes.shape, 2, 2)
    return "entry 'action' has torch.float32 values of shape [2, 2] per step, but the storage holds torch.float32 of [4]"


def _touch_in_double(episodes):
    # TorchRL's storage refuses it; the block would cast it.
    episodes["next", "touch"] = episodes["next", "touch"].double()
    return "entry ('next', 'touch') has torch.float64 values of shape [2] per step, but the storage holds torch.float32"


@pytest.mark.parametrize("change", [_feature_moved_to_the_goal, _action_as_a_matrix, _touch_in_double])
def test_a_write_whose_entries_change_shape_or_dtype_is_refused_and_stores_nothing(change):
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=10 * T)
    rb.extend(make_episodes(2))
    changed = make_episodes(2, seed=1)
    with pytest.raises(ValueError, match=re.escape(change(changed))):
        rb.extend(changed)
    assert len(rb) == 2 * T and rb.write_count == 2
    rb.extend(make_episodes(1, seed=2))  # into row 2: the refused write left the cursor where it was
    assert torch.equal(rb.storage.get(torch.tensor([2]))["observation"], make_episodes(1, seed=2)["observation"])


@pytest.mark.parametrize("writer", [None, EpisodeWriter(T)])
def test_a_first_write_its_sampler_cannot_score_stores_nothing(writer):
    rb = make_replay_buffer(CEBPSampler(), HindsightRelabel(sparse_reward), capacity=10 * T, writer=writer)
    partial = make_episodes(2)
    del partial["next", "touch"]
    with pytest.raises(KeyError, match=r"no key .*next.*touch.*\[n_episodes, T, 2\]"):
        rb.extend(partial)
    assert len(rb) == 0 and rb.write_count == 0  # the writer's cursor moved back too
    rb.extend(make_episodes(2, seed=1))  # the next write goes where the refused one would have
    assert rb.storage.shape == (2, T) and rb.sampler.n_episodes == 2
    assert set(rb.sample(4096)["index"][:, 0].tolist()) == {0, 1}


@pytest.mark.parametrize("make, message", [
    (lambda: CEBPSampler(beta=-1), r"CEBPSampler beta=-1.0: allowed values lie in \[0.0, inf\)"),
    (lambda: CEBPSampler(temperature=0), r"CEBPSampler temperature=0.0: allowed values lie in \(0.0, inf\)"),
    (lambda: CEBPSampler(scale=float("nan")), r"CEBPSampler scale=nan"),
    (lambda: InitialCEBPSampler(beta=-0.7), r"InitialCEBPSampler beta=-0.7"),
    (lambda: ReleasedCEBPSampler(k=0, workspace=PUSH_WORKSPACE), r"ReleasedCEBPSampler k=0.0"),
    (lambda: CPERSampler(lam=0), r"CPERSampler lam=0.0"),
    (lambda: CPERSampler(threshold=-1), r"CPERSampler threshold=-1.0"),
    (lambda: EBPSampler(clip_energy=0), r"EBPSampler clip_energy=0.0"),
    (lambda: EBPSampler(temperature=-1), r"EBPSampler temperature=-1.0"),
    (lambda: MEPSampler(n_components=0), r"MEPSampler n_components=0.0: allowed values lie in \[1, inf\)"),
    (lambda: MEPSampler(reg_covar=0), r"MEPSampler reg_covar=0.0"),
    (lambda: PERSampler(100, beta=-1), r"PERSampler beta=-1.0"),
    (lambda: PERSampler(100, alpha=-0.6), r"PERSampler alpha=-0.6"),
    (lambda: PERSampler(100, beta_anneal_draws=0), r"PERSampler beta_anneal_draws=0.0"),
    (lambda: PERSampler(0), r"PERSampler capacity=0.0"),
])
def test_a_sampler_parameter_out_of_range_is_refused_naming_value_and_range(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_is_success_of_the_stored_goal_never_reaches_a_relabelled_batch():
    episodes = make_episodes(8)
    episodes["next", "is_success"] = episodes["next", "reward"] == 0  # the stored goal's success
    rb = make_replay_buffer(None, HindsightRelabel(sparse_reward, future_p=1.0), capacity=10 * T, batch_size=4096)
    rb.extend(episodes)
    assert ("next", "is_success") not in rb.sample().keys(True, True)


def test_the_episode_storage_finds_its_buffers_and_rewinds_their_writers():
    storage = EpisodeStorage(10 * T)
    rb = TensorDictReplayBuffer(storage=storage, dim_extend=0)
    assert _upstream.attached_buffers(storage) == [rb]
    rb.extend(make_episodes(3))
    _upstream.rewind_writers(storage, torch.tensor([1, 2]))
    assert rb.write_count == 1
    rb.extend(make_episodes(1, seed=1))  # goes to row 1
    assert torch.equal(storage.get(torch.tensor([1]))["observation"], make_episodes(1, seed=1)["observation"])


def test_ddpg_her_refuses_no_frames_with_a_message(capsys):
    example = load_module(Path(__file__).resolve().parents[2] / "examples" / "ddpg_her.py")
    with pytest.raises(SystemExit) as done:
        example.main(["--total-frames", "0"])
    assert done.value.code == 2 and "--total-frames=0: must be a positive integer" in capsys.readouterr().err


def test_a_write_of_more_episodes_than_rows_keeps_the_lengths_of_the_episodes_that_land():
    def ending(after_steps):  # episodes that end early where given, else whole
        episodes = make_episodes(len(after_steps), seed=len(after_steps))
        for row, steps in enumerate(after_steps):
            if steps is not None:
                episodes["next", "done"][row] = False
                episodes["next", "done"][row, steps - 1] = True
        return episodes

    rb = TensorDictReplayBuffer(storage=EpisodeStorage(2 * T), sampler=CEBPSampler(), dim_extend=0, batch_size=4000)
    rb.extend(ending([4, None]))
    rb.extend(ending([None, 4, None]))  # rows 0, 1, 0: row 0 whole, row 1 ends after 4 steps
    assert rb.storage.valid_lengths(torch.arange(2)).tolist() == [T, 4]
    assert rb.storage.common_length() is None
    index = rb.sample()["index"]
    assert not ((index[:, 0] == 1) & (index[:, 1] >= 4)).any()  # no padding step drawn


def test_a_pair_read_takes_each_step_within_its_row_as_torchrl_storage_does():
    episodes = make_episodes(3)
    ours, theirs = EpisodeStorage(4 * T), LazyTensorStorage(4 * T, ndim=2)
    for storage in (ours, theirs):
        TensorDictReplayBuffer(storage=storage, dim_extend=0).extend(episodes)
    rows, steps = torch.tensor([1, 2, 0]), torch.tensor([-1, 0, -T])
    assert torch.equal(ours.get((rows, steps))["observation"], theirs.get((rows, steps))["observation"])
    for outside in (T, -T - 1):
        with pytest.raises(IndexError, match=f"step {outside} is outside rows of {T} steps"):
            ours.get((rows, torch.tensor([0, outside, 1])))


def test_a_write_with_an_entry_the_first_did_not_hold_is_refused_and_stores_nothing():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(4 * T), dim_extend=0, batch_size=4)
    rb.extend(make_episodes(2))
    extended = make_episodes(1, seed=1)
    extended["next", "info"] = torch.ones(1, T, 2)  # a draw, which reads the blocks, would never return it
    with pytest.raises(KeyError, match=re.escape("no other: it adds [('next', 'info')]")):
        rb.extend(extended)
    assert len(rb) == 2 * T


def test_a_first_write_holding_a_non_tensor_entry_is_refused_naming_it():
    episodes = make_episodes(2)
    episodes["task"] = NonTensorData("push", batch_size=episodes.shape)  # the blocks would drop it
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(4 * T), dim_extend=0, batch_size=4)
    with pytest.raises(TypeError, match=re.escape("exclude ['task'] before writing")):
        rb.extend(episodes)
    assert len(rb) == 0


def test_a_write_with_collector_ids_after_the_first_gets_every_check_and_leaves_the_ids_out():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(4 * T), dim_extend=0, batch_size=4)
    rb.extend(make_episodes(2))  # as env.rollout writes before collectors share the storage
    with_ids = make_episodes(1, seed=1)
    with_ids["collector", "traj_ids"] = torch.zeros(1, T, dtype=torch.long)
    with_ids["observation"] = with_ids["observation"].double()
    with pytest.raises(ValueError, match=re.escape("entry 'observation' has torch.float64 values")):
        rb.extend(with_ids)
    with_ids["observation"] = with_ids["observation"].float()
    rb.extend(with_ids)
    assert len(rb) == 3 * T and "collector" not in rb.storage.get(slice(0, 3)).keys()


@pytest.mark.parametrize("written_before", [False, True])
def test_a_memmap_storage_loaded_from_a_state_keeps_its_rows_in_its_scratch_dir(tmp_path, written_before):
    source = TensorDictReplayBuffer(storage=EpisodeMemmapStorage(4 * T, scratch_dir=str(tmp_path / "source")),
                                    dim_extend=0)
    source.extend(make_episodes(2))
    target = TensorDictReplayBuffer(storage=EpisodeMemmapStorage(4 * T, scratch_dir=str(tmp_path / "target")),
                                    dim_extend=0)
    if written_before:
        target.extend(make_episodes(1, seed=1))
    target.load_state_dict(source.state_dict())
    observation = _upstream.stored_tensordict(target.storage).get("observation")
    assert Path(observation.filename).parent == tmp_path / "target"  # not anonymous memory, which RAM must hold
    assert torch.equal(target.storage.get(slice(0, 2))["observation"], make_episodes(2)["observation"])


def test_a_refused_direct_write_into_the_storage_leaves_the_buffers_writer_where_it_was():
    rb = TensorDictReplayBuffer(storage=EpisodeStorage(8 * T), dim_extend=0)
    rb.extend(make_episodes(4))  # the writer's next row: 4
    with pytest.raises(ValueError, match="episodes of 20 steps cannot go into a storage of 50-step episodes"):
        rb.storage.set(torch.tensor([1, 2, 3]), make_episodes(3, length=20))
    assert rb.write_count == 4
    rb.extend(make_episodes(1, seed=1))  # into row 4: rows 1-3 keep their episodes
    assert torch.equal(rb.storage.get(slice(0, 4))["observation"], make_episodes(4)["observation"])
    assert torch.equal(rb.storage.get(torch.tensor([4]))["observation"], make_episodes(1, seed=1)["observation"])
    with pytest.raises(ValueError, match="cannot go into a storage of 50-step episodes"):
        rb.extend(make_episodes(2, length=20))  # a refused extend still rewinds the writer it moved
    assert rb.write_count == 5


def test_a_pair_read_takes_each_row_among_the_filled_ones_as_torchrl_storage_does():
    episodes = make_episodes(3)
    ours, theirs = EpisodeStorage(4 * T), LazyTensorStorage(4 * T, ndim=2)
    for storage in (ours, theirs):
        TensorDictReplayBuffer(storage=storage, dim_extend=0).extend(episodes)
    rows, steps = torch.tensor([-1, -3, 2]), torch.tensor([0, 4, -1])
    assert torch.equal(ours.get((rows, steps))["observation"], theirs.get((rows, steps))["observation"])
    for outside in (3, -4):  # row 3 is allocated, but not filled
        with pytest.raises(IndexError, match=f"row {outside} is outside the 3 filled rows"):
            ours.get((torch.tensor([0, outside]), torch.tensor([0, 1])))
        with pytest.raises(IndexError):
            theirs.get((torch.tensor([0, outside]), torch.tensor([0, 1])))


def test_a_memmap_storage_loaded_into_another_live_storages_scratch_dir_is_refused_not_shared(tmp_path):
    first = EpisodeMemmapStorage(4 * 50, scratch_dir=str(tmp_path))
    first.set(torch.arange(2), TensorDict({"observation": torch.ones(2, 50, 3)}, [2, 50]))
    second = EpisodeMemmapStorage(4 * 50, scratch_dir=str(tmp_path))  # one config, one scratch_dir
    state = first.state_dict()
    state[_upstream.STORAGE_STATE_KEY]["observation"] = torch.full((2, 50, 3), 7.0)  # other episodes
    with pytest.raises(RuntimeError, match=rf"scratch_dir {re.escape(str(tmp_path))}/? already holds memory-mapped "
                                           "files .* give each storage a scratch_dir of its own"):
        second.load_state_dict(state)
    assert (first.get(torch.arange(2))["observation"] == 1).all()  # the first storage's rows are its own still
    third = EpisodeMemmapStorage(4 * 50, scratch_dir=str(tmp_path / "own"))
    third.load_state_dict(state)
    assert (third.get(torch.arange(2))["observation"] == 7).all()
