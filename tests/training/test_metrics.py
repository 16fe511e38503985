import math

import pytest
import torch
from hydra.utils import instantiate
from tensordict import TensorDict

from tests.tiny_run import TINY_RUN, config, rows
from torchrl_cebp.training import load_checkpoint
from torchrl_cebp.training.builders import episodes_per_cycle, make_env, make_replay
from torchrl_cebp.training.metrics import ExplorationLog, exploration_stats


def test_every_epoch_row_holds_the_exploration_of_the_episodes_it_stored_recomputed_from_the_runs_replay(tiny_run):
    cfg = config(*TINY_RUN)
    log = rows(tiny_run / "progress.csv")
    env = make_env(cfg)
    replay = make_replay(cfg, instantiate(cfg.sampler), env)[0]
    replay.load_state_dict(load_checkpoint(tiny_run)["replay"])
    per_epoch = cfg.cycles_per_epoch * episodes_per_cycle(cfg)
    assert len(replay) == len(log) * per_epoch * env.max_episode_steps  # nothing overwritten: rows in epoch order
    for epoch, row in enumerate(log):
        episodes = replay.storage.get(torch.arange(epoch * per_epoch, (epoch + 1) * per_epoch))
        expected = exploration_stats(episodes["achieved_goal"][:, 0], episodes["next", "achieved_goal"][:, -1],
                                     success_radius=0.05)
        assert float(row["explore_moved_share"]) == pytest.approx(expected["explore_moved_share"], abs=1e-12)
        assert float(row["explore_goal_entropy_bits"]) == pytest.approx(expected["explore_goal_entropy_bits"],
                                                                        abs=1e-9)
    env.close()


def test_exploration_counts_moves_beyond_the_radius_and_bins_final_goals_on_the_grid():
    start = torch.zeros(8, 3)
    end = torch.zeros(8, 3)
    end[:2, 0] = 0.051  # moved beyond 5 cm, into the same 2-cm cell
    end[2, 1] = 0.049   # moved, but within the radius
    end[3, 2] = 0.3     # lifted
    stats = exploration_stats(start, end, success_radius=0.05)
    assert stats["explore_moved_share"] == 3 / 8
    shares = torch.tensor([2, 1, 1, 4]) / 8  # cells: x=0.051 (2), y=0.049, z=0.3, and the 4 unmoved at the origin
    assert stats["explore_goal_entropy_bits"] == pytest.approx(-(shares * shares.log2()).sum().item(), abs=1e-12)
    assert exploration_stats(start, start, 0.05) == {"explore_moved_share": 0.0, "explore_goal_entropy_bits": 0.0}
    # A 1-m grid puts every final goal in one cell; 8 goals 10 cm apart are 8 cells, log2(8) bits.
    assert exploration_stats(start, end, 0.05, cell=1.0)["explore_goal_entropy_bits"] == 0.0
    spread = torch.arange(8.0).unsqueeze(-1).expand(8, 3) * 0.1
    assert exploration_stats(start, spread, 0.05)["explore_goal_entropy_bits"] == pytest.approx(math.log2(8))


def test_exploration_reads_each_episodes_last_valid_step_and_restarts_each_epoch():
    achieved = torch.zeros(2, 5, 3)
    next_achieved = torch.zeros(2, 5, 3)
    next_achieved[0, 2] = torch.tensor([0.2, 0.0, 0.0])  # episode 0 ends at step 2, its padding returns to 0
    next_achieved[1, 4] = torch.tensor([0.0, 0.0, 0.01])
    done = torch.zeros(2, 5, 1, dtype=torch.bool)
    done[0, 2] = True
    episodes = TensorDict({"achieved_goal": achieved, "next": {"achieved_goal": next_achieved, "done": done}}, [2, 5])
    log = ExplorationLog(success_radius=0.05)
    log.update(episodes)
    log.update(episodes[1:])
    assert log.compute()["explore_moved_share"] == 1 / 3
    assert log.compute() == {}
