"""The shipped Franka pick-and-place policy: a small weights-only file that drives the twin through the camera loop."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from torchrl_cebp.envs import FETCH_OBSERVATION
from torchrl_cebp.sim2real import SHIPPED_POLICY
from torchrl_cebp.sim2real.__main__ import main, parse_args, run
from torchrl_cebp.training import load_policy
from torchrl_cebp.training.checkpoint import POLICY_FORMAT


def test_shipped_policy_is_a_small_weights_only_file_with_the_franka_config():
    assert SHIPPED_POLICY.stat().st_size < 1_000_000
    state = torch.load(SHIPPED_POLICY, map_location="cpu", weights_only=True)
    assert state["format"] == POLICY_FORMAT and {"format", "env", "hidden", "actor", "normalizer"} <= set(state)
    assert state["env"]["task"] == "franka_pick_place"


def test_shipped_policy_acts_in_the_franka_action_space():
    policy = load_policy(SHIPPED_POLICY)
    batch = TensorDict(observation=torch.randn(5, FETCH_OBSERVATION.size), desired_goal=torch.randn(5, 3), batch_size=[5])
    action = policy(batch)["action"]
    assert action.shape == (5, 4) and action.abs().max() <= 1.0
    assert action.std(0).min() > 0  # it reads its input: different observations, different actions


def test_a_damaged_policy_file_is_named_in_one_line(tmp_path, capsys):
    path = tmp_path / "policy.pt"
    path.write_bytes(SHIPPED_POLICY.read_bytes()[:1000])  # a copy cut short
    assert main(["run", f"checkpoint={path}", "backend=sim", "episodes=1"]) == 2
    assert capsys.readouterr().err == (
        f"error: {path} does not load: it is not a complete file of torch.save (1000 bytes: truncated, or another format)\n"
    )


def test_run_uses_the_shipped_policy_by_default():
    assert parse_args(["run"])[1]["checkpoint"] == str(SHIPPED_POLICY)


@pytest.mark.slow
def test_shipped_policy_succeeds_through_the_camera_loop():
    # Two cameras, the setup the README recommends: the loop's own score and the twin's true cube agree.
    report = run(parse_args(["run", "backend=sim", "episodes=10", "side_camera=true"])[1])
    assert report["camera_loop_success"] >= 0.8 and report["true_success"] >= 0.8
    # One camera, the paper's: the policy still places the cube, though the camera may lose it under the hand.
    assert run(parse_args(["run", "backend=sim", "episodes=10"])[1])["true_success"] >= 0.8
