"""The released code's robot: CPER's joint-controlled Fetch, table-blind touch pads, touch in the observation."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from tests.envs.test_touch_fetch import drive
from torchrl_cebp.envs import FETCH_OBSERVATION, TASKS, ObservationLayout, gym_id, make_env, make_touch_fetch
from torchrl_cebp.envs.joint_control import ARM_JOINTS

EXPECTED_ACTIONS = {"push": 7, "pick_place": 8, "slide": 7}


def arm_angles(env) -> np.ndarray:
    return np.array([env.data.qpos[env.model.jnt_qposadr[env.model.joint(j.name).id]] for j in ARM_JOINTS])


@pytest.mark.parametrize("task", TASKS)
def test_joint_action_sizes_and_specs(task):
    env = make_env(task, "extended", control="joint", touch_ignores_table=True, seed=0)
    assert env.action_spec.shape == (EXPECTED_ACTIONS[task],)
    check_env_specs(env)


def test_zero_action_drives_every_arm_joint_to_the_centre_of_its_range():
    env = make_touch_fetch("push", "extended", control="joint")
    env.reset(seed=0)
    centre = np.array([j.centre for j in ARM_JOINTS])
    env.model.opt.gravity[:] = 0.0  # kp 300 leaves the lift joints sagging under gravity; without it they arrive
    start = np.abs(arm_angles(env) - centre)
    for _ in range(50):
        env.step(np.zeros(7))
    np.testing.assert_allclose(env.data.ctrl[-7:], centre)
    end = np.abs(arm_angles(env) - centre)
    assert start.max() > 0.1
    assert end.max() < 0.02, end


def test_joint_reset_perturbs_the_start_and_mocap_does_not():
    joint = make_touch_fetch("push", "extended", control="joint")
    starts = [joint.reset(seed=seed)[0]["observation"][FETCH_OBSERVATION.gripper_position] for seed in (0, 1)]
    assert np.linalg.norm(starts[0] - starts[1]) > 1e-3
    mocap = make_touch_fetch("push", "extended")
    starts = [mocap.reset(seed=seed)[0]["observation"][FETCH_OBSERVATION.gripper_position] for seed in (0, 1)]
    np.testing.assert_array_equal(starts[0], starts[1])


def test_joint_reset_perturbation_stays_within_cpers_bounds():
    env = make_touch_fetch("push", "extended", control="joint")
    initial = np.array([j.initial for j in ARM_JOINTS])
    low, high = np.array([j.perturbation for j in ARM_JOINTS]).T
    offsets = []
    for seed in range(200):
        env.reset(seed=seed)
        offsets.append(arm_angles(env) - initial)
    offsets = np.array(offsets)
    assert (offsets >= low - 1e-12).all() and (offsets <= high + 1e-12).all()
    # every joint is perturbed, over most of its interval (shoulder lift and elbow only downwards)
    assert ((offsets.max(0) - offsets.min(0)) > 0.8 * (high - low)).all()


def test_joint_robot_with_table_blind_pads_feels_no_table():
    # A zero action lowers the joint robot's closed fingers onto the table (a 2 cm sag below its reset height).
    readings = {}
    for blind in (False, True):
        env = make_touch_fetch("push", "extended", control="joint", touch_ignores_table=blind)
        start = env.reset(seed=2)[0]["achieved_goal"]
        readings[blind] = sum(env.step(np.zeros(7))[4]["touch"].sum() for _ in range(20))
        np.testing.assert_allclose(env._get_obs()["achieved_goal"], start, atol=1e-3)  # the object was not touched
    assert readings[False] > 10.0
    assert readings[True] == 0.0


def test_joint_object_and_goal_are_drawn_around_the_unperturbed_initial_grip():
    # As CPER's released code: the anchor is the grip of the initial joints, the same every episode,
    # while the arm itself starts perturbed.
    env = make_touch_fetch("push", "extended", control="joint")
    anchor = env.initial_gripper_xpos.copy()
    grips = []
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        np.testing.assert_array_equal(env.initial_gripper_xpos, anchor)
        grips.append(obs["observation"][FETCH_OBSERVATION.gripper_position])
        obj = obs["observation"][FETCH_OBSERVATION.object_position]
        assert 0.1 <= np.linalg.norm(obj[:2] - anchor[:2]) and np.abs(obj[:2] - anchor[:2]).max() <= 0.25
        offset = obs["desired_goal"][:2] - anchor[:2] - [0.1, 0.0]
        assert np.abs(offset).max() <= 0.25
    assert np.ptp(np.array(grips), axis=0).max() > 0.02  # the perturbed starts differ from the anchor


def test_table_blind_pads_read_zero_on_the_table_and_positive_on_the_object():
    # The mocap robot carries the same pads: press the closed fingers onto bare table, then grasp the cube.
    for blind, expect_table_touch in ((True, False), (False, True)):
        env = make_env("pick_place", touch_ignores_table=blind, seed=3)
        td = env.reset()
        grip = td["observation"][FETCH_OBSERVATION.gripper_position].numpy()
        block = td["observation"][FETCH_OBSERVATION.object_position].numpy()
        away = grip[:2] + 0.1 * (grip[:2] - block[:2]) / np.linalg.norm(grip[:2] - block[:2])
        _, press = drive(env, td, [*away, 0.3], gripper=-1.0, steps=15)
        table_touch = torch.stack([t["touch"] for t in press[5:]])
        if expect_table_touch:
            assert table_touch.sum() > 1.0
        else:
            assert torch.equal(table_touch, torch.zeros_like(table_touch))
    env = make_env("pick_place", touch_ignores_table=True, seed=3)
    td = env.reset()
    block = td["observation"][FETCH_OBSERVATION.object_position].numpy().copy()
    td, _ = drive(env, td, block + [0, 0, 0.1], gripper=1.0, steps=10)
    td, _ = drive(env, td, block, gripper=1.0, steps=8)
    td, close = drive(env, td, block, gripper=-1.0, steps=6)
    held = close[-1]["touch"]
    assert (held > 1.0).all(), held


@pytest.mark.parametrize("control", ["mocap", "joint"])
def test_touch_in_observation_is_the_step_touch_and_its_running_sum(control):
    env = make_env("pick_place", "extended", control=control, touch_ignores_table=False, touch_in_observation=True, seed=3)
    layout = ObservationLayout(with_touch=True)
    assert env.observation_spec["observation"].shape == (layout.size,)
    torch.manual_seed(2)  # random actions under which both robots touch something
    rollout = env.rollout(50)
    step_touch = rollout["next", "touch"].sum(-1)
    assert step_touch.sum() > 0  # the unblinded pads touch something in 50 random steps
    observed = rollout["next", "observation"]
    torch.testing.assert_close(observed[:, layout.touch].squeeze(-1), step_touch)
    torch.testing.assert_close(observed[:, layout.touch_total].squeeze(-1), step_touch.double().cumsum(0).float())
    assert rollout["observation"][0, layout.touch_total].item() == 0.0


def test_layout_matches_gymnasium_robotics_observation():
    env = make_touch_fetch("pick_place")
    env.reset(seed=0)
    parts = env.generate_mujoco_observations()
    names = [name for name, _ in FETCH_OBSERVATION.fields]
    obs = env._get_obs()["observation"]
    for name, part in zip(names, parts):
        np.testing.assert_array_equal(obs[FETCH_OBSERVATION.slice(name)], np.ravel(part))
    assert FETCH_OBSERVATION.size == obs.shape[0] == 25


def test_joint_gym_ids_are_registered():
    import gymnasium as gym

    for task in TASKS:
        env = gym.make(gym_id(task, "extended", "joint"), touch_ignores_table=True)
        assert env.action_space.shape == (EXPECTED_ACTIONS[task],)
        env.close()
