"""robot_state alone: what it publishes, how it integrates, what it rejects."""

import math
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from kin_reference import unskew
from node_harness import Harness, statuses
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from manip_kin.core.kinematics import frame_pose, frame_twist
from manip_kin.core.robots import load_robot
from manip_kin.errors import JointCountError, UnknownRobotError
from manip_kin.ros.nodes.robot_state import RobotStateNode
from manip_kin.ros.wire.messages import array_to_multiarray, pose_stamped_to_matrix, stamp_to_seconds, twist_to_arrays


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def _latest(received):
    return received[-1] if received else None


def test_publishes_state_poses_twists_and_description(harness):
    model = load_robot("genova7")
    joint_states = harness.collect(JointState, "/joint_states")
    ee_poses = harness.collect(PoseStamped, "/ee_pose")
    tool_poses = harness.collect(PoseStamped, "/tool_pose")
    ee_twists = harness.collect(TwistStamped, "/ee_twist")
    tool_twists = harness.collect(TwistStamped, "/tool_twist")
    started = time.time()
    harness.start(RobotStateNode, robot="genova7", rate_hz=200.0)
    assert harness.spin_until(
        lambda: len(joint_states) > 20 and len(tool_poses) > 20 and tool_twists and ee_twists and ee_poses, 10
    )
    # Latched: a subscriber that joins late still gets the description.
    descriptions = harness.collect(String, "/robot_description", latched=True)
    assert harness.spin_until(lambda: descriptions, 5)
    assert "<robot" in descriptions[0].data and all(name in descriptions[0].data for name in model.joint_names)

    state = joint_states[-1]
    assert list(state.name) == model.joint_names
    assert len(state.position) == 7 and len(state.velocity) == 7
    q0 = model.start_configuration()
    np.testing.assert_allclose(state.position, q0, atol=1e-12)
    np.testing.assert_allclose(state.velocity, 0.0, atol=1e-12)
    assert started <= stamp_to_seconds(state.header.stamp) <= time.time()  # stamped with the system time
    stamps = [stamp_to_seconds(m.header.stamp) for m in joint_states]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    # rate_hz 200 (default 500): the loop's deadlines are 5 ms apart and a cycle starts at most a
    # period after its deadline, so 10 consecutive cycles last at least 45 ms (test_nodes_plumbing);
    # the stamps are read after each cycle's work, which a loaded machine delays, hence the 10th
    # percentile and 40 ms. At 500 Hz they would last 20 ms. (Too slow is the machine, not the node.)
    ten_cycles = np.array(stamps[10:]) - np.array(stamps[:-10])
    assert np.percentile(ten_cycles, 10) > 0.040, ten_cycles

    tool = tool_poses[-1]
    assert tool.header.frame_id == "base_link"
    np.testing.assert_allclose(pose_stamped_to_matrix(tool), frame_pose(model, q0, "tool"), atol=1e-9)
    # robots.md sanity value of the genova7 tool at q0.
    np.testing.assert_allclose(pose_stamped_to_matrix(tool)[:3, 3], [0.0, -1.1369, 0.2327], atol=1e-4)
    np.testing.assert_allclose(pose_stamped_to_matrix(ee_poses[-1]), frame_pose(model, q0, "ee"), atol=1e-9)
    for twist in (ee_twists[-1], tool_twists[-1]):
        assert twist.header.frame_id == "base_link"
        assert not any(np.concatenate(twist_to_arrays(twist.twist)))


def test_integrates_commands_with_twists_and_times_out(harness):
    model = load_robot("irb120")
    joint_states = harness.collect(JointState, "/joint_states")
    ee_twists = harness.collect(TwistStamped, "/ee_twist")
    tool_poses = harness.collect(PoseStamped, "/tool_pose")
    harness.start(RobotStateNode, robot="irb120", rate_hz=250.0, command_timeout=0.5)  # default 0.1
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    command = np.array([0.2, 0.1, -0.1, 0.0, 0.3, 0.0])
    last_sent = [0.0]

    def send():
        harness.publish("/joint_velocity_commands", array_to_multiarray(command))
        last_sent[0] = time.monotonic()

    assert harness.spin_until(lambda: joint_states and joint_states[-1].position[0] > 0.05, 10, every=send)
    state = joint_states[-1]
    np.testing.assert_allclose(state.velocity, command, atol=1e-9)
    moved = np.array(state.position)
    np.testing.assert_allclose(moved, command * (moved[0] / command[0]), atol=1e-9)  # moved along the command
    # How far per cycle is the integrator's business (test_joint_integrator_steps below, exact);
    # stamps are read after the cycle's work, which a loaded machine delays by milliseconds.
    # Twist = J(q) q̇ at the same cycle (the ee twist message with the same stamp).
    by_stamp = {stamp_to_seconds(m.header.stamp): m for m in ee_twists}
    state = next(s for s in reversed(joint_states) if stamp_to_seconds(s.header.stamp) in by_stamp)
    twist = by_stamp[stamp_to_seconds(state.header.stamp)]
    assert np.linalg.norm(twist_to_arrays(twist.twist)[1]) > 0.01
    angular, linear = frame_twist(model, np.array(state.position), np.array(state.velocity), "ee")
    np.testing.assert_allclose(twist_to_arrays(twist.twist)[0], angular, atol=1e-9)
    np.testing.assert_allclose(twist_to_arrays(twist.twist)[1], linear, atol=1e-9)
    # Commands stop: after command_timeout the arm holds still.
    assert harness.spin_until(lambda: not any(joint_states[-1].velocity), 5)
    # Not before command_timeout: the node took the last command after it was sent (a lower bound).
    assert time.monotonic() - last_sent[0] > 0.5
    held = np.array(joint_states[-1].position)
    count = len(joint_states)
    assert harness.spin_until(lambda: len(joint_states) >= count + 25, 5)  # 0.1 s of states at 250 Hz
    for message in joint_states[count:]:
        np.testing.assert_array_equal(message.position, held)
    np.testing.assert_allclose(pose_stamped_to_matrix(tool_poses[-1]), frame_pose(model, held), atol=1e-9)


def test_reads_commands_best_effort(harness):
    # The loops read the streams they need only the newest of best effort (topics.latest_state_qos):
    # a best-effort publisher (a driver with sensor-data QoS) matches, which a reliable reader refuses.
    joint_states = harness.collect(JointState, "/joint_states")
    harness.start(RobotStateNode, robot="irb120", rate_hz=250.0)
    publisher = harness.node.create_publisher(
        Float64MultiArray, "/joint_velocity_commands", QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    )
    assert harness.spin_until(lambda: publisher.get_subscription_count() == 1, 15)
    send = lambda: publisher.publish(Float64MultiArray(data=[0.5, 0.0, 0.0, 0.0, 0.0, 0.0]))  # noqa: E731
    assert harness.spin_until(lambda: joint_states and joint_states[-1].position[0] > 0.05, 10, every=send)
    np.testing.assert_allclose(joint_states[-1].velocity, [0.5, 0, 0, 0, 0, 0], atol=1e-12)


def test_rejects_bad_commands_and_keeps_running(harness, capfd):
    joint_states = harness.collect(JointState, "/joint_states")
    node = harness.start(RobotStateNode, robot="irb120", rate_hz=250.0)
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    for bad in ([0.1] * 5, [0.1] * 7, [math.nan, 0, 0, 0, 0, 0], [0, 0, math.inf, 0, 0, 0], []):
        harness.publish("/joint_velocity_commands", Float64MultiArray(data=[float(v) for v in bad]))
        harness.spin_for(0.05)
    assert harness.spin_until(lambda: node.rejected_commands == 5, 3)
    count = len(joint_states)
    assert harness.spin_until(lambda: len(joint_states) > count + 10, 5)
    assert np.all(np.isfinite(joint_states[-1].position))
    np.testing.assert_allclose(joint_states[-1].position, 0.0)
    np.testing.assert_allclose(joint_states[-1].velocity, 0.0)
    # The node still obeys a good command afterwards.
    good = lambda: harness.publish("/joint_velocity_commands", Float64MultiArray(data=[0.5, 0, 0, 0, 0, 0]))  # noqa: E731
    assert harness.spin_until(lambda: joint_states[-1].position[0] > 0.05, 10, every=good)
    np.testing.assert_allclose(joint_states[-1].position[1:], 0.0)
    logged = capfd.readouterr().err
    assert "has 5 values; valid: 6" in logged and "NaN or infinity" in logged


def test_position_and_velocity_limits(harness):
    model = load_robot("genova7")
    joint_states = harness.collect(JointState, "/joint_states")
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    harness.start(RobotStateNode, robot="genova7", rate_hz=250.0, diagnostics_rate_hz=20.0)
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    # Prismatic joint6 starts at 0.15 m; drive it down at its 0.5 m/s limit: it stops at 0.
    down = np.zeros(7)
    down[5] = -0.5
    push = lambda: harness.publish("/joint_velocity_commands", array_to_multiarray(down))  # noqa: E731
    assert harness.spin_until(lambda: joint_states and joint_states[-1].position[5] == 0.0, 10, every=push)
    harness.spin_for(0.05, every=push)  # still pushed down: it stays on the limit
    state = joint_states[-1]
    assert state.position[5] == 0.0 and state.velocity[5] == 0.0
    assert harness.spin_until(
        lambda: any(
            s.values and "joint6" in dict((kv.key, kv.value) for kv in s.values)["joints_at_limit"]
            for s in statuses(diagnostics, "robot_state")
        ),
        2,
    )
    # 10 rad/s on joint1 and 1 rad/s on joint2: scaled together to joint1's 2 rad/s limit.
    fast = np.zeros(7)
    fast[0], fast[1] = 10.0, 1.0
    push = lambda: harness.publish("/joint_velocity_commands", array_to_multiarray(fast))  # noqa: E731
    assert harness.spin_until(lambda: joint_states[-1].velocity[0] > 0, 10, every=push)
    harness.spin_for(0.05, every=push)
    np.testing.assert_allclose(joint_states[-1].velocity[:2], [2.0, 0.2], atol=1e-9)
    assert model.within_limits(joint_states[-1].position)


def test_bad_parameters_stop_the_node(harness):
    with pytest.raises(JointCountError, match="initial_positions"):
        harness.start(RobotStateNode, robot="irb120", initial_positions=[0.0, 0.0])
    with pytest.raises(UnknownRobotError, match="nosuchbot"):
        harness.start(RobotStateNode, robot="nosuchbot")
    with pytest.raises(ValueError, match="outside the joint limits"):
        harness.start(RobotStateNode, robot="irb120", initial_positions=[4.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="rate_hz"):
        harness.start(RobotStateNode, robot="irb120", rate_hz=-5.0)
    node = harness.start(
        RobotStateNode, robot="irb120", initial_positions=[0, 1, 0, 0, 0, 0], rate_hz=100
    )  # integers accepted
    np.testing.assert_allclose(node.plant.q, [0, 1, 0, 0, 0, 0])


def _numeric_twist(model, q, qdot, frame, step=1e-6):
    """(ω, v) of ``frame`` in base moving with ``qdot``: central difference of FK along q̇."""
    plus = frame_pose(model, q + step * qdot, frame)
    minus = frame_pose(model, q - step * qdot, frame)
    derivative = (plus - minus) / (2 * step)
    return unskew(derivative[:3, :3] @ frame_pose(model, q, frame)[:3, :3].T), derivative[:3, 3]


def test_ee_and_tool_twists_of_a_moving_arm_with_a_tool(harness):
    """genova7 has a tool: both twists, each against numeric differentiation of its own FK."""
    model = load_robot("genova7")
    assert model.has_tool
    joint_states = harness.collect(JointState, "/joint_states")
    ee_twists = harness.collect(TwistStamped, "/ee_twist")
    tool_twists = harness.collect(TwistStamped, "/tool_twist")
    harness.start(RobotStateNode, robot="genova7", rate_hz=250.0, base_frame="world")
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    command = np.array([0.3, -0.2, 0.25, 0.4, -0.3, 0.05, 0.5])
    send = lambda: harness.publish("/joint_velocity_commands", array_to_multiarray(command))  # noqa: E731

    def matched():
        ee = {stamp_to_seconds(m.header.stamp): m for m in ee_twists}
        tool = {stamp_to_seconds(m.header.stamp): m for m in tool_twists}
        for state in reversed(joint_states):
            key = stamp_to_seconds(state.header.stamp)
            if np.allclose(state.velocity, command, atol=1e-9) and key in ee and key in tool:
                return state, ee[key], tool[key]
        return None

    state, ee, tool = harness.spin_until(matched, 10, every=send)
    q, qdot = np.array(state.position), np.array(state.velocity)
    assert ee.header.frame_id == tool.header.frame_id == "world"  # base_frame (default base_link)
    for message, frame in ((ee, "ee"), (tool, "tool")):
        angular, linear = _numeric_twist(model, q, qdot, frame)
        received = twist_to_arrays(message.twist)
        np.testing.assert_allclose(received[0], angular, atol=1e-7, err_msg=frame)
        np.testing.assert_allclose(received[1], linear, atol=1e-7, err_msg=frame)
    # The tool sits away from the ee: its linear velocity differs by ω × (p_tool - p_ee).
    lever = frame_pose(model, q, "tool")[:3, 3] - frame_pose(model, q, "ee")[:3, 3]
    assert np.linalg.norm(lever) > 0.01
    np.testing.assert_allclose(
        twist_to_arrays(tool.twist)[1],
        twist_to_arrays(ee.twist)[1] + np.cross(twist_to_arrays(ee.twist)[0], lever),
        atol=1e-9,
    )


SPINNER_URDF = """<robot name="spinner">
  <link name="base_link"/><link name="link1"/><link name="link2"/>
  <joint name="spin" type="continuous">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit effort="1" velocity="2.0"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="1" velocity="2.0"/>
  </joint>
</robot>"""


def test_continuous_joint_integrates_through_plus_minus_pi(harness, tmp_path):
    """No limit at ±π: the position keeps growing past π (no clamp, no wrap) and the pose
    follows the FK of the unwrapped angle."""
    path = tmp_path / "spinner.urdf"
    path.write_text(SPINNER_URDF)
    model = load_robot(str(path))
    joint_states = harness.collect(JointState, "/joint_states")
    ee_poses = harness.collect(PoseStamped, "/ee_pose")
    harness.start(RobotStateNode, robot=str(path), rate_hz=250.0, initial_positions=[math.pi - 0.1, 0.5])
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    command = np.array([2.0, 0.0])  # its velocity limit
    send = lambda: harness.publish("/joint_velocity_commands", array_to_multiarray(command))  # noqa: E731
    assert harness.spin_until(lambda: joint_states and joint_states[-1].position[0] > math.pi + 0.3, 10, every=send)
    positions = [m.position[0] for m in joint_states]
    assert all(b >= a for a, b in zip(positions, positions[1:]))  # through π without a jump to -π
    state = joint_states[-1]
    np.testing.assert_allclose(state.velocity, command, atol=1e-9)
    by_stamp = {stamp_to_seconds(m.header.stamp): m for m in ee_poses}
    for message in joint_states[-20:]:
        pose = by_stamp.get(stamp_to_seconds(message.header.stamp))
        if pose is not None:
            np.testing.assert_allclose(
                pose_stamped_to_matrix(pose), frame_pose(model, np.array(message.position)), atol=1e-9
            )


def test_diagnostics_rate_zero_turns_them_off(harness):
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    joint_states = harness.collect(JointState, "/joint_states")
    harness.start(RobotStateNode, robot="irb120", rate_hz=250.0, diagnostics_rate_hz=0.0)
    # 250 states (1 s) without a status; at the default 2 Hz two or more would have come.
    assert harness.spin_until(lambda: len(joint_states) >= 250, 10)
    assert not statuses(diagnostics, "robot_state")


def test_joint_integrator_steps():
    """q ← q + q̇·dt, the whole vector scaled into the velocity limits, clamped at position
    limits with the velocity of the clamped step reported (exact, no ROS, no clock)."""
    from manip_kin.plant import KinematicPlant

    model = load_robot("genova7")
    q0 = model.start_configuration()
    integrator = KinematicPlant(model, q0)
    command = np.array([0.2, -0.1, 0.3, 0.0, 0.1, 0.05, -0.4])
    for dt in (0.002, 0.004, 0.0013):
        before = np.array(integrator.q_values)
        integrator.step(command, dt)
        np.testing.assert_allclose(np.array(integrator.q_values) - before, command * dt, atol=1e-15)
        np.testing.assert_allclose(integrator.qdot_values, command, atol=1e-12)
    np.testing.assert_allclose(integrator.q_values, q0 + command * (0.002 + 0.004 + 0.0013), atol=1e-14)
    assert integrator.velocity_scale == 1.0
    # 10 rad/s on joint 1 (limit 2): everything scaled by 0.2.
    fast = np.array([10.0, 1.0, 0, 0, 0, 0, 0])
    before = np.array(integrator.q_values)
    integrator.step(fast, 0.01)
    assert integrator.velocity_scale == pytest.approx(0.2)
    np.testing.assert_allclose(np.array(integrator.q_values) - before, fast * 0.2 * 0.01, atol=1e-15)
    # The prismatic joint (upper limit 0.3) pushed past it: clamped, velocity of the clamped step.
    q = np.array(integrator.q_values)
    up = np.zeros(7)
    up[5] = 0.5
    integrator.step(up, 1.0)
    assert integrator.q_values[5] == 0.3 and integrator.at_limit[5]
    assert integrator.qdot_values[5] == pytest.approx(0.3 - q[5])
    # No command: at rest, twists zero.
    integrator.step(None, 0.01)
    assert not any(integrator.qdot_values) and not any(integrator.tool_twist_values)


def test_a_stall_moves_the_arm_on_its_held_command_stamped_at_the_cycle_start(harness):
    """Through a stall of its own process the simulated arm moves on with the command it holds
    (for at most command_timeout), and a state is stamped with the time it is the arm's at: the
    cycle's start, not the later moment it was published."""
    joint_states = harness.collect(JointState, "/joint_states")
    node = harness.start(RobotStateNode, robot="irb120", rate_hz=250.0, command_timeout=0.5)
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    assert harness.spin_until(lambda: len(joint_states) > 5, 5)  # the states reach the test
    node.loop.stop()  # the test runs the cycles, at the times it chooses
    assert not node.loop.running
    base_ns = time.monotonic_ns()
    node._cycle(base_ns)  # the cycle before the command
    command = np.array([0.2, 0.1, -0.1, 0.0, 0.3, 0.0])
    harness.publish("/joint_velocity_commands", array_to_multiarray(command))
    time.sleep(0.05)  # delivered to the node's reader (its cycles take it from there)
    start_ns = base_ns + 4_000_000  # the next cycle on schedule takes it
    node._cycle(start_ns)
    before = np.array(node.plant.q_values)
    stall = 0.040  # ten periods at 250 Hz
    cycle_ns = start_ns + int(stall * 1e9)
    while time.monotonic_ns() < cycle_ns + 5_000_000:  # the cycle runs 5 ms after its start time
        time.sleep(0.001)
    expected_stamp = cycle_ns + time.time_ns() - time.monotonic_ns()
    node._cycle(cycle_ns)
    np.testing.assert_allclose(np.array(node.plant.q_values) - before, command * stall, rtol=1e-9, atol=1e-12)

    def stamps_ns():
        return [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in joint_states]

    assert harness.spin_until(lambda: max(stamps_ns()) > expected_stamp - 20_000_000, 5), stamps_ns()[-3:]
    stamp_ns = max(stamps_ns())
    assert abs(stamp_ns - expected_stamp) < 1_000_000, (stamp_ns - expected_stamp) * 1e-6
    # Through a longer stall it moves until the command times out, command_timeout after the
    # cycle that took it, and then rests.
    node._cycle(cycle_ns + 2_000_000_000)
    moved = np.array(node.plant.q_values) - before
    np.testing.assert_allclose(moved, command * 0.5, rtol=1e-9, atol=1e-12)
    assert not any(node.plant.qdot_values)


def test_a_stall_replays_the_commands_sent_during_it_at_their_own_cycles(harness):
    """Commands queued while robot_state's loop was late each drive the period their own cycle
    would have driven, as hardware taking them in its own cycles does (the newest alone over
    the whole stall put a 0.4 m/s line 0.5 mm beside itself)."""
    node = harness.start(RobotStateNode, robot="irb120", rate_hz=50.0, command_timeout=0.1)
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    node.loop.stop()
    period = 20_000_000
    base_ns = time.monotonic_ns()
    node._cycle(base_ns)
    before = np.array(node.plant.q_values)
    first = np.array([0.2, 0.1, -0.1, 0.0, 0.3, 0.0])
    second = np.array([-0.1, 0.0, 0.2, 0.1, 0.0, -0.2])

    def publish_at(offset_ns, command):
        while time.monotonic_ns() < base_ns + offset_ns:
            time.sleep(0.0005)
        sent = time.monotonic_ns() - base_ns
        harness.publish("/joint_velocity_commands", array_to_multiarray(command))
        return sent

    # Sent 1.5 and 3.5 periods into the stall: the cycles at 2 and 4 periods would take them.
    sent = [publish_at(3 * period // 2, first), publish_at(7 * period // 2, second)]
    assert period < sent[0] < 2 * period and 3 * period < sent[1] < 4 * period, sent  # else the timing is off
    time.sleep(0.05)  # both delivered
    node._cycle(base_ns + 11 * period // 2)  # 5.5 periods after the last cycle
    moved = np.array(node.plant.q_values) - before
    # Nothing over the first period; the cycle at 2 periods takes the first command, which drives
    # the second period and is held through the third; the cycle at 4 takes the second, which
    # drives the fourth, and the cycle now drives from 4 periods to now with it (the newest
    # alone over the whole stall was the old rule: second * 5.5 periods).
    expected = first * 2 * period * 1e-9 + second * 2.5 * period * 1e-9
    np.testing.assert_allclose(moved, expected, rtol=1e-9, atol=1e-12)
