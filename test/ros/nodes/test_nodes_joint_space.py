"""Joint space through the nodes, in process: trajectory_generator streams joint_reference from a
joint_trajectory; cartesian_controller follows joint references; the latest goal of either kind wins."""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from node_harness import Harness, statuses, without_acceleration_limits
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform
from manip_kin.motion.joint_trajectory import TrajectoryPoint
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.nodes.trajectory_generator import TrajectoryGeneratorNode
from manip_kin.ros.wire.joint_messages import make_joint_trajectory
from manip_kin.ros.wire.messages import make_joint_state, make_pose_stamped, ns_to_stamp, stamp_key, stamp_to_ns

SCARA = load_robot("scara")
NAMES = SCARA.joint_names
Q0 = np.zeros(4)
RATE = 200.0


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def _now(harness):
    return harness.node.get_clock().now().to_msg()


def _state_stream(harness, q=Q0):
    """joint_states of a scara resting at ``q``, stamped now."""

    def stream():
        harness.publish("joint_states", make_joint_state(NAMES, q, stamp=_now(harness)))

    return stream


def _start_generator(harness, **params):
    references = harness.collect(JointState, "joint_reference")
    goals = harness.collect(PoseStamped, "goal_pose")
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    node = harness.start(TrajectoryGeneratorNode, robot="scara", rate_hz=RATE, **params)
    for topic, msg_type in (
        ("joint_trajectory", JointTrajectory),
        ("line_target", PoseStamped),
        ("joint_states", JointState),
    ):
        harness.wait_matched(topic, msg_type)
    return node, references, goals, diagnostics


def _trajectory(points, names=NAMES, stamp_ns=None, harness=None):
    msg = make_joint_trajectory(names, points)
    msg.header.stamp = ns_to_stamp(stamp_ns) if stamp_ns is not None else _now(harness)
    return msg


def _reference_samples(references):
    stamps = np.array([stamp_to_ns(r.header.stamp) for r in references])
    positions = np.array([r.position for r in references])
    velocities = np.array([r.velocity for r in references])
    return (stamps - stamps[0]) * 1e-9, positions, velocities  # in integer ns first: 1e9 s in float is ±0.2 µs


@pytest.mark.parametrize("scaling", ["cubic", "quintic"])
def test_multi_point_trajectory_streamed_through_its_points_on_time(harness, scaling):
    node, references, goals, diagnostics = _start_generator(harness, joint_time_scaling=scaling)
    stream = _state_stream(harness)
    harness.spin_for(0.1, every=stream)
    points = [
        TrajectoryPoint(0.6, [0.4, -0.3, 0.1, 0.2], [0.5, 0.0, 0.1, 0.0]),
        TrajectoryPoint(1.2, [0.8, 0.2, 0.25, -0.1]),
        TrajectoryPoint(1.8, [0.5, 0.5, 0.2, 0.0]),
    ]
    # Names in another order than the model's: matched by name.
    order = [3, 1, 0, 2]
    shuffled = [
        TrajectoryPoint(
            p.time_from_start, [p.positions[j] for j in order], [p.velocities[j] for j in order] if p.velocities else ()
        )
        for p in points
    ]
    harness.publish("joint_trajectory", _trajectory(shuffled, [NAMES[j] for j in order], stamp_ns=4242))
    assert harness.spin_until(lambda: node.state == "holding", 5, every=stream)
    harness.spin_for(0.05, every=stream)
    assert not goals  # a joint trajectory streams joint references only
    assert all(list(r.name) == NAMES for r in references)
    times, positions, velocities = _reference_samples(references)
    assert np.all(np.diff(times) > 0)
    # The first reference is the start (t = 0): where the arm is.
    np.testing.assert_allclose(positions[0], Q0, atol=1e-12)
    # On time: a reference is stamped with the time it is for (start + t), so near a point's
    # time t_i the stream must be that point moving at its velocity: for a sample at
    # t = t_i + δ, |q − (q_i + v_i δ)| ≤ ½ |q̈|max δ² with |q̈| ≤ 15 rad/s² here. The nearest
    # samples (5 ms apart, at most 25 ms away on a loaded machine) give 5e-3 at worst,
    # usually < 2e-4; a point passed 10 ms late at 0.5 rad/s would be 5e-3 + off.
    for point in points:
        rate = np.asarray(point.velocities or [0.0] * 4)
        near = np.flatnonzero(np.abs(times - point.time_from_start) <= 0.025)
        assert near.size, f"no reference within 25 ms of {point.time_from_start} s"
        for k in near:
            delta = times[k] - point.time_from_start
            predicted = np.asarray(point.positions) + rate * delta
            assert np.all(np.abs(positions[k] - predicted) <= 0.5 * 15.0 * delta**2 + 1e-9), (
                point,
                delta,
                positions[k],
            )
    # Velocities are the derivative of the positions: between two samples the mean of their
    # velocities is the step over Δt (trapezoidal rule). Its error is |q⃛| Δt² / 12 within a
    # segment, and up to |Δq̈| Δt / 8 across a point where the cubic's acceleration jumps
    # (by ≤ 14 rad/s² here): < 0.04 rad/s for Δt < 20 ms. Velocities without the Hermite
    # terms would be off by ~0.5 rad/s near the first point.
    gaps = np.diff(times)
    steps = np.diff(positions, axis=0) / gaps[:, None]
    mean_velocities = 0.5 * (velocities[1:] + velocities[:-1])
    short = np.flatnonzero(gaps[:-1] <= 0.02)  # pairs the bound covers (the last step ends at rest)
    assert short.size > 0.8 * (gaps.size - 1)  # a loaded machine may stall the loop now and then
    assert np.max(np.abs(steps[short] - mean_velocities[short])) < 0.04
    k = int(np.argmin(np.abs(times - 0.6)))
    np.testing.assert_allclose(velocities[k], points[0].velocities, atol=0.05)
    # Ends at rest on the last point, exactly; total duration as given.
    np.testing.assert_allclose(positions[-1], points[-1].positions, atol=1e-12)
    assert not velocities[-1].any() and times[-1] == pytest.approx(1.8, abs=1e-6)
    held = harness.spin_until(
        lambda: [s for s in statuses(diagnostics, "trajectory_generator") if s.message == "holding"], 2, every=stream
    )
    values = {kv.key: kv.value for kv in held[-1].values}
    assert values["target_stamp"] == "0.000004242" and values["motion"] == "joint trajectory"
    assert values["final_goal_stamp"] == stamp_key(references[-1].header.stamp)
    assert values["joint_time_scaling"] == scaling


def test_bad_trajectories_rejected_with_the_reason(harness, capfd):
    node, references, _, diagnostics = _start_generator(harness)
    # No joint state yet: nothing to start from.
    harness.publish("joint_trajectory", _trajectory([TrajectoryPoint(1.0, [0.1] * 4)], harness=harness))
    assert harness.spin_until(lambda: node.supervisor.rejected_targets == 1, 3)
    assert "no current" in node.supervisor.last_rejection and "joint_states" in node.supervisor.last_rejection
    stream = _state_stream(harness)
    harness.spin_for(0.1, every=stream)
    bad = [
        (_trajectory([TrajectoryPoint(1.0, [0.1] * 3)], NAMES[:3], harness=harness), "lacks joints ['joint4']"),
        (_trajectory([TrajectoryPoint(1.0, [0.1] * 4)], ["a", *NAMES[1:]], harness=harness), "['a'] are not joints"),
        (
            _trajectory([TrajectoryPoint(1.0, [0.1] * 4), TrajectoryPoint(0.5, [0.2] * 4)], harness=harness),
            "strictly increasing",
        ),
        (_trajectory([TrajectoryPoint(1.0, [0.1, 0.1, 0.9, 0.1])], harness=harness), "outside its limits"),
        (_trajectory([TrajectoryPoint(0.05, [1.0, 0, 0.1, 0])], harness=harness), "too fast"),
        (_trajectory([], harness=harness), "no points"),
    ]
    for count, (msg, fragment) in enumerate(bad, start=2):
        harness.publish("joint_trajectory", msg)
        assert harness.spin_until(lambda c=count: node.supervisor.rejected_targets == c, 3, every=stream), (
            fragment,
            node.supervisor.rejected_targets,
            node.supervisor.last_rejection,
        )
        assert fragment in node.supervisor.last_rejection, (fragment, node.supervisor.last_rejection)
    assert node.state == "rejected" and not references
    logged = capfd.readouterr().err
    assert "rejected joint_trajectory" in logged or "rejected /joint_trajectory" in logged
    # Still works afterwards.
    harness.publish("joint_trajectory", _trajectory([TrajectoryPoint(0.6, [0.1] * 4)], harness=harness))
    assert harness.spin_until(lambda: node.state == "holding", 3, every=stream)
    # The final reference is published as the state changes; let it arrive.
    assert harness.spin_until(lambda: np.allclose(references[-1].position, [0.1] * 4, atol=1e-12), 2, every=stream)


def test_latest_goal_of_either_kind_wins_in_the_generator(harness):
    node, references, goals, _ = _start_generator(harness, task="position")
    stream = _state_stream(harness)
    harness.spin_for(0.1, every=stream)
    harness.publish("joint_trajectory", _trajectory([TrajectoryPoint(3.0, [0.5, 0.5, 0.2, 0.0])], harness=harness))
    assert harness.spin_until(lambda: node.state == "streaming" and len(references) > 5, 3, every=stream)
    # A line target pre-empts the joint trajectory: pose goals flow, references stop.
    start = frame_pose(SCARA, Q0)
    target = make_transform(start[:3, :3], start[:3, 3] + [-0.1, 0.1, 0.0])
    harness.publish("line_target", make_pose_stamped(target, "base_link", _now(harness)))
    assert harness.spin_until(lambda: len(goals) > 5, 3, every=stream)
    count = len(references)
    harness.spin_for(0.1, every=stream)
    assert len(references) <= count + 1 and node.supervisor.motion_kind == "line"
    # And a trajectory pre-empts the line.
    harness.publish("joint_trajectory", _trajectory([TrajectoryPoint(0.5, [0.1, 0.0, 0.0, 0.0])], harness=harness))
    assert harness.spin_until(lambda: node.supervisor.motion_kind == "joint trajectory", 3, every=stream)
    assert harness.spin_until(lambda: node.state == "holding", 3, every=stream)
    final = [0.1, 0.0, 0.0, 0.0]
    assert harness.spin_until(lambda: np.allclose(references[-1].position, final, atol=1e-12), 2, every=stream)


# --- the controller ---------------------------------------------------------------------------------


def _start_controller(harness, **params):
    commands = harness.collect(Float64MultiArray, "joint_velocity_commands")
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    # The law's own commands: this checks its values (test_nodes_safety checks the limits).
    params = {**without_acceleration_limits(NAMES), **params}
    node = harness.start(CartesianControllerNode, robot="scara", rate_hz=RATE, **params)
    for topic, msg_type in (
        ("joint_states", JointState),
        ("joint_reference", JointState),
        ("goal_pose", PoseStamped),
        ("goal_twist", TwistStamped),
    ):
        harness.wait_matched(topic, msg_type)
    return node, commands, diagnostics


def test_controller_follows_a_joint_reference_then_a_pose_goal(harness, capfd):
    node, commands, diagnostics = _start_controller(harness, gain_joint=3.0, goal_twist_timeout=0.05)
    q = np.array([0.1, -0.2, 0.1, 0.3])
    reference = np.array([0.3, 0.1, 0.15, 0.2])
    velocity = np.array([0.2, -0.1, 0.02, 0.0])

    def stream(ref_velocity=velocity):
        harness.publish("joint_states", make_joint_state(NAMES, q))
        harness.publish("joint_reference", make_joint_state(NAMES, reference, ref_velocity, _now(harness)))

    assert harness.spin_until(lambda: node.state == "tracking", 3, every=stream, period=0.005)
    commands.clear()
    harness.spin_for(0.1, every=stream, period=0.005)
    np.testing.assert_allclose(commands[-1].data, velocity + 3.0 * (reference - q), atol=1e-12)
    # The reference stops moving but q is still away: tracking; then at the reference: converged.
    rest = lambda: stream(np.zeros(4))  # noqa: E731
    harness.spin_for(0.1, every=rest, period=0.005)
    np.testing.assert_allclose(commands[-1].data, 3.0 * (reference - q), atol=1e-12)
    assert node.state == "tracking"
    q = reference + [5e-4, -5e-4, 0.0, 2e-4]
    assert harness.spin_until(lambda: node.state == "converged", 3, every=rest, period=0.005)
    status = harness.spin_until(
        lambda: [s for s in statuses(diagnostics, "cartesian_controller") if s.message == "converged"], 2, every=rest
    )[-1]
    values = {kv.key: kv.value for kv in status.values}
    assert values["goal_kind"] == "joint" and float(values["joint_error"]) == pytest.approx(5e-4, abs=1e-9)
    expected = np.linalg.norm(frame_pose(SCARA, reference)[:3, 3] - frame_pose(SCARA, q)[:3, 3])
    assert float(values["position_error"]) == pytest.approx(expected, abs=1e-9)
    # Bad references are rejected and the previous one kept.
    outside = make_joint_state(NAMES, [0.1, 0.1, 0.7, 0.1], stamp=_now(harness))
    missing = make_joint_state(NAMES[:3], [0.1, 0.1, 0.1], stamp=_now(harness))
    not_finite = make_joint_state(NAMES, [0.1, math.nan, 0.1, 0.1], stamp=_now(harness))
    for msg in (outside, missing, not_finite):
        harness.publish("joint_reference", msg)
    assert harness.spin_until(lambda: node.inputs.rejected_references == 3, 3)
    logged = harness.logged(node, capfd)  # the loop thread logs right after counting
    assert all(f in logged for f in ("outside its limits", "lacks joints", "NaN or infinity")), logged
    # A pose goal after the reference wins: the cartesian law's command.
    goal = make_transform(np.eye(3), [0.6, 0.3, 0.1])
    harness.publish("goal_pose", make_pose_stamped(goal, "base_link", _now(harness)))
    still = lambda: harness.publish("joint_states", make_joint_state(NAMES, q))  # noqa: E731
    assert harness.spin_until(lambda: node.supervisor.goal_kind == "pose", 3, every=still)
    commands.clear()
    harness.spin_for(0.1, every=still)
    law = CartesianController(SCARA, ControllerConfig()).step(q, goal, None, 1.0 / RATE).qdot
    np.testing.assert_allclose(commands[-1].data, law, atol=1e-9)
