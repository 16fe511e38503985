"""The evaluation command: success rate of a checkpoint and a video of its episodes."""
import re

import imageio.v3 as iio
import numpy as np
import pytest
import torch
from tensordict import TensorDict

from tests.tiny_run import config, copy_run
from torchrl_cebp.agents import SHIPPED_AGENTS
from torchrl_cebp.envs import make_franka, make_touch_fetch
from torchrl_cebp.evaluate import main, record_video, success_rate
from torchrl_cebp.sim2real import SHIPPED_POLICY
from torchrl_cebp.training import load_policy, train
from torchrl_cebp.training.checkpoint import POLICY_NAME, UnreadableFileError


def plain_gymnasium_success_rate(policy, make_env, seeds) -> float:
    """The success rate of ``policy`` over one gymnasium episode per seed, stepped by hand (no TorchRL env).

    The episodes run side by side and the policy acts on all of them in one batch, as the command's batched env has it
    act: a network's forward over one row is another BLAS kernel than over a batch, whose actions differ in their last
    bits (by CPU), and the contacts can turn that into another outcome.
    """
    envs = [make_env() for _ in seeds]
    observations = [env.reset(seed=seed)[0] for env, seed in zip(envs, seeds)]
    for _ in range(envs[0].max_episode_steps):
        td = TensorDict({key: torch.as_tensor(np.stack([obs[key] for obs in observations]), dtype=torch.float32)
                         for key in ("observation", "desired_goal")}, [len(envs)])
        with torch.no_grad():
            actions = policy(td)["action"].numpy()
        steps = [env.step(action) for env, action in zip(envs, actions)]
        observations = [step[0] for step in steps]
    return float(np.mean([float(step[4]["is_success"]) for step in steps]))


def test_the_command_prints_the_success_rate_a_plain_loop_measures(capsys):
    # The shipped Franka policy (50-step episodes, as it trained): a rate that is not trivially 0.
    main([str(SHIPPED_POLICY), "--episodes", "4"])  # success_rate seeds simulation i with 1234 + i
    expected = plain_gymnasium_success_rate(
        load_policy(SHIPPED_POLICY), lambda: make_franka(max_episode_steps=50), range(1234, 1238))
    assert capsys.readouterr().out == f"{SHIPPED_POLICY}: success rate over 4 episodes: {expected:.3f}\n"
    assert expected >= 0.75  # the shipped policy places the cube
    main(["--task", "franka_pick_place", "--episodes", "4"])  # the same file, with no path to type
    assert capsys.readouterr().out == f"{SHIPPED_POLICY}: success rate over 4 episodes: {expected:.3f}\n"


def test_the_episode_length_can_be_set_and_is_named(capsys):
    main(["--task", "franka_pick_place", "--episodes", "4", "--episode-steps", "5"])
    expected = plain_gymnasium_success_rate(
        load_policy(SHIPPED_POLICY), lambda: make_franka(max_episode_steps=5), range(1234, 1238))
    assert capsys.readouterr().out == f"{SHIPPED_POLICY}: success rate over 4 episodes of 5 steps: {expected:.3f}\n"
    assert expected == 0.0  # too short to place the cube, which it does in 50 steps: the length reached the env


@pytest.mark.parametrize(
    "argv, message",
    [
        ([], "give either a policy .* or --task, not both or neither"),
        (["--task", "push", "--episode-steps", "0"], "--episode-steps must be at least 1, got 0"),
        (["--task", "push", "--video-episodes", "-1"], "--video-episodes must be at least 1, got -1"),
        (["runs/x", "--task", "push"], "give either a policy .* or --task, not both or neither"),
        (["--task", "slide"], r"invalid choice: 'slide' \(choose from .*franka_pick_place.*pick_place.*push"),
        (["--task", "push", "--video", "push.avi"], r"unknown format '\.avi'; valid: \['\.mp4', '\.gif'\]"),
    ],
)
def test_the_command_refuses_a_wrong_choice_of_policy_or_video_by_name(capsys, argv, message):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert re.search(message, capsys.readouterr().err)


def test_a_task_whose_agent_is_missing_names_the_agents_this_installation_has(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(SHIPPED_AGENTS, "push", tmp_path / "push.pt")  # an installation without the Push agent
    with pytest.raises(SystemExit) as exit_info:
        main(["--task", "push"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert f"the push agent is not in this installation ({tmp_path / 'push.pt'} is missing); shipped here: [" in err
    assert "'franka_pick_place'" in err and "'push'" not in err.split("shipped here:")[1]


def test_success_rate_on_the_checkpoints_own_robot_equals_a_plain_gymnasium_loop(tmp_path):
    # The released code's robot (7-D actions): the evaluation must rebuild it from the checkpoint.
    train(config("sampler=her", "env=push_released", "epochs=1"), tmp_path)
    expected = plain_gymnasium_success_rate(
        load_policy(tmp_path),
        lambda: make_touch_fetch("push", "extended", control="joint", touch_ignores_table=True),
        range(1234, 1238),
    )
    assert success_rate(tmp_path, episodes=4, seed=1234) == pytest.approx(expected)


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_video_has_one_frame_per_step(tiny_run, tmp_path, suffix):
    path = record_video(tiny_run, tmp_path / f"episode{suffix}", episodes=1, size=(64, 48))
    frames = iio.imread(path)
    assert frames.shape[0] == 51 and frames.shape[1:3] == (48, 64)
    assert frames.std() > 5  # a rendered scene, not a blank frame


def test_bad_video_format_and_missing_checkpoint(tiny_run, tmp_path):
    with pytest.raises(ValueError, match="'.avi'.*mp4.*gif"):
        record_video(tiny_run, tmp_path / "x.avi")
    with pytest.raises(FileNotFoundError, match="No policy at .*nowhere"):
        success_rate(tmp_path / "nowhere")


def _truncated(path):
    path.write_bytes(path.read_bytes()[:1000])


def _empty(path):
    path.write_bytes(b"")


def _a_module(path):
    torch.save(torch.nn.Linear(2, 2), path)


def _a_tensor(path):
    torch.save(torch.ones(3), path)


def _other_weights(path):
    torch.save({"weights": torch.ones(3)}, path)


def _other_sizes(path):
    state = torch.load(path, weights_only=True)
    torch.save({**state, "hidden": [64, 64]}, path)  # the tiny run's actor is 32 x 32


POLICY_DAMAGE = {
    _truncated: r"does not load: it is not a complete file of torch\.save \(1000 bytes: truncated, or another format\)",
    _empty: r"does not load: it is empty \(0 bytes\)",
    _a_module: r"does not load: it holds a pickled torch\.nn\.modules\.linear\.Linear, not only tensors",
    _a_tensor: r"is neither a policy file nor a training checkpoint: it holds a Tensor, not a dict",
    _other_weights: r"is neither a policy file nor a training checkpoint: it lacks \['config', 'loss', 'normalizer'\]",
    _other_sizes: r"does not hold a whole policy: RuntimeError: Error\(s\) in loading state_dict .* size mismatch for ",
}


@pytest.mark.parametrize("damage", POLICY_DAMAGE, ids=lambda damage: damage.__name__.strip("_"))
def test_a_damaged_or_foreign_policy_file_is_named_with_what_is_wrong(tiny_run, tmp_path, capsys, damage):
    policy_file = copy_run(tiny_run, tmp_path / "run") / POLICY_NAME
    damage(policy_file)
    with pytest.raises(UnreadableFileError, match=f"^{policy_file} {POLICY_DAMAGE[damage]}"):
        load_policy(policy_file)
    with pytest.raises(SystemExit) as exit_info:
        main([str(policy_file.parent)])  # the run directory: read from its policy.pt
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.count("\n") == 1 and err.startswith(f"error: {policy_file} ")
