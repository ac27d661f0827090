"""trajectory_generator alone: plans from the joint states' tool pose, streams the line, rejects bad targets."""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Path
from node_harness import Harness, statuses, without_acceleration_limits
from sensor_msgs.msg import JointState

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform
from manip_kin.motion.lines import distance_to_segment
from manip_kin.ros.nodes.trajectory_generator import TrajectoryGeneratorNode
from manip_kin.ros.wire.messages import (
    make_joint_state,
    make_pose_stamped,
    ns_to_stamp,
    pose_stamped_to_matrix,
    stamp_key,
    stamp_to_ns,
    twist_to_arrays,
)

MODEL = load_robot("irb120")
Q0 = np.zeros(6)
START = frame_pose(MODEL, Q0)  # [0.374, 0, 0.630], orientation I
TARGET = make_transform(np.eye(3), [0.374, 0.15, 0.55])


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def _start(harness, **params):
    goals = harness.collect(PoseStamped, "/goal_pose")
    twists = harness.collect(TwistStamped, "/goal_twist")
    paths = harness.collect(Path, "/planned_path", latched=True)
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    node = harness.start(TrajectoryGeneratorNode, robot="irb120", rate_hz=200.0, **params)
    for topic, msg_type in (("/line_target", PoseStamped), ("/joint_states", JointState)):
        harness.wait_matched(topic, msg_type)
    # And the other way: the node's streams reach this test's subscriptions from the first goal
    # on (a line started before they match would lose its first goals).
    assert harness.spin_until(
        lambda: (
            node.stream._goal_pub.get_subscription_count() > 0 and node.stream._twist_pub.get_subscription_count() > 0
        ),
        5,
    )
    return node, goals, twists, paths, diagnostics


def _state_stream(harness, q=Q0):
    def stream():
        # Stamped now: the generator judges the joint state's age by its stamp.
        now = harness.node.get_clock().now().to_msg()
        harness.publish("/joint_states", make_joint_state(MODEL.joint_names, q, stamp=now))

    return stream


#: The jerk limit of the jerk_limited line [m/s³]: the 1 m/s² is reached in 0.05 s.
JERK = 20.0


def _double_s_progress(times, length):
    """Progress of the line at ``times`` [s]: its jerk schedule (±JERK while the acceleration
    ramps, none while it is held at 1 m/s² or cruising at 0.3 m/s) integrated three times."""
    rise, held, ramp = 1.0 / JERK, 0.3 / 1.0 - 1.0 / JERK, 0.3 / 1.0 + 1.0 / JERK
    cruise = length / 0.3 - ramp
    up = [(rise, JERK), (held, 0.0), (rise, -JERK)]
    schedule = [*up, (cruise, 0.0), *[(span, -jerk) for span, jerk in up]]
    dt = 1e-5
    jerk = np.concatenate([np.full(int(round(span / dt)), value) for span, value in schedule])
    acceleration = np.cumsum(jerk) * dt
    speed = np.cumsum(acceleration) * dt
    position = np.concatenate([[0.0], np.cumsum(speed) * dt])
    return np.interp(times, np.arange(position.size) * dt, position / position[-1])


@pytest.mark.parametrize("scaling", ["trapezoidal", "quintic", "constant", "jerk_limited"])
def test_streams_line_then_holds(harness, scaling):
    # A constant line is a velocity step: it runs only without joint acceleration limits.
    limits = without_acceleration_limits(MODEL.joint_names) if scaling == "constant" else {}
    node, goals, twists, paths, diagnostics = _start(
        harness,
        time_scaling=scaling,
        max_linear_velocity=0.3,
        max_linear_acceleration=1.0,
        max_linear_jerk=JERK,
        path_points=17,
        **limits,
    )
    stream = _state_stream(harness)
    harness.spin_for(0.1, every=stream)
    assert not goals  # nothing streamed before a target
    harness.publish("/line_target", make_pose_stamped(TARGET, "base_link", ns_to_stamp(77)))
    assert harness.spin_until(lambda: node.state == "holding", 5, every=stream)
    # The final goal (the target itself) and its twist are published as the line ends: wait for them.
    assert harness.spin_until(
        lambda: (
            goals
            # exactly (np.allclose's default rtol accepted a goal 2e-7 short of the end: seen)
            and np.abs(pose_stamped_to_matrix(goals[-1]) - TARGET).max() <= 1e-12
            and len(twists) == len(goals)
            and paths
        ),
        5,
        every=stream,
    )
    length = np.linalg.norm(TARGET[:3, 3] - START[:3, 3])
    path = paths[-1]
    assert path.header.frame_id == "base_link" and len(path.poses) == 17  # path_points (default 50)
    np.testing.assert_allclose(pose_stamped_to_matrix(path.poses[0]), START, atol=1e-9)
    np.testing.assert_allclose(pose_stamped_to_matrix(path.poses[-1]), TARGET, atol=1e-9)
    assert all(g.header.frame_id == "base_link" for g in goals) and len(goals) == len(twists)
    positions = np.array([[g.pose.position.x, g.pose.position.y, g.pose.position.z] for g in goals])
    assert distance_to_segment(positions, START[:3, 3], TARGET[:3, 3]).max() < 1e-9
    progress = np.linalg.norm(positions - START[:3, 3], axis=1)
    assert np.all(np.diff(progress) >= -1e-12)
    stamps = [stamp_to_ns(g.header.stamp) for g in goals]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    duration = (stamps[-1] - stamps[0]) * 1e-9
    expected = {
        "constant": length / 0.3,
        "quintic": max(1.875 * length / 0.3, math.sqrt(5.7735 * length / 1.0)),
        # 1 m/s² reached at the jerk in 0.05 s and held; 0.3 m/s reached at 0.35 s; cruise between.
        "jerk_limited": length / 0.3 + 0.3 / 1.0 + 1.0 / JERK,
    }
    if scaling in expected:
        # The timing is checked on the stamps, not on the wall clock of this test: inverting the
        # closed-form profile s(t) at each goal's progress gives the time into the line at which
        # it was sampled; stamp minus that time must be the same for every goal (the line's
        # start). A late cycle shifts a stamp and its sample time together, not the relation;
        # Goals near the
        # ends, where the quintic is flat and the inversion ill-conditioned, are left out.
        # Sampling uses the cycle's start time, the stamp is read when publishing, and a loaded
        # machine can preempt the loop in between (40 ms was seen once): 90 % of the goals must
        # agree to 2 ms, none be off by 0.1 s. A wrong profile drifts by 100s of ms across them all.
        total = expected[scaling]
        grid = np.linspace(0.0, 1.0, 200001)
        profile = {
            "constant": grid,
            "quintic": 10 * grid**3 - 15 * grid**4 + 6 * grid**5,
            "jerk_limited": _double_s_progress(grid * total, length),
        }[scaling]
        inner = [(t, d / length) for t, d in zip(stamps, progress) if 0.05 < d / length < 0.95]
        assert len(inner) >= 5  # (a loaded machine runs the 200 Hz loop slower: 17 were seen)
        starts = [t * 1e-9 - np.interp(fraction, profile, grid) * total for t, fraction in inner]
        deviation = np.abs(np.array(starts) - np.median(starts))
        assert np.percentile(deviation, 90) < 0.002 and deviation.max() < 0.1, deviation
        assert duration >= total - 0.1  # the line does not end early (stamping jitter, as above)
    speeds = np.array([np.linalg.norm(twist_to_arrays(t.twist)[1]) for t in twists])
    assert speeds.max() <= 0.3 + 1e-9
    # Twist direction is the line direction; the last goal is the target with zero twist.
    direction = (TARGET[:3, 3] - START[:3, 3]) / length
    moving = [twist_to_arrays(t.twist)[1] for t in twists if np.linalg.norm(twist_to_arrays(t.twist)[1]) > 1e-6]
    np.testing.assert_allclose([v / np.linalg.norm(v) for v in moving], np.tile(direction, (len(moving), 1)), atol=1e-9)
    np.testing.assert_allclose(pose_stamped_to_matrix(goals[-1]), TARGET, atol=1e-12)
    assert not any(np.concatenate(twist_to_arrays(twists[-1].twist)))
    # Holding: no more streaming.
    count = len(goals)
    harness.spin_for(0.2, every=stream)
    assert len(goals) == count
    held = [s for s in statuses(diagnostics, "trajectory_generator") if s.message == "holding"]
    values = {kv.key: kv.value for kv in held[-1].values}
    assert values["target_stamp"] == "0.000000077" and values["final_goal_stamp"] == stamp_key(goals[-1].header.stamp)


def test_rejects_bad_and_unreachable_targets(harness, capfd):
    node, goals, _, _, diagnostics = _start(harness)
    stream = _state_stream(harness)
    harness.spin_for(0.1, every=stream)
    nan = make_pose_stamped(TARGET, "base_link")
    nan.pose.position.z = math.nan
    wrong_frame = make_pose_stamped(TARGET, "tool0")
    zero_quat = make_pose_stamped(TARGET, "base_link")
    zero_quat.pose.orientation.w = 0.0
    unreachable = make_pose_stamped(make_transform(np.eye(3), [1.5, 0.0, 0.6]), "base_link", ns_to_stamp(5))
    for msg in (nan, wrong_frame, zero_quat, unreachable):
        harness.publish("/line_target", msg)
    assert harness.spin_until(lambda: node.supervisor.rejected_targets == 4, 5, every=stream)
    harness.spin_for(0.1, every=stream)
    assert not goals and node.state == "rejected"
    logged = capfd.readouterr().err
    assert "NaN or infinity" in logged and "'tool0' is not the base frame" in logged and "has length 0" in logged
    assert "leaves the arm's reach" in logged
    values = {kv.key: kv.value for kv in statuses(diagnostics, "trajectory_generator")[-1].values}
    assert values["rejected_stamp"] == "0.000000005" and "reach" in values["last_rejection"]
    # Still works afterwards.
    harness.publish("/line_target", make_pose_stamped(TARGET, "base_link"))
    assert harness.spin_until(lambda: node.state == "holding", 5, every=stream)


def test_no_old_or_bad_joint_state_rejected(harness):
    node, goals, _, _, _ = _start(harness, joint_state_timeout=0.5)
    harness.publish("/line_target", make_pose_stamped(TARGET, "base_link"))
    assert harness.spin_until(lambda: node.supervisor.rejected_targets == 1, 3)
    assert "no current /joint_states" in node.supervisor.last_rejection and not goals
    # A joint state stamped 0.7 s ago is too old to start a line from with a 0.5 s timeout...
    old = ns_to_stamp(harness.node.get_clock().now().nanoseconds - 700_000_000)
    harness.publish("/joint_states", make_joint_state(MODEL.joint_names, Q0, stamp=old))
    harness.spin_for(0.1)
    harness.publish("/line_target", make_pose_stamped(TARGET, "base_link"))
    assert harness.spin_until(lambda: node.supervisor.rejected_targets == 2, 3)
    assert "no current /joint_states" in node.supervisor.last_rejection and not goals
    # ... and current with a 1 s timeout: the line starts.
    from rclpy.parameter import Parameter

    node.set_parameters([Parameter("joint_state_timeout", value=1.0)])
    harness.publish("/joint_states", make_joint_state(MODEL.joint_names, Q0, stamp=old))
    harness.spin_for(0.1)
    harness.publish("/line_target", make_pose_stamped(TARGET, "base_link"))
    assert harness.spin_until(lambda: node.state in ("streaming", "holding"), 3)
    # A current state missing a joint: rejected with the joint named, nothing streamed anew.
    assert harness.spin_until(lambda: node.state == "holding", 5)
    harness.spin_for(0.1)  # the final goal arrives
    count = len(goals)
    now = harness.node.get_clock().now().to_msg()
    harness.publish("/joint_states", make_joint_state(MODEL.joint_names[:5], Q0[:5], stamp=now))
    harness.spin_for(0.1)
    harness.publish("/line_target", make_pose_stamped(START, "base_link"))
    assert harness.spin_until(lambda: node.supervisor.rejected_targets == 3, 3)
    assert "lacks joints" in node.supervisor.last_rejection and MODEL.joint_names[5] in node.supervisor.last_rejection
    harness.spin_for(0.1)
    assert node.state == "rejected" and len(goals) == count


def test_a_target_sent_again_is_not_planned_again(harness):
    """A client that missed the generator's report sends the target again with its stamp:
    the running line goes on (no second plan from where the arm is by then); a new stamp
    with the same pose is a new target."""
    node, goals, _, paths, _ = _start(harness, max_linear_velocity=0.1)
    stream = _state_stream(harness)
    harness.spin_for(0.1, every=stream)
    target = make_pose_stamped(TARGET, "base_link", harness.node.get_clock().now().to_msg())
    harness.publish("/line_target", target)
    assert harness.spin_until(lambda: node.state == "streaming" and len(goals) > 20, 3, every=stream)
    started = node.supervisor.started_ns
    stream = _state_stream(harness, np.array([0.05, 0.1, -0.05, 0.1, -0.1, 0.2]))  # the arm moved on
    harness.spin_for(0.1, every=stream)
    harness.publish("/line_target", target)
    harness.spin_for(0.3, every=stream)
    assert len(paths) == 1 and node.supervisor.started_ns == started and node.state == "streaming"
    target.header.stamp = harness.node.get_clock().now().to_msg()
    harness.publish("/line_target", target)
    assert harness.spin_until(lambda: len(paths) == 2, 3, every=stream)
    assert node.supervisor.started_ns > started


def test_new_target_preempts_from_current_pose(harness):
    node, goals, _, paths, _ = _start(harness, max_linear_velocity=0.1)
    stream = _state_stream(harness)
    harness.spin_for(0.1, every=stream)
    harness.publish("/line_target", make_pose_stamped(TARGET, "base_link"))
    assert harness.spin_until(lambda: node.state == "streaming" and len(goals) > 20, 3, every=stream)
    # The arm is now elsewhere: the new line starts from the tool pose of its joint state.
    q_moved = np.array([0.05, 0.1, -0.05, 0.1, -0.1, 0.2])
    moved = frame_pose(MODEL, q_moved)
    second = make_transform(np.eye(3), [0.40, -0.05, 0.60])
    stream = _state_stream(harness, q_moved)
    harness.spin_for(0.1, every=stream)
    harness.publish("/line_target", make_pose_stamped(second, "base_link"))
    assert harness.spin_until(lambda: len(paths) >= 2, 3, every=stream)
    np.testing.assert_allclose(pose_stamped_to_matrix(paths[-1].poses[0]), moved, atol=1e-6)
    assert harness.spin_until(lambda: node.state == "holding", 5, every=stream)
    # The final pose is published as the line ends; let it arrive before looking at it.
    assert harness.spin_until(
        lambda: np.abs(pose_stamped_to_matrix(goals[-1]) - second).max() <= 1e-12, 5, every=stream
    )
    np.testing.assert_allclose(pose_stamped_to_matrix(goals[-1]), second, atol=1e-12)
