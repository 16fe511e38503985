"""The digital twin and the camera -> perception -> robot loop: accuracy, a full pick, and the safety rules."""

from __future__ import annotations

import sys

import cv2
import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs, step_mdp

from torchrl_cebp.sim2real import (
    SHIPPED_POLICY,
    SIDE_CAMERA_NAME,
    TWIN_CALIBRATION,
    CameraView,
    CubeLocator,
    CubePerception,
    ImageFolderCamera,
    MuJoCoTwinBackend,
    PerceptionStatus,
    ParallaxCorrection,
    RealLoopEnv,
    SafetyStatus,
    ScriptedPickPlace,
    TableCalibration,
    TwinCamera,
    Workspace,
    draw_perception,
    render_table_scene,
)
from torchrl_cebp.sim2real.__main__ import build_loop, main, parse_args, run
from torchrl_cebp.training import load_policy


@pytest.fixture(scope="module")
def twin() -> tuple[MuJoCoTwinBackend, TwinCamera]:
    backend = MuJoCoTwinBackend(seed=0)
    return backend, TwinCamera(backend)


def make_loop(backend: MuJoCoTwinBackend, camera: TwinCamera, **kwargs) -> RealLoopEnv:
    locator = CubeLocator(backend.calibration)
    parallax = ParallaxCorrection(backend.scene.camera_pos, locator.cube_size / 2)
    return RealLoopEnv(backend, camera, CubePerception(locator), parallax=parallax, **kwargs)


@pytest.fixture
def intact_twin(twin):
    """The shared twin with every marker on the table and the camera connected (tests break them)."""
    backend, camera = twin
    camera.lost = False
    for marker_id in TWIN_CALIBRATION.marker_ids:
        backend.env.model.geom(f"aruco_{marker_id}").pos[2] = TWIN_CALIBRATION.table_height + 0.0005
    return twin


@pytest.fixture
def loop(intact_twin):
    backend, camera = intact_twin
    env = make_loop(backend, camera, goal=np.array([0.5, 0.0, 0.2]))
    env.set_seed(0)
    return env


def test_calibration_read_from_the_model(twin, tmp_path):
    backend, _ = twin
    assert backend.calibration == TWIN_CALIBRATION
    out = tmp_path / "table.yaml"
    assert main(["calibrate", "backend=sim", f"out={out}"]) == 0
    assert TableCalibration.load(out) == TWIN_CALIBRATION


def test_perception_recovers_cube_within_1cm(intact_twin):
    backend, camera = intact_twin
    locator = CubeLocator(backend.calibration)
    parallax = ParallaxCorrection(backend.scene.camera_pos, locator.cube_size / 2)
    errors = []
    for seed in range(8):
        backend._seed = seed
        backend.reset()
        result = locator.locate(camera.read())
        assert result.ok, result.reason
        errors.append(np.linalg.norm(parallax(result.position) - backend.cube_position()))
    assert max(errors) < 0.01, errors


def test_specs(loop):
    check_env_specs(loop)


def test_scripted_policy_picks_through_camera_perception_robot(loop, twin):
    backend, _ = twin
    td = loop.rollout(40, ScriptedPickPlace(), break_when_any_done=False)
    assert (td["next", "safety_status"] == SafetyStatus.OK).all()
    assert bool(td["next", "is_success"][-1])
    goal = td["desired_goal"][-1].numpy()
    assert np.linalg.norm(backend.cube_position() - goal) < loop.layout.distance_threshold
    assert (backend.touch > 0).all()  # held in the air, not resting there


def test_one_hidden_marker_keeps_the_loop_acting_on_an_accurate_cube(loop, twin):
    backend, _ = twin
    td = loop.reset()
    backend.env.model.geom("aruco_2").pos[2] = -0.1  # as if the arm stood in front of it
    td = loop.step(td.set("action", torch.tensor([0.0, 0.0, 0.0, 1.0])))
    nxt = td["next"]
    assert nxt["safety_status"].item() == SafetyStatus.OK and nxt["perception_ok"].item()
    assert np.linalg.norm(nxt["cube_position"].numpy() - backend.cube_position()) < 0.01


def test_a_side_camera_finds_the_cube_the_main_camera_lost(intact_twin, tmp_path):
    backend, _ = intact_twin
    # The main camera sees the markers and no cube: recorded frames of the empty table.
    cv2.imwrite(str(tmp_path / "frame_000.png"), render_table_scene(TWIN_CALIBRATION, None))
    blind = ImageFolderCamera(tmp_path, loop=True)
    alone = RealLoopEnv(backend, blind, CubePerception(CubeLocator(backend.calibration)))
    assert alone.reset()["perception_status"].item() == PerceptionStatus.CUBE
    side = TwinCamera(backend, SIDE_CAMERA_NAME)
    view = CameraView.calibrated(side, backend.calibration, side.position)
    env = RealLoopEnv(backend, blind, CubePerception(CubeLocator(backend.calibration)), more_views=[view])
    td = env.reset()
    assert td["perception_ok"].item() and len(env.last_frames) == 2
    assert np.linalg.norm(td["cube_position"].numpy() - backend.cube_position()) < 0.01
    # Where the camera is not known, its view is not corrected for the cube's height: still found, less exactly.
    uncorrected = CameraView.calibrated(side, backend.calibration)
    assert uncorrected.parallax is None
    env = RealLoopEnv(backend, blind, CubePerception(CubeLocator(backend.calibration)), more_views=[uncorrected])
    assert 0.01 < np.linalg.norm(env.reset()["cube_position"].numpy() - backend.cube_position()) < 0.05
    side.close()


def test_debug_with_the_side_camera_writes_both_views(tmp_path):
    import imageio.v3 as iio

    assert main(["debug", f"out={tmp_path}", "steps=2", "side_camera=true", f"video={tmp_path / 'both.mp4'}"]) == 0
    main_frame, side_frame = (cv2.imread(str(folder / "frame_0001.png")) for folder in (tmp_path, tmp_path / "side"))
    assert (tmp_path / "side" / "raw" / "frame_0001.png").exists() and (main_frame != side_frame).any()
    assert iio.imread(tmp_path / "both.mp4").shape[1:3] == (main_frame.shape[0], 2 * main_frame.shape[1])


def test_gripper_closed_beside_the_cube_does_not_carry_it():
    # Episode 11 of seed 0: the shipped policy closes its fingers to the cube's width beside the cube and
    # moves on. The loop used to take the cube for held and let it travel with the gripper, 8 cm from where
    # it truly lay; the cameras, which still see it on the table, now overrule the gripper.
    env, backend = build_loop(parse_args(["run", "backend=sim", "side_camera=true"])[1])
    policy = load_policy(SHIPPED_POLICY)
    for _ in range(11):
        env.reset()  # the placements and goals of episodes 0-10, without running them
    td, errors = env.reset(), []
    with torch.no_grad():
        for _ in range(12):
            td = env.step(policy(td))
            errors.append(np.linalg.norm(td["next", "cube_position"].numpy() - backend.cube_position()))
            td = step_mdp(td)
    assert max(errors) < env.layout.cube_size, np.round(errors, 3)
    for view in env.views:
        view.camera.close()


def test_markers_hidden_holds_still_with_reason(loop, twin):
    backend, _ = twin
    td = loop.reset()
    # One marker left in view cannot confirm that the camera has not moved.
    for marker_id in (1, 2, 3):
        backend.env.model.geom(f"aruco_{marker_id}").pos[2] = -0.1  # under the table top: out of view
    td = loop.step(td.set("action", torch.tensor([1.0, 0.0, 0.0, 1.0])))
    nxt = td["next"]
    assert nxt["safety_status"].item() == SafetyStatus.MARKERS and not nxt["perception_ok"].item()
    assert torch.isnan(nxt["observation"][3:9]).all() and torch.isnan(nxt["achieved_goal"]).all()
    before = backend.state().grip_pos.copy()
    td = loop.step(step_mdp(td).set("action", torch.tensor([1.0, 1.0, 1.0, 1.0])))
    np.testing.assert_allclose(backend.state().grip_pos, before, atol=2e-3)
    assert td["next", "safety_status"].item() == SafetyStatus.MARKERS


def test_command_outside_workspace_is_clamped(intact_twin):
    backend, camera = intact_twin
    high = (0.55, 0.3, 0.5)
    env = make_loop(backend, camera, workspace=Workspace(low=(0.3, -0.3, 0.01), high=high, max_step=0.05))
    td = env.reset()
    for _ in range(4):
        td = env.step(td.set("action", torch.tensor([1.0, 0.0, 0.0, 1.0])))
        td = step_mdp(td)
    assert td["clamped"].item()
    assert backend.state().grip_pos[0] <= high[0] + 0.005


def test_camera_lost_stops_robot_and_ends_episode(loop, twin):
    backend, camera = twin
    td = loop.reset()
    camera.lost = True
    td = loop.step(td.set("action", torch.tensor([0.0, 0.0, 0.5, 1.0])))
    nxt = td["next"]
    assert nxt["safety_status"].item() == SafetyStatus.CAMERA_LOST
    assert nxt["terminated"].item() and nxt["done"].item()
    assert backend.stopped
    with pytest.raises(RuntimeError, match="stopped"):
        backend.move(np.zeros(3), 1.0)


def test_cli_rejects_bad_values_naming_them(capsys):
    for argv, message in (
        (["run", "backend=ur5", "policy=scripted"], "invalid choice: 'ur5'"),
        (["run", "episodes=many", "policy=scripted"], "invalid int value: 'many'"),
        (["run", "checkpoint="], "checkpoint=PATH"),
        (["calibrate"], "the following arguments are required: --out"),
        (["fly"], "invalid choice: 'fly'"),
    ):
        with pytest.raises(SystemExit) as exit_:
            parse_args(argv)
        assert exit_.value.code == 2
        assert message in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["debug", "-h"], ["calibrate", "--help"],
                                  ["perceive", "--help"]])
@pytest.mark.parametrize(("program", "usage"), [("/src/torchrl_cebp/sim2real/__main__.py", "python -m torchrl_cebp.sim2real"),
                                              ("/venv/bin/torchrl-cebp-sim2real", "torchrl-cebp-sim2real")])
def test_help_prints_usage_as_typed_and_exits_0(argv, program, usage, capsys, monkeypatch):
    monkeypatch.setattr(sys, "argv", [program])
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 0
    assert f"usage: {usage} " in capsys.readouterr().out


def test_run_and_debug_share_the_loop_options():
    _, run = parse_args(["run", "policy=scripted", "camera_position=0.5,0,1.2", "--seed", "3"])
    _, debug = parse_args(["debug", "out=frames", "camera_position=0.5,0,1.2", "--seed", "3"])
    assert run["camera_position"] == debug["camera_position"] == (0.5, 0.0, 1.2)
    assert run["seed"] == debug["seed"] == 3 and debug["policy"] == "scripted"


def test_load_policy_reads_the_trainer_checkpoint(tmp_path):
    from tensordict import TensorDict

    from torchrl_cebp.agents import HERDDPGLoss, ObsGoalNormalizer, make_actor, make_critic
    from torchrl_cebp.training.checkpoint import save_checkpoint

    hidden = [16, 16]
    loss = HERDDPGLoss(make_actor(28, 4, hidden), make_critic(28, 4, hidden), gamma=0.98, action_l2=1.0)
    normalizer = ObsGoalNormalizer(25, 3)
    normalizer.update(TensorDict(observation=torch.randn(64, 25), desired_goal=torch.randn(64, 3), batch_size=[64]))
    state = {"config": {"agent": {"hidden": hidden}}, "loss": loss.state_dict(), "normalizer": normalizer.state_dict()}
    save_checkpoint(state, tmp_path)

    policy = load_policy(tmp_path)
    obs = TensorDict(observation=torch.randn(25), desired_goal=torch.randn(3))
    with loss.actor_network_params.to_module(loss.actor_network):
        expected = loss.actor_network(normalizer(obs.clone()))["action"]
    torch.testing.assert_close(policy(obs)["action"], expected)


def test_debug_annotates_the_frames_the_policy_acted_on(tmp_path, monkeypatch):
    from torchrl_cebp.sim2real.twin import TwinCamera

    read = TwinCamera.read
    frames = []
    monkeypatch.setattr(TwinCamera, "read", lambda self: frames.append(read(self)) or frames[-1])
    assert main(["debug", f"out={tmp_path}", "steps=3"]) == 0
    assert len(frames) == 4  # the reset's frame and one per step: no second read for the annotation
    locator = CubeLocator(TWIN_CALIBRATION)
    for i in range(3):
        raw = cv2.imread(str(tmp_path / "raw" / f"frame_{i:04d}.png"))
        np.testing.assert_array_equal(raw, frames[i])
        annotated = cv2.imread(str(tmp_path / f"frame_{i:04d}.png"))
        # The annotation's pixels: where drawing the same perception changes a black or a white canvas.
        found = locator.locate(raw)
        drawn = np.zeros(raw.shape[:2], bool)
        for blank in (np.zeros_like(raw), np.full_like(raw, 255)):
            drawn |= (draw_perception(blank, found) != blank).any(-1)
        assert 0.001 < drawn.mean() < 0.2
        np.testing.assert_array_equal(annotated[~drawn], raw[~drawn])  # the frame the policy saw, pixel for pixel
        assert (annotated[drawn] != raw[drawn]).any(-1).mean() > 0.5


def test_camera_only_mode_annotates_recorded_frames(tmp_path, capsys):
    assert main(["debug", f"out={tmp_path / 'debug'}", "steps=3"]) == 0  # records the raw frames too
    assert main(["perceive", f"frames={tmp_path / 'debug' / 'raw'}", f"out={tmp_path / 'annotated'}"]) == 0
    printed = capsys.readouterr().out
    assert "frame_0000.png: ok, cube at [" in printed
    assert len(list((tmp_path / "annotated").glob("*.png"))) == 3


def test_closed_loop_runs_a_trained_checkpoint_end_to_end(tmp_path, capsys):
    from tests.training.test_training import config
    from torchrl_cebp.training import train

    train(config("env=franka_pick_place", "sampler=cebp", "epochs=1", "cycles_per_epoch=1"), tmp_path)
    assert main(["run", f"checkpoint={tmp_path}", "backend=sim", "episodes=1"]) == 0
    assert "success rate" in capsys.readouterr().out


def test_twin_camera_survives_another_render_context_freed_after_it():
    # A MuJoCo render context's destructor frees its GL objects by id in whichever context is current:
    # an unreachable Fetch renderer collected after the twin's camera rendered used to wipe its textures.
    import gc

    from torchrl_cebp.envs import make_env_from_config

    other = make_env_from_config({"task": "push", "goal_space": "standard"}, seed=0, render_size=(64, 48))
    other.reset()
    other.render()
    del other  # unreachable, but held by reference cycles until the next collection
    backend = MuJoCoTwinBackend(seed=0)
    camera = TwinCamera(backend)
    backend.reset()
    first = camera.read()
    gc.collect()
    np.testing.assert_array_equal(camera.read(), first)
    camera.close()


def test_compare_sim_replays_the_loops_cube_placements_and_goals(monkeypatch, capsys):
    placements, goals = [], []
    reset, simulate = MuJoCoTwinBackend.reset, MuJoCoTwinBackend.simulate

    def recording_reset(self):
        reset(self)
        placements.append((id(self), self.cube_position()))

    def recording_simulate(self, policy, goal):
        goals.append(np.asarray(goal).copy())
        return simulate(self, policy, goal)

    monkeypatch.setattr(MuJoCoTwinBackend, "reset", recording_reset)
    monkeypatch.setattr(MuJoCoTwinBackend, "simulate", recording_simulate)
    report = run({**parse_args(["run", "policy=scripted", "episodes=2", "seed=5", "compare_sim=true"])[1]})
    loop_backend, truth_backend = placements[0][0], placements[1][0]
    loop_cubes = [cube for owner, cube in placements if owner == loop_backend]
    truth_cubes = [cube for owner, cube in placements if owner == truth_backend]
    assert len(loop_cubes) == len(truth_cubes) == 2 and truth_backend != loop_backend
    for loop_cube, truth_cube in zip(loop_cubes, truth_cubes):
        np.testing.assert_array_equal(loop_cube, truth_cube)
    assert not np.array_equal(loop_cubes[0], loop_cubes[1])  # the stream moves on between episodes
    assert goals[0].tolist() != goals[1].tolist()
    assert report["steps"] == 2 * 100  # two whole episodes of the twin's 100 steps
    out = capsys.readouterr().out
    assert "(plain simulation)" in out
    # The scripted grasp truly places the cube, and the loop's own score agrees.
    assert report["true_success"] == report["camera_loop_success"] == 1.0
    # The plain-simulation rate is that of a fresh twin of the same seed replaying those episodes.
    loop_goals = [goal.copy() for goal in goals]
    fresh = MuJoCoTwinBackend(seed=5)
    replayed = [fresh.simulate(ScriptedPickPlace(), goal) for goal in loop_goals]
    assert report["simulation_success"] == np.mean(replayed) and any(replayed)
    assert f"success rate {np.mean(replayed):.2f} over the same cube placements and goals (plain simulation)" in out
    assert "1.00 by the twin's true cube position" in out


def test_compare_sim_needs_the_twin(capsys):
    with pytest.raises(SystemExit) as exit_info:
        parse_args(["run", "policy=scripted", "backend=franky", "host=1.2.3.4", "compare_sim=true"])
    assert exit_info.value.code == 2 and "compare_sim=true needs backend=sim" in capsys.readouterr().err


def test_debug_writes_the_annotated_frames_as_an_mp4(tmp_path):
    import imageio.v3 as iio

    assert main(["debug", f"out={tmp_path}", "steps=4", f"video={tmp_path / 'episode.mp4'}"]) == 0
    frames = iio.imread(tmp_path / "episode.mp4")
    assert frames.shape[0] == 4 and frames.shape[-1] == 3
    first = cv2.cvtColor(cv2.imread(str(tmp_path / "frame_0000.png")), cv2.COLOR_BGR2RGB)
    assert np.abs(frames[0, : first.shape[0]].astype(int) - first).mean() < 8  # the same picture, through H.264
    assert main(["debug", f"out={tmp_path / 'x'}", "video=episode.avi"]) == 2
