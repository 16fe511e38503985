"""FrankyBackend's logic against a fake ``franky`` module that records its calls (the real one drives a Franka)."""
import sys
import types
from types import SimpleNamespace

import numpy as np
import pytest

from torchrl_cebp.sim2real import FrankyBackend

QUATERNION = [0.0, 1.0, 0.0, 0.0]  # the hand pointing down; moves must keep it
OPEN_WIDTH = 0.08


def fake_franky(calls: list) -> types.ModuleType:
    """A ``franky`` whose robot reaches every target at once and whose gripper reports the width it was sent to."""
    franky = types.ModuleType("franky")

    class Affine:
        def __init__(self, translation, quaternion):
            self.translation, self.quaternion = np.asarray(translation, dtype=np.float64), list(quaternion)

    class CartesianMotion:
        def __init__(self, target, reference):
            self.target, self.reference = target, reference

    class Robot:
        def __init__(self, host):
            calls.append(("Robot", host))
            self.relative_dynamics_factor = 1.0
            self._pose = Affine([0.3, 0.1, 0.4], QUATERNION)

        @property
        def current_cartesian_state(self):
            twist = SimpleNamespace(linear=[0.01, -0.02, 0.03])
            return SimpleNamespace(pose=SimpleNamespace(end_effector_pose=self._pose),
                                   velocity=SimpleNamespace(end_effector_twist=twist))

        def move(self, motion):
            calls.append(("move", motion.target.translation.tolist(), motion.target.quaternion, motion.reference))
            self._pose = motion.target

        def recover_from_errors(self):
            calls.append(("recover_from_errors",))

        def stop(self):
            calls.append(("stop",))

    class Gripper:
        def __init__(self, host):
            calls.append(("Gripper", host))
            self.width = 0.0

        def open(self, speed):
            calls.append(("open", speed))
            self.width = OPEN_WIDTH

        def grasp(self, width, speed, force, epsilon_outer):
            calls.append(("grasp", width, speed, force, epsilon_outer))
            self.width = width

    franky.Affine, franky.CartesianMotion, franky.Robot, franky.Gripper = Affine, CartesianMotion, Robot, Gripper
    franky.ReferenceType = SimpleNamespace(Absolute="Absolute", Relative="Relative")
    return franky


@pytest.fixture
def calls(monkeypatch):
    recorded: list = []
    monkeypatch.setitem(sys.modules, "franky", fake_franky(recorded))
    return recorded


def test_connects_to_the_robot_and_its_gripper_with_the_dynamics_factor(calls):
    backend = FrankyBackend("172.16.0.2", dynamics_factor=0.2)
    assert calls == [("Robot", "172.16.0.2"), ("Gripper", "172.16.0.2")]
    assert backend.robot.relative_dynamics_factor == 0.2


def test_reset_recovers_moves_the_grip_point_home_keeping_the_orientation_and_opens(calls):
    backend = FrankyBackend("robot", home=(0.5, 0.0, 0.225), grip_offset=(0.0, 0.0, 0.02))
    calls.clear()
    backend.reset()
    [recover, move, opened] = calls
    assert recover == ("recover_from_errors",) and opened == ("open", 0.05)
    # franky's end-effector frame sits 2 cm below the grip point: the target is home minus the offset
    assert move[0] == "move" and move[1] == pytest.approx([0.5, 0.0, 0.205]) and move[2:] == (QUATERNION, "Absolute")
    np.testing.assert_allclose(backend.state().grip_pos, [0.5, 0.0, 0.225])


def test_state_reports_the_grip_point_its_velocity_and_each_fingers_half_of_the_width(calls):
    backend = FrankyBackend("robot", grip_offset=(0.0, 0.0, 0.02))
    backend.gripper.width = 0.06
    state = backend.state()
    np.testing.assert_allclose(state.grip_pos, [0.3, 0.1, 0.42])
    np.testing.assert_allclose(state.grip_vel, [0.01, -0.02, 0.03])
    np.testing.assert_allclose(state.finger_pos, [0.03, 0.03])
    np.testing.assert_array_equal(state.finger_vel, [0.0, 0.0])
    assert state.gripper_width == pytest.approx(0.06)


def test_move_is_an_absolute_target_in_the_base_frame_and_the_gripper_switches_only_on_a_change(calls):
    backend = FrankyBackend("robot", grip_offset=(0.0, 0.0, 0.02), grasp_force=15.0, grasp_width=0.04)
    backend.reset()
    calls.clear()
    backend.move(np.array([0.01, -0.02, -0.03]), gripper=1.0)  # stays open: no gripper command
    backend.move(np.array([0.0, 0.0, 0.0]), gripper=-1.0)  # closes: one grasp
    backend.move(np.array([0.0, 0.0, 0.01]), gripper=-0.5)  # still closing: no second grasp
    backend.move(np.array([0.0, 0.0, 0.0]), gripper=0.5)  # opens
    moves = [call[1] for call in calls if call[0] == "move"]
    np.testing.assert_allclose(moves, [[0.51, -0.02, 0.175], [0.51, -0.02, 0.175], [0.51, -0.02, 0.185],
                                       [0.51, -0.02, 0.185]])
    assert [call for call in calls if call[0] != "move"] == [("grasp", 0.04, 0.05, 15.0, 0.04), ("open", 0.05)]
    assert all(call[2:] == (QUATERNION, "Absolute") for call in calls if call[0] == "move")


def test_a_stopped_robot_refuses_to_move_until_reset(calls):
    backend = FrankyBackend("robot")
    backend.stop()
    assert calls[-1] == ("stop",)
    with pytest.raises(RuntimeError, match=r"stopped; reset\(\) it before moving again"):
        backend.move(np.zeros(3), gripper=1.0)
    assert not any(call[0] == "move" for call in calls)
    backend.reset()
    backend.move(np.zeros(3), gripper=1.0)
    assert calls[-1][0] == "move"


def test_without_franky_the_backend_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "franky", None)  # an import of franky then fails
    with pytest.raises(ImportError, match=r"pip install 'torchrl-cebp\[real\]'"):
        FrankyBackend("robot")
