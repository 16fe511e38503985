import cv2
import numpy as np
import pytest
import torch
from sim2real_frames import FRAME_SIZE, degrade
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs import EnvBase, TransformedEnv
from torchrl.envs.utils import check_env_specs

from torchrl_cebp.sim2real import (
    CameraLost,
    CubeLocator,
    CubePerception,
    FrameSource,
    ImageFolderCamera,
    PerceptionStatus,
    render_table_scene,
)

CUBE_XY = (0.55, -0.1)


class CameraOnlyEnv(EnvBase):
    """Emits the camera's frames as ``"pixels"``; the action is ignored (camera-only debug mode)."""

    def __init__(self, camera: FrameSource):
        super().__init__(batch_size=torch.Size([]))
        self.camera = camera
        self.observation_spec = Composite(
            pixels=Bounded(0, 255, shape=(*camera.expected_size, 3), dtype=torch.uint8)
        )
        self.action_spec = Unbounded(shape=(1,))
        self.reward_spec = Unbounded(shape=(1,))

    def _observe(self) -> TensorDictBase:
        return TensorDict(pixels=torch.from_numpy(self.camera.read()))

    def _reset(self, tensordict=None, **kwargs):
        return self._observe().update(self.full_done_spec.zero())

    def _step(self, tensordict):
        return self._observe().update(self.full_done_spec.zero()).set("reward", torch.zeros(1))

    def _set_seed(self, seed):
        return seed


@pytest.fixture
def frames(tmp_path, calibration):
    """Recorded frames: cube seen, cube seen, a marker covered, the camera moved with a marker covered, cube gone."""
    moved = np.array([[420, 40], [620, 260], [300, 470], [30, 180]], np.float32)  # the table's corners in the image
    scenes = [
        render_table_scene(calibration, CUBE_XY),
        degrade(render_table_scene(calibration, CUBE_XY), "all"),
        render_table_scene(calibration, CUBE_XY, occluded_markers=[0]),
        render_table_scene(calibration, CUBE_XY, occluded_markers=[0], table_corners_px=moved),
        render_table_scene(calibration, None),
    ]
    for i, frame in enumerate(scenes):
        cv2.imwrite(str(tmp_path / f"frame_{i:03d}.png"), frame)
    return tmp_path


def make_env(frames, calibration, loop):
    camera = ImageFolderCamera(frames, expected_size=FRAME_SIZE, loop=loop)
    return TransformedEnv(CameraOnlyEnv(camera), CubePerception(CubeLocator(calibration)))


def test_specs_check(frames, calibration):
    env = make_env(frames, calibration, loop=True)
    check_env_specs(env)
    spec = env.observation_spec
    assert spec["cube_position"].shape == (3,) and spec["cube_position"].dtype == torch.float32
    assert spec["perception_ok"].dtype == torch.bool
    assert spec["perception_status"].space.n == len(PerceptionStatus)


def test_rollout_writes_position_or_nan_never_stale(frames, calibration):
    env = make_env(frames, calibration, loop=False)
    # reset reads frame 0, the 4 steps frames 1-4.
    rollout = env.rollout(4, break_when_any_done=False)
    ok = torch.cat([rollout["perception_ok"][:1], rollout["next", "perception_ok"]])
    status = torch.cat([rollout["perception_status"][:1], rollout["next", "perception_status"]])
    position = torch.cat([rollout["cube_position"][:1], rollout["next", "cube_position"]])
    assert ok.tolist() == [True, True, True, False, False]
    # A covered marker is tolerated while the camera has not moved; once it has, nothing is mapped.
    assert [PerceptionStatus(s).reason for s in status.tolist()] == ["ok", "ok", "ok", "markers", "cube"]
    expected = torch.tensor([*CUBE_XY, calibration.table_height + 0.025])
    torch.testing.assert_close(position[:3], expected.expand(3, 3), atol=0.01, rtol=0)
    assert position[3:].isnan().all()
    with pytest.raises(CameraLost):
        env.rand_step(rollout[-1]["next"].clone())


def test_batched_rgb_pixels(calibration):
    bgr = np.stack([render_table_scene(calibration, CUBE_XY), render_table_scene(calibration, None)])
    rgb = torch.from_numpy(bgr[..., ::-1].copy())
    td = CubePerception(CubeLocator(calibration), in_key="rgb", channel_order="rgb", position_key=("cube", "pos"))(
        TensorDict(rgb=rgb, batch_size=[2])
    )
    assert td["cube", "pos"].shape == (2, 3) and td["perception_ok"].tolist() == [True, False]
    assert td["perception_status"].tolist() == [PerceptionStatus.OK, PerceptionStatus.CUBE]
    torch.testing.assert_close(td["cube", "pos"][0, :2], torch.tensor(CUBE_XY), atol=0.01, rtol=0)
    with pytest.raises(ValueError, match="channel_order"):
        CubePerception(CubeLocator(calibration), channel_order="hsv")
