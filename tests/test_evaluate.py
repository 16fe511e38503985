"""The evaluation command: success rate of a checkpoint and a video of its episodes."""
import imageio.v3 as iio
import pytest

from tests.training.test_training import config
from torchrl_cebp.evaluate import main, record_video, success_rate
from torchrl_cebp.training import train


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    run = tmp_path_factory.mktemp("run")
    train(config("sampler=her", "env=push", "epochs=1"), run)
    return run


def test_success_rate_over_n_episodes(run_dir, capsys):
    rate = success_rate(run_dir, episodes=4)
    assert rate in (0.0, 0.25, 0.5, 0.75, 1.0)
    main([str(run_dir), "--episodes", "2"])
    assert "success rate over 2 episodes" in capsys.readouterr().out


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
