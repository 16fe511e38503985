"""The examples run as written, briefly, and what they train on is right."""
from pathlib import Path

import pytest
import torch

from tests.modules import load_module
from tests.replay.test_writer import assert_whole_episodes
from torchrl_cebp.envs import make_env
from torchrl_cebp.replay import episode_lengths

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(name):
    return load_module(EXAMPLES / f"{name}.py")


def test_ddpg_her_says_how_to_run_it(capsys):
    with pytest.raises(SystemExit) as done:
        load_example("ddpg_her").main(["--help"])
    assert done.value.code == 0 and "--sampler" in capsys.readouterr().out


@pytest.mark.parametrize("sampler", ["cebp", "per", "mep"])
def test_ddpg_her_trains_on_whole_relabelled_episodes_in_torchrls_loop(sampler, capsys):
    # 150 frames per env lane: three 50-step episodes each, ended across batches of 30 frames per lane.
    replay_buffer, losses = load_example("ddpg_her").main(
        ["--sampler", sampler, "--total-frames", "300", "--frames-per-batch", "60", "--utd-ratio", "0.1",
         "--batch-size", "64", "--buffer-size", "5000", "--refit-frames", "120"])
    assert "frames 300/300  episodes 6" in capsys.readouterr().out
    episodes = replay_buffer.storage.get(slice(None))
    assert episodes.shape == (6, 50) and bool((episode_lengths(episodes) == 50).all())
    assert_whole_episodes(replay_buffer)
    assert replay_buffer.sample(4096)["index"][:, 0].unique().tolist() == list(range(6))  # each is drawn
    batch = replay_buffer.sample()
    relabelled = batch["her_relabelled"]
    assert relabelled.any() and not relabelled.all()
    reward = make_env("push").compute_reward(batch["next", "achieved_goal"], batch["desired_goal"])
    assert torch.equal(batch["next", "reward"], reward)  # every reward is the one of the goal the batch holds
    assert losses.shape == (6,) and all(bool(torch.isfinite(value).all()) for value in losses.values())


def test_ddpg_her_refuses_an_unknown_sampler_naming_the_configs(capsys):
    with pytest.raises(SystemExit) as done:
        load_example("ddpg_her").main(["--sampler", "foo"])
    error = capsys.readouterr().err
    assert done.value.code == 2 and "invalid choice: 'foo'" in error and "'cebp_initial'" in error
