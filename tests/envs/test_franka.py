"""Franka pick-and-place in MuJoCo: gymnasium contract, Fetch observation layout, goal space, touch physics."""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from torchrl_cebp.envs import FRANKA_TASK, FrankaPickPlaceEnv, make_franka
from torchrl_cebp.envs.franka import FRANKA_GYM_ID, HAND_BODY, HAND_QUAT, FrankaLayout, sample_goal


@pytest.fixture(scope="module")
def env() -> FrankaPickPlaceEnv:
    return FrankaPickPlaceEnv()


def drive(env: FrankaPickPlaceEnv, obs: dict, target: np.ndarray, gripper: float, steps: int) -> tuple[dict, list]:
    """Proportional control of the grip point towards ``target``; returns the last observation and each step's touch."""
    touches = []
    for _ in range(steps):
        move = np.clip((target - obs["observation"][:3]) / 0.05, -1, 1)
        obs, _, _, _, info = env.step(np.append(move, gripper).astype(np.float32))
        touches.append(info["touch"])
    return obs, touches


def test_gymnasium_contract_and_registration(env):
    check_env(env, skip_render_check=True)
    assert FRANKA_TASK == "franka_pick_place"
    registered = gym.make(FRANKA_GYM_ID)
    assert registered.spec.max_episode_steps == 100
    with pytest.raises(ValueError, match="valid goal spaces: standard"):
        make_franka("extended")


def test_fetch_layout(env):
    obs, info = env.reset(seed=0)
    assert obs["observation"].shape == (25,) and obs["desired_goal"].shape == (3,)
    assert env.action_space.shape == (4,) and env.max_episode_steps == 100
    np.testing.assert_array_equal(obs["achieved_goal"], obs["observation"][3:6])
    np.testing.assert_allclose(obs["observation"][6:9], obs["observation"][3:6] - obs["observation"][:3])
    assert info["touch"].shape == (2,)
    # Fetch's sparse reward, vectorised.
    goals = np.zeros((4, 3))
    assert env.compute_reward(goals + 0.01, goals, {}).tolist() == [0, 0, 0, 0]


def test_goal_and_object_ranges(env):
    layout = FrankaLayout()
    rng = np.random.default_rng(0)
    goals = np.stack([sample_goal(layout, rng) for _ in range(4000)])
    centre = np.asarray(layout.table_centre)
    assert np.abs(goals[:, :2] - centre).max() <= layout.target_range
    lifted = goals[:, 2] > layout.cube_centre_height
    assert 0.47 < lifted.mean() < 0.53
    assert goals[:, 2].max() <= layout.cube_centre_height + layout.target_height
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        assert np.abs(obs["observation"][3:5] - centre).max() <= layout.obj_range + 1e-3
        assert obs["observation"][5] == pytest.approx(layout.cube_centre_height, abs=2e-3)


def test_touch_only_while_holding_the_cube(env):
    obs, _ = env.reset(seed=3)
    cube = obs["observation"][3:6].copy()
    obs, approach = drive(env, obs, cube + [0, 0, 0.1], gripper=1.0, steps=8)
    obs, descend = drive(env, obs, cube, gripper=1.0, steps=6)
    obs, close = drive(env, obs, cube, gripper=-1.0, steps=6)
    obs, lift = drive(env, obs, cube + [0, 0, 0.15], gripper=-1.0, steps=8)

    for touch in approach + descend:  # open gripper moving in free air
        np.testing.assert_array_equal(touch, np.zeros(2))
    for touch in close[-2:] + lift:  # holding the cube
        assert (touch > 0).all(), touch
    assert obs["achieved_goal"][2] > cube[2] + 0.12  # lifted with the gripper
    assert np.linalg.norm(obs["observation"][6:9]) < 0.02  # still between the fingers


def test_make_env_gives_the_franka_task_as_a_torchrl_env():
    from torchrl.envs.utils import check_env_specs

    from torchrl_cebp.envs import make_env

    check_env_specs(make_env(FRANKA_TASK, num_envs=2))
    td = make_env(FRANKA_TASK, seed=0).rollout(100)
    assert td["next", "touch"].shape == (100, 2) and td["next", "truncated"][-1].item()


def grasp_and_lift(env: FrankaPickPlaceEnv, seed: int, height: float) -> tuple[dict, list]:
    """Hover, descend, close on the cube and lift it ``height``; the last observation and the closing steps' touch."""
    obs, _ = env.reset(seed=seed)
    cube = obs["observation"][3:6].copy()
    obs, _ = drive(env, obs, cube + [0, 0, 0.1], gripper=1.0, steps=8)
    obs, _ = drive(env, obs, cube, gripper=1.0, steps=6)
    obs, close = drive(env, obs, cube, gripper=-1.0, steps=6)
    obs, _ = drive(env, obs, cube + [0, 0, height], gripper=-1.0, steps=8)
    return obs, close


def test_grasped_cube_survives_fast_random_moves(env):
    # Exploration moves the hand at full speed in random directions; the cube must stay between the fingers.
    # With the finger targets clamped to the joint range the squeeze was 12 N and 5 of these 10 cubes fell.
    held = 0
    for seed in range(10):
        obs, close = grasp_and_lift(env, seed, height=0.15)
        assert close[-1].min() > 50.0, close[-1]  # each pad squeezes with about the actuators' 70 N limit
        rng = np.random.default_rng(seed)
        for _ in range(30):
            obs, *_ = env.step(np.append(rng.uniform(-1, 1, 3), -1.0).astype(np.float32))
        held += np.linalg.norm(obs["observation"][6:9]) < 0.03
    assert held >= 8, held


def test_grasped_start_hands_over_the_cube_held_at_its_placement():
    grasped, layout = FrankaPickPlaceEnv(grasped_start=1.0), FrankaLayout()
    for seed in range(8):
        obs, info = grasped.reset(seed=seed)
        assert (info["touch"] > 0).all(), info["touch"]
        assert np.linalg.norm(obs["observation"][6:9]) < 0.02  # the cube sits between the fingers
        assert obs["observation"][5] == pytest.approx(layout.cube_centre_height, abs=5e-3)  # still on the table
        assert np.abs(obs["observation"][3:5] - layout.table_centre).max() <= layout.obj_range + 1e-3
    obs, _ = drive(grasped, obs, obs["observation"][:3] + [0, 0, 0.2], gripper=-1.0, steps=6)
    assert obs["achieved_goal"][2] > layout.cube_centre_height + 0.15  # closing the gripper was all a lift needed


def test_grasped_start_draws_the_share_asked_and_leaves_plain_resets_alone(env):
    half = FrankaPickPlaceEnv(grasped_start=0.5)
    held = [bool((half.reset(seed=seed)[1]["touch"] > 0).all()) for seed in range(40)]
    assert 10 <= sum(held) <= 30, sum(held)
    never = FrankaPickPlaceEnv(grasped_start=0.0)
    for seed in range(3):  # no extra random draw: the placements and goals of every earlier run stay the same
        np.testing.assert_array_equal(never.reset(seed=seed)[0]["observation"], env.reset(seed=seed)[0]["observation"])
    with pytest.raises(ValueError, match="grasped_start=1.5: must be a probability"):
        FrankaPickPlaceEnv(grasped_start=1.5)
    from torchrl_cebp.envs import make_env

    with pytest.raises(ValueError, match="only franka_pick_place has grasped starts; use 0 for 'push'"):
        make_env("push", grasped_start=0.5)


def test_hand_stays_in_the_workspace_box(env):
    # Unclamped, full-speed moves took the grip point past the table's edge (x = -0.19), below its top and 0.95 m up.
    box = env.layout.workspace
    for axis, sign in itertools.product(range(3), (-1.0, 1.0)):
        obs, _ = env.reset(seed=0)
        action = np.zeros(4, np.float32)
        action[axis], action[3] = sign, 1.0
        for _ in range(25):
            obs, *_ = env.step(action)
            grip = obs["observation"][:3]
            assert (grip >= np.subtract(box.low, 0.005)).all() and (grip <= np.add(box.high, 0.005)).all(), grip
        face = box.high[axis] if sign > 0 else box.low[axis]
        assert grip[axis] == pytest.approx(face, abs=0.005)


def test_every_corner_of_the_workspace_is_reached_with_the_hand_down(env):
    # Beyond the arm's reach (the loop's former box went to x = 0.8) the wrist stops at its joint limit and the
    # weld swings the hand by centimetres, tilted by up to 20 degrees.
    box = env.layout.workspace
    for corner in itertools.product(*zip(box.low, box.high)):
        obs, _ = env.reset(seed=0)
        obs, _ = drive(env, obs, np.array(corner), gripper=1.0, steps=40)
        assert np.linalg.norm(obs["observation"][:3] - corner) < 0.005, corner
        tilt = 2 * np.degrees(np.arccos(min(1.0, abs(np.dot(env.data.body(HAND_BODY).xquat, HAND_QUAT)))))
        assert tilt < 3.0, (corner, tilt)
