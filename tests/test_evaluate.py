"""The evaluation command: success rate of a checkpoint and a video of its episodes."""
import imageio.v3 as iio
import numpy as np
import pytest
import torch
from tensordict import TensorDict

from tests.training.test_training import config
from torchrl_cebp.evaluate import main, record_video, success_rate
from torchrl_cebp.envs import make_touch_fetch
from torchrl_cebp.training import load_policy, train


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    run = tmp_path_factory.mktemp("run")
    train(config("sampler=her", "env=push", "epochs=1"), run)
    return run


def test_success_rate_over_n_episodes(run_dir, capsys):
    main([str(run_dir), "--episodes", "2"])
    assert "success rate over 2 episodes" in capsys.readouterr().out


def test_success_rate_on_the_checkpoints_own_robot_equals_a_plain_gymnasium_loop(tmp_path):
    # The released code's robot (7-D actions): the evaluation must rebuild it from the checkpoint.
    train(config("sampler=her", "env=push_released", "epochs=1"), tmp_path)
    policy = load_policy(tmp_path)
    successes = []
    for i in range(4):
        env = make_touch_fetch("push", "extended", control="joint", touch_ignores_table=True)
        obs, _ = env.reset(seed=1234 + i)  # success_rate seeds simulation i with seed + i
        for _ in range(env.max_episode_steps):
            td = TensorDict({key: torch.as_tensor(obs[key], dtype=torch.float32) for key in ("observation", "desired_goal")})
            with torch.no_grad():
                action = policy(td)["action"].numpy()
            obs, _, _, _, info = env.step(action)
        successes.append(float(info["is_success"]))
    assert success_rate(tmp_path, episodes=4, seed=1234) == pytest.approx(np.mean(successes))


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_video_has_one_frame_per_step(run_dir, tmp_path, suffix):
    path = record_video(run_dir, tmp_path / f"episode{suffix}", episodes=1, size=(64, 48))
    frames = iio.imread(path)
    assert frames.shape[0] == 51 and frames.shape[1:3] == (48, 64)
    assert frames.std() > 5  # a rendered scene, not a blank frame


def test_bad_video_format_and_missing_checkpoint(run_dir, tmp_path):
    with pytest.raises(ValueError, match="'.avi'.*mp4.*gif"):
        record_video(run_dir, tmp_path / "x.avi")
    with pytest.raises(FileNotFoundError):
        success_rate(tmp_path / "nowhere")
