"""cartesian_controller alone: commands from the control law, state on /diagnostics, rejections."""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from node_harness import Harness, statuses
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.control import CartesianController, ControllerConfig
from manip_kin.kinematics import frame_pose
from manip_kin.nodes import conversions as conv
from manip_kin.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.robots import load_robot
from manip_kin.rotations import make_transform, rpy_to_matrix

MODEL = load_robot("genova7")
Q0 = MODEL.start_configuration()
GOAL = make_transform(rpy_to_matrix(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])
RATE = 250.0


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def _values(status):
    return {kv.key: kv.value for kv in status.values}


def _joint_state(q, names=None):
    names = MODEL.joint_names if names is None else names
    order = [MODEL.joint_names.index(n) for n in names]
    return conv.make_joint_state(names, np.asarray(q)[order])


def _expected(goal, twist=None, q=Q0):
    return CartesianController(MODEL, ControllerConfig()).step(q, goal, twist, 1.0 / RATE).qdot


def _start(harness, **params):
    commands = harness.collect(Float64MultiArray, "/joint_velocity_commands")
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    node = harness.start(CartesianControllerNode, robot="genova7", rate_hz=RATE, **params)
    harness.wait_matched("/joint_states", JointState)
    harness.wait_matched("/goal_pose", PoseStamped)
    harness.wait_matched("/goal_twist", TwistStamped)
    return node, commands, diagnostics


def test_zeros_without_joint_state_or_goal_then_tracks(harness):
    node, commands, diagnostics = _start(harness)
    assert harness.spin_until(lambda: len(commands) > 10, 5)
    assert all(len(c.data) == 7 and not any(c.data) for c in commands)
    assert harness.spin_until(
        lambda: any(s.message == "stale input" for s in statuses(diagnostics, "cartesian_controller")), 3
    )
    # Joint states (names shuffled: matched by name) but no goal: idle, zeros.
    shuffled = list(reversed(MODEL.joint_names))
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0, shuffled))  # noqa: E731
    assert harness.spin_until(lambda: node.state == "idle", 3, every=stream)
    commands.clear()
    harness.spin_for(0.1, every=stream)
    assert commands and not any(commands[-1].data)
    # A goal: the command is the control law's at q0.
    goal_msg = conv.make_pose_stamped(GOAL, "base_link", conv.ns_to_stamp(123_000_000_456))
    harness.publish("/goal_pose", goal_msg)
    assert harness.spin_until(lambda: node.state in ("tracking", "joint-limited"), 3, every=stream)
    commands.clear()
    harness.spin_for(0.1, every=stream)
    np.testing.assert_allclose(commands[-1].data, _expected(GOAL), atol=1e-9)
    assert np.linalg.norm(commands[-1].data) > 0.1
    status = harness.spin_until(
        lambda: [
            s for s in statuses(diagnostics, "cartesian_controller") if _values(s)["goal_stamp"] == "123.000000456"
        ],
        3,
        every=stream,
    )[-1]
    values = _values(status)
    current = frame_pose(MODEL, Q0)
    assert math.isclose(float(values["position_error"]), np.linalg.norm(GOAL[:3, 3] - current[:3, 3]), rel_tol=1e-6)
    assert float(values["manipulability"]) > 0 and float(values["loop_rate_hz"]) > 0.5 * RATE
    # Joint states stop: stale input, zeros.
    assert harness.spin_until(lambda: node.state == "stale input", 2)
    commands.clear()
    harness.spin_for(0.1)
    assert commands and not any(commands[-1].data)


def test_feed_forward_used_while_fresh(harness):
    node, commands, _ = _start(harness, goal_twist_timeout=0.05)
    angular, linear = np.array([0.0, 0.0, 0.3]), np.array([0.05, 0.0, -0.02])

    def stream():
        harness.publish("/joint_states", _joint_state(Q0))
        harness.publish("/goal_twist", conv.make_twist_stamped(angular, linear, "base_link"))

    harness.publish("/goal_pose", conv.make_pose_stamped(GOAL, "base_link"))
    harness.spin_for(0.3, every=stream, period=0.005)
    np.testing.assert_allclose(commands[-1].data, _expected(GOAL, (angular, linear)), atol=1e-9)
    assert not np.allclose(_expected(GOAL, (angular, linear)), _expected(GOAL))
    # Twists stop: after goal_twist_timeout the pose error alone drives the command.
    harness.spin_for(0.2, every=lambda: harness.publish("/joint_states", _joint_state(Q0)))
    np.testing.assert_allclose(commands[-1].data, _expected(GOAL), atol=1e-9)


def test_bad_goals_rejected_previous_goal_kept(harness, capfd):
    node, commands, _ = _start(harness)
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    harness.publish("/goal_pose", conv.make_pose_stamped(GOAL, "base_link"))
    assert harness.spin_until(lambda: node.goal is not None, 3, every=stream)
    nan_goal = conv.make_pose_stamped(GOAL, "base_link")
    nan_goal.pose.position.x = math.nan
    long_quat = conv.make_pose_stamped(GOAL, "base_link")
    long_quat.pose.orientation.w, long_quat.pose.orientation.x = 0.9, 0.9
    wrong_frame = conv.make_pose_stamped(make_transform(np.eye(3), [0.1, 0.1, 0.1]), "world")
    bad_twist = conv.make_twist_stamped([math.inf, 0, 0], [0, 0, 0], "base_link")
    for msg in (nan_goal, long_quat, wrong_frame):
        harness.publish("/goal_pose", msg)
    harness.publish("/goal_twist", bad_twist)
    harness.publish("/joint_states", conv.make_joint_state(MODEL.joint_names[:3], [0.0, 0.0, 0.0]))
    assert harness.spin_until(
        lambda: node.rejected_goals == 3 and node.rejected_twists == 1 and node.rejected_joint_states == 1,
        3,
        every=stream,
    )
    commands.clear()
    harness.spin_for(0.1, every=stream)
    np.testing.assert_allclose(commands[-1].data, _expected(GOAL), atol=1e-9)
    logged = capfd.readouterr().err
    assert "NaN or infinity" in logged and "has length" in logged and "'world' is not the base frame" in logged
    assert "lacks joints" in logged


def test_converged_state(harness):
    node, commands, diagnostics = _start(harness, position_tolerance=1e-3, orientation_tolerance=1e-2)
    goal = frame_pose(MODEL, Q0)
    goal[2, 3] += 5e-4  # within tolerance
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    harness.publish("/goal_pose", conv.make_pose_stamped(goal, "base_link"))
    assert harness.spin_until(lambda: node.state == "converged", 3, every=stream)
    assert harness.spin_until(
        lambda: any(s.message == "converged" for s in statuses(diagnostics, "cartesian_controller")), 2, every=stream
    )
    assert np.linalg.norm(commands[-1].data) < 0.01
