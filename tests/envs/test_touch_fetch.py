"""Touch-sensing Fetch tasks: touch physics, TorchRL contract (keys, specs, seeds, reward), goal spaces."""

from __future__ import annotations

import functools

import gymnasium as gym
import gymnasium_robotics
import numpy as np
import pytest
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.envs import EnvBase, ParallelEnv, SerialEnv
from torchrl.envs.utils import check_env_specs, step_mdp

from torchrl_cebp.envs import ALL_TASKS, GOAL_SPACES, TASKS, gym_id, make_env, make_env_from_config, make_touch_fetch

gym.register_envs(gymnasium_robotics)
GYMNASIUM_IDS = {"pick_place": "FetchPickAndPlace-v4", "push": "FetchPush-v4", "slide": "FetchSlide-v4"}


def drive(env: EnvBase, td: TensorDictBase, target, gripper: float, steps: int) -> tuple[TensorDictBase, list]:
    """Proportional mocap control of the grip site towards ``target``; returns the last root td and the steps."""
    transitions = []
    for _ in range(steps):
        move = ((torch.as_tensor(target, dtype=torch.float32) - td["observation"][:3]) / 0.025).clamp(-1, 1)
        td = env.step(td.set("action", torch.cat([move, torch.tensor([gripper])])))
        transitions.append(td["next"].clone())
        td = step_mdp(td)
    return td, transitions


def test_scripted_grasp_senses_both_fingers_only_while_holding():
    env = make_env("pick_place", seed=3)
    td = env.reset()
    block = td["observation"][3:6].numpy().copy()
    td, approach = drive(env, td, block + [0, 0, 0.1], gripper=1.0, steps=10)
    td, descend = drive(env, td, block, gripper=1.0, steps=8)
    td, close = drive(env, td, block, gripper=-1.0, steps=6)
    td, lift = drive(env, td, block + [0, 0, 0.15], gripper=-1.0, steps=10)

    for step in approach + descend:  # open gripper moving in free air
        assert torch.equal(step["touch"], torch.zeros(2))
    for step in close[-2:] + lift:  # holding the block
        assert (step["touch"] > 0).all(), step["touch"]
    table_top = block[2]
    assert lift[-1]["achieved_goal"][2] > table_top + 0.1
    assert torch.equal(lift[-1]["achieved_goal"], lift[-1]["observation"][3:6])


def test_scripted_push_senses_contact_and_moves_block():
    env = make_env("push", seed=3)
    td = env.reset()
    block = td["observation"][3:6].numpy().copy()
    td, _ = drive(env, td, block + [-0.07, 0, 0.06], gripper=0.0, steps=10)
    td, lower = drive(env, td, block + [-0.07, 0, 0.0], gripper=0.0, steps=6)
    td, push = drive(env, td, block + [0.1, 0, 0.0], gripper=0.0, steps=10)

    assert torch.equal(lower[-1]["touch"], torch.zeros(2))
    assert max(step["touch"].sum() for step in push) > 0
    displacement = push[-1]["achieved_goal"].numpy() - block
    assert displacement[0] > 0.1
    assert torch.equal(push[-1]["observation"][9:11], torch.zeros(2))  # gripper stays blocked


@pytest.mark.parametrize("goal_space", GOAL_SPACES)
@pytest.mark.parametrize("task", TASKS)
def test_make_env_keys_shapes_dtypes_and_specs(task, goal_space):
    env = make_env(task, goal_space, seed=0)
    assert (env.task, env.goal_space) == (task, goal_space)
    check_env_specs(env)
    td = env.rollout(env.max_episode_steps + 5)  # stops at truncation
    steps = env.max_episode_steps
    float_shapes = {"observation": 25, "achieved_goal": 3, "desired_goal": 3, "touch": 2}
    for key, size in float_shapes.items():
        for root in ((), ("next",)):
            value = td[(*root, key)]
            assert value.shape == (steps, size) and value.dtype == torch.float32, key
    assert td["next", "reward"].shape == (steps, 1) and td["next", "reward"].dtype == torch.float32
    for key in ("done", "terminated", "truncated", "is_success"):
        assert td["next", key].shape == (steps, 1) and td["next", key].dtype == torch.bool, key
    assert td["next", "truncated"].squeeze(-1).tolist() == [False] * (steps - 1) + [True]
    assert torch.equal(td["next", "done"], td["next", "truncated"])
    assert not td["next", "terminated"].any()
    assert (td["next", "touch"] >= 0).all()
    assert torch.equal(td["next", "is_success"], td["next", "reward"] == 0)


def test_seeds_make_resets_reproducible():
    def first_reset(env: EnvBase) -> torch.Tensor:
        td = env.reset()
        return torch.cat([td["achieved_goal"], td["desired_goal"]])

    reference = first_reset(make_env("pick_place", seed=7))
    assert torch.equal(first_reset(make_env("pick_place", seed=7)), reference)
    reseeded = make_env("pick_place")
    reseeded.set_seed(7)
    assert torch.equal(first_reset(reseeded), reference)
    assert not torch.equal(first_reset(make_env("pick_place", seed=8)), reference)
    env = make_env("pick_place", seed=7)
    assert not torch.equal(first_reset(env), first_reset(env))  # later resets keep drawing


@pytest.mark.parametrize(
    ("kwargs", "valid"), [({"task": "reach"}, ALL_TASKS), ({"task": "push", "goal_space": "huge"}, GOAL_SPACES)]
)
def test_bad_names_raise_listing_valid_ones(kwargs, valid):
    with pytest.raises(ValueError) as error:
        make_env(**kwargs)
    for name in valid:
        assert name in str(error.value)


def test_compute_reward_is_vectorised_and_matches_step_reward():
    env = make_env("push", seed=1)
    td = env.rollout(env.max_episode_steps)
    recomputed = env.compute_reward(td["next", "achieved_goal"], td["next", "desired_goal"])
    assert recomputed.dtype == torch.float32 and torch.equal(recomputed, td["next", "reward"])

    desired = torch.zeros(2, 4, 3)
    achieved = torch.zeros(2, 4, 3)
    achieved[1, :, 0] = 2 * env.distance_threshold
    achieved[0, :, 0] = 0.5 * env.distance_threshold
    reward = env.compute_reward(achieved, desired)
    assert reward.shape == (2, 4, 1) and reward.dtype == torch.float32
    assert (reward[0] == 0).all() and (reward[1] == -1).all()

    gymnasium_reward = env._sims[0].compute_reward(achieved.double().numpy(), desired.double().numpy(), None)
    assert np.array_equal(gymnasium_reward, reward.squeeze(-1).numpy())


@pytest.mark.parametrize("task", TASKS)
def test_standard_goal_space_is_gymnasium_robotics_default(task):
    ours = make_touch_fetch(task)
    reference = gym.make(GYMNASIUM_IDS[task]).unwrapped
    for attribute in ("obj_range", "target_range", "distance_threshold", "target_in_the_air", "block_gripper"):
        assert getattr(ours, attribute) == getattr(reference, attribute), attribute
    np.testing.assert_array_equal(np.broadcast_to(ours.target_offset, 3), np.broadcast_to(reference.target_offset, 3))
    assert ours.max_episode_steps == gym.spec(GYMNASIUM_IDS[task]).max_episode_steps


def test_extended_pick_place_targets_always_in_the_air_and_ahead():
    env = make_touch_fetch("pick_place", "extended")
    goals = np.stack([env.reset(seed=seed)[0]["desired_goal"] for seed in range(40)])
    assert (goals[:, 2] >= env.height_offset).all()
    assert (goals[:, 2] <= env.height_offset + 0.35).all()
    assert (goals[:, 2] > env.height_offset + 0.01).mean() > 0.9  # not the half-on-the-table of standard
    assert abs((goals[:, 0] - env.initial_gripper_xpos[0]).mean() - 0.2) < 0.05


def test_extended_slide_and_push_settings():
    slide = make_env("slide", "extended")
    assert slide.max_episode_steps == 70 and slide.distance_threshold == 0.15
    gym_slide = make_touch_fetch("slide", "extended")
    starts = np.stack([gym_slide.reset(seed=seed)[0]["achieved_goal"] for seed in range(20)])
    # Puck starts shifted away from the robot by obj_range: x in [gripper, gripper + 2 * obj_range].
    assert (starts[:, 0] >= gym_slide.initial_gripper_xpos[0] - 1e-9).all()
    np.testing.assert_allclose(gym_slide.model.geom("table0").size[:2], [1.2, 1.0])

    push = make_touch_fetch("push", "extended")
    table = push.model.body("table0").geomadr[0]
    np.testing.assert_allclose(push.model.geom_size[table][:2], [0.5, 0.5])
    standard = make_touch_fetch("push")
    near_edge = [env.model.body("table0").pos[0] - env.model.geom_size[table][0] for env in (push, standard)]
    assert near_edge[0] == pytest.approx(near_edge[1])  # grown away from the robot


def test_touch_sites_are_visible_and_on_the_inner_pads():
    env = make_touch_fetch("push")
    for side, inward in (("left", 1), ("right", -1)):
        site = env.model.site(f"robot0:{side}_pad")
        assert site.group[0] < 3 and site.rgba[3] > 0  # groups 0-2 render by default
        assert np.sign(site.pos[1]) == inward


def test_registered_gymnasium_ids_report_touch():
    env = gym.make(gym_id("slide", "extended"))
    assert env.spec.max_episode_steps == 70
    _, info = env.reset(seed=0)
    assert info["touch"].shape == (2,)
    info = env.step(env.action_space.sample())[4]
    assert info["touch"].shape == (2,) and (info["touch"] >= 0).all()
    assert gym.make(gym_id("push")).unwrapped.goal_space == "standard"


@pytest.mark.parametrize("batched_cls", [SerialEnv, ParallelEnv])
def test_batched_envs_roll_out(batched_cls):
    env = batched_cls(2, functools.partial(make_env, "push", "extended"))
    try:
        env.set_seed(0)
        td = env.rollout(4)
        assert td["next", "touch"].shape == (2, 4, 2)
        assert not torch.equal(td["desired_goal"][0, 0], td["desired_goal"][1, 0])
    finally:
        env.close()


def test_num_envs_steps_a_batch_of_simulations_in_one_env():
    check_env_specs(make_env("push", num_envs=3))
    env = make_env("push", seed=0, num_envs=3)
    td = env.rollout(env.max_episode_steps)
    assert td.batch_size == (3, env.max_episode_steps)
    assert td["next", "truncated"][:, -1].all() and not td["next", "truncated"][:, :-1].any()
    goals = td["desired_goal"][:, 0]
    assert not torch.equal(goals[0], goals[1])  # simulation i is seeded seed + i
    again = make_env("push", seed=0, num_envs=3).reset()["desired_goal"]
    assert torch.equal(again, goals)
    single = make_env("push", seed=1).reset()["desired_goal"]
    assert torch.equal(single, goals[1])


def test_num_envs_partial_reset_leaves_the_other_simulations_running():
    env = make_env("pick_place", seed=0, num_envs=2)
    env.reset()
    env.rand_step()
    before = env._rows.copy()
    env.reset(TensorDict({"_reset": torch.tensor([[True], [False]])}, [2]))
    assert not np.array_equal(env._rows[0], before[0])
    assert np.array_equal(env._rows[1], before[1])
    assert env._steps.tolist() == [0, 1]


def test_episode_steps_set_a_tasks_episode_length():
    env = make_env("slide", "standard", num_envs=2, episode_steps=70)
    td = env.rollout(100, break_when_any_done=True)
    assert env.max_episode_steps == 70 and td.shape == (2, 70) and td["next", "truncated"][:, -1].all()
    assert make_env("slide", "standard").max_episode_steps == 50  # gymnasium's, unless asked
    config = {"task": "slide", "goal_space": "standard", "episode_steps": 70}
    assert make_env_from_config(config).max_episode_steps == 70
    franka = make_env("franka_pick_place", num_envs=2, episode_steps=50)
    td = franka.rollout(100, break_when_any_done=True)
    assert franka.max_episode_steps == 50 and td.shape == (2, 50) and td["next", "truncated"][:, -1].all()
    assert make_env("franka_pick_place").max_episode_steps == 100  # the paper's, unless asked
