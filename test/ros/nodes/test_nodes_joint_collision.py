"""cartesian_controller with collision_avoidance: joint references and jogs are collision-limited too.

The arm holds its last command (test/support/held_arm.py); every distance asserted is computed in
closed form over every position the fake arm integrated (the ball arm's spheres against a box,
test/support/collision_robots.py), not through the controller's checker.
"""

import numpy as np
import pytest
from collision_robots import BALL_ARM_URDF
from held_arm import start_held_arm
from node_harness import Harness
from sensor_msgs.msg import JointState
from test_nodes_collision import (
    ARM_COMMAND_TIMEOUT,
    GOAL_Q,
    SAFETY,
    START_Q,
    _ball_box_distance,
    _box_marker,
    _reported,
)
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.motion.joint_trajectory import TrajectoryPoint
from manip_kin.pipeline.outcome import goal_outcome
from manip_kin.ros.nodes.trajectory_generator import TrajectoryGeneratorNode
from manip_kin.ros.wire.joint_messages import make_joint_trajectory
from manip_kin.ros.wire.messages import make_joint_state, stamp_key

#: Too tall for the arm to pass over or under: a joint reference across it is blocked.
PILLAR = (0.08, 0.08, 0.6)


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


@pytest.fixture(scope="module")
def ball_urdf(tmp_path_factory):
    path = tmp_path_factory.mktemp("ball") / "ball_arm.urdf"
    path.write_text(BALL_ARM_URDF)
    return str(path)


def _start_with_pillar(harness, ball_urdf, **params):
    model = load_robot(ball_urdf)
    centre = 0.5 * (frame_pose(model, START_Q)[:3, 3] + frame_pose(model, GOAL_Q)[:3, 3])
    assert _ball_box_distance(model, START_Q, centre, PILLAR) > 0.05
    model, hardware, node, diagnostics = start_held_arm(
        harness,
        ball_urdf,
        START_Q,
        # Below the damper's hold time, as test_nodes_collision.py's arm. With commands held
        # forever a full run once took the ball to 13.6 mm: what a stall longer than the hold
        # time does (test_a_stall_within_the_arms_command_timeout_keeps_the_safety_distance).
        arm_command_timeout=ARM_COMMAND_TIMEOUT,
        collision_avoidance=True,
        collision_safety_distance=SAFETY,
        collision_pair_samples=100,
        **params,
    )
    topic = f"{node.test_namespace}/collision_objects"
    harness.wait_matched(topic, MarkerArray)
    harness.publish(topic, _box_marker(centre, PILLAR))
    assert harness.spin_until(lambda: len(node.collision.scene) == 1, 3)
    return model, hardware, node, diagnostics, centre


def _nearest(model, hardware, centre) -> tuple[float, float]:
    """The least distance over the arm's history, and the last one [m]."""
    distances = [_ball_box_distance(model, q, centre, PILLAR) for q in list(hardware.history)]
    return min(distances), distances[-1]


def _send_reference(harness, node, model, q) -> str:
    msg = make_joint_state(model.joint_names, q, np.zeros(model.dof), harness.node.get_clock().now().to_msg())
    harness.publish(f"{node.test_namespace}/joint_reference", msg)
    return stamp_key(msg.header.stamp)


def test_a_joint_reference_behind_an_obstacle_ends_blocked_without_contact(harness, ball_urdf):
    model, hardware, node, diagnostics, centre = _start_with_pillar(harness, ball_urdf, gain_joint=3.0)
    try:
        harness.wait_matched(f"{node.test_namespace}/joint_reference", JointState)
        stamp = _send_reference(harness, node, model, GOAL_Q)  # j1 sweeps the arm through the pillar
        assert harness.spin_until(lambda: node.state == "blocked", 10), (node.state, node.detail)
        assert "obstacle:cell/1" in node.detail
        assert harness.spin_until(lambda: node.command_filter.at_rest, 3)  # blocked: at rest
        nearest, _ = _nearest(model, hardware, centre)
        assert nearest >= SAFETY - 1e-3, nearest
        assert np.abs(hardware.positions() - GOAL_Q).max() > 0.5  # held off, far from the reference
        state, values = _reported(harness, diagnostics, node, "blocked")
        outcome = goal_outcome(values, state, stamp)
        assert outcome.word == "blocked" and outcome.exit_code == 1 and "obstacle:cell/1" in outcome.reason
        assert values["goal_kind"] == "joint" and float(values["joint_error"]) > 0.5
        assert values["nearest_pair"].endswith("obstacle:cell/1")
        assert float(values["nearest_distance"]) == pytest.approx(SAFETY, abs=5e-3)
        # Back to where it came from: clear of the pillar, reached.
        _send_reference(harness, node, model, START_Q)
        assert harness.spin_until(lambda: node.state == "converged", 10), (node.state, node.detail)
        np.testing.assert_allclose(hardware.positions(), START_Q, atol=2e-3)
    finally:
        hardware.close()


def test_a_jog_into_an_obstacle_stops_at_the_safety_distance(harness, ball_urdf):
    model, hardware, node, _, centre = _start_with_pillar(harness, ball_urdf)
    try:
        topic = f"{node.test_namespace}/joint_jog"
        harness.wait_matched(topic, JointState)

        def send():
            msg = JointState(name=["j1"], velocity=[0.3])
            msg.header.stamp = harness.node.get_clock().now().to_msg()
            harness.publish(topic, msg)

        harness.spin_for(3.0, every=send)  # 0.9 rad of commanded travel: the pillar is 0.2 rad away
        assert node.supervisor.goal_kind == "jog"
        nearest, last = _nearest(model, hardware, centre)
        assert nearest >= SAFETY - 1e-3, nearest
        assert last < SAFETY + 0.01  # it went up to the pillar
    finally:
        hardware.close()


def test_a_joint_trajectory_through_an_obstacle_stops_short_and_ends_blocked(harness, ball_urdf):
    """As ``manip_kin move`` does it: trajectory_generator (its own collision check off) streams
    joint_reference samples to the controller."""
    model, hardware, node, _, centre = _start_with_pillar(harness, ball_urdf, gain_joint=3.0)
    try:
        namespace = node.test_namespace
        generator = harness.start(TrajectoryGeneratorNode, namespace=namespace, robot=ball_urdf, rate_hz=250.0)
        harness.wait_matched(f"{namespace}/joint_trajectory", JointTrajectory)
        # The generator reads the newest joint state when a trajectory comes: let the arm's arrive first.
        assert harness.spin_until(lambda: hardware._joint_states.get_subscription_count() > 1, 5)
        harness.spin_for(0.1)
        trajectory = make_joint_trajectory(model.joint_names, [TrajectoryPoint(2.0, GOAL_Q.tolist())])
        trajectory.header.stamp = harness.node.get_clock().now().to_msg()
        harness.publish(f"{namespace}/joint_trajectory", trajectory)
        assert harness.spin_until(lambda: generator.state == "streaming", 5), generator.state
        assert harness.spin_until(lambda: node.state == "blocked", 10), (node.state, node.detail)
        assert "obstacle:cell/1" in node.detail and node.supervisor.goal_kind == "joint"
        assert harness.spin_until(lambda: node.command_filter.at_rest, 3)
        nearest, last = _nearest(model, hardware, centre)
        assert nearest >= SAFETY - 1e-3, nearest
        assert last < SAFETY + 0.01  # it went up to the pillar and stopped there
    finally:
        hardware.close()
