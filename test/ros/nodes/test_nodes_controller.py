"""cartesian_controller alone: commands from the control law, state on /diagnostics, rejections.

Expected commands are computed here, independently of manip_kin.control.resolved_rate: FK of the controlled
frame, a numeric Jacobian, a textbook rotation log and the damped least-squares law written out
(kin_reference.resolved_rates), with the node's parameters. Every parameter that changes the
command is set to a non-default value in some test whose expectation would be wrong if the node
ignored it.
"""

import math
import os
import threading
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from kin_reference import numeric_geometric_jacobian, resolved_rates, rotation_log, velocity_scaled
from node_harness import Harness, statuses, without_acceleration_limits
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.wire.messages import (
    make_joint_state,
    make_pose_stamped,
    make_twist_stamped,
    ns_to_stamp,
    stamp_to_ns,
)

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
    return make_joint_state(names, np.asarray(q)[order])


def _expected(
    goal,
    twist=None,
    q=Q0,
    model=MODEL,
    frame=None,
    rows=range(6),
    gains=(0.8, 0.8),
    damping=(0.04, 0.02),
    velocity_limits=True,
):
    """The command the law gives, computed without manip_kin.control.resolved_rate (see the module docstring)."""
    fk = lambda x: frame_pose(model, x, frame)  # noqa: E731
    pose = fk(np.asarray(q, float))
    orientation_error = rotation_log(goal[:3, :3] @ pose[:3, :3].T)
    position_error = goal[:3, 3] - pose[:3, 3]
    jacobian = numeric_geometric_jacobian(fk, q)
    qdot = resolved_rates(jacobian, orientation_error, position_error, rows, gains, twist, damping)
    return velocity_scaled(qdot, model.velocity_limits) if velocity_limits else qdot


def _start(harness, robot="genova7", **params):
    commands = harness.collect(Float64MultiArray, "/joint_velocity_commands")
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    # joint_state_timeout 1 s (default 0.1): this process streams the joint states, and on a
    # loaded machine it can stall for more than 0.1 s, which would make a command zeros.
    params.setdefault("joint_state_timeout", 1.0)
    # The law's own commands: these tests check its values (test_nodes_safety checks the limits).
    params = {**without_acceleration_limits(load_robot(robot).joint_names), **params}
    node = harness.start(CartesianControllerNode, robot=robot, rate_hz=RATE, **params)
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
    goal_msg = make_pose_stamped(GOAL, "base_link", ns_to_stamp(123_000_000_456))
    harness.publish("/goal_pose", goal_msg)
    assert harness.spin_until(lambda: node.state in ("tracking", "joint-limited"), 3, every=stream)
    commands.clear()
    harness.spin_for(0.1, every=stream)
    np.testing.assert_allclose(commands[-1].data, _expected(GOAL), atol=1e-7)
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
    assert float(values["manipulability"]) > 0
    assert float(values["loop_target_rate_hz"]) == RATE and float(values["loop_rate_hz"]) > 0
    # Joint states stop: stale input, zeros; not before joint_state_timeout (1 s here, a lower
    # bound: the node took the last state after it was sent).
    stream()
    last_sent = time.monotonic()
    assert harness.spin_until(lambda: node.state == "stale input", 10)
    assert time.monotonic() - last_sent > 1.0
    commands.clear()
    harness.spin_for(0.1)
    assert commands and not any(commands[-1].data)


def test_feed_forward_used_while_fresh(harness):
    # goal_twist_timeout 0.5 s (default 0.02): the feed-forward outlives the twist stream by that.
    node, commands, _ = _start(harness, goal_twist_timeout=0.5)
    angular, linear = np.array([0.0, 0.0, 0.3]), np.array([0.05, 0.0, -0.02])
    last_twist = [0.0]

    def stream():
        harness.publish("/joint_states", _joint_state(Q0))
        harness.publish("/goal_twist", make_twist_stamped(angular, linear, "base_link"))
        last_twist[0] = time.monotonic()

    with_twist, without = _expected(GOAL, (angular, linear)), _expected(GOAL)
    assert np.abs(with_twist - without).max() > 0.05
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    # While twists stream the command carries the feed-forward (conditions, no fixed waits).
    assert harness.spin_until(
        lambda: commands and np.allclose(commands[-1].data, with_twist, atol=1e-7), 5, every=stream, period=0.005
    ), (commands[-1].data if commands else None, with_twist)
    # Twists stop: after goal_twist_timeout the pose error alone drives the command, and not
    # before (a lower bound: the node took the last twist after it was sent).
    assert harness.spin_until(
        lambda: np.allclose(commands[-1].data, without, atol=1e-7),
        5,
        every=lambda: harness.publish("/joint_states", _joint_state(Q0)),
    ), (commands[-1].data, without)
    assert time.monotonic() - last_twist[0] > 0.5


def test_the_filter_is_told_while_the_law_follows_a_feed_forward(harness):
    """The command filter makes up what a late cycle cost only for a law that follows a moving
    reference (command_filter.py): a goal with a fresh twist says so, a goal alone does not."""
    node, commands, _ = _start(harness, goal_twist_timeout=0.5)
    told = []
    update = node.command_filter.update

    def recording(target, positions=None, elapsed=None, feed_forward=False):
        told.append(feed_forward)
        return update(target, positions, elapsed, feed_forward)

    node.command_filter.update = recording
    angular, linear = np.array([0.0, 0.0, 0.3]), np.array([0.05, 0.0, -0.02])

    def stream():
        harness.publish("/joint_states", _joint_state(Q0))
        harness.publish("/goal_twist", make_twist_stamped(angular, linear, "base_link"))

    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    with_twist = _expected(GOAL, (angular, linear))
    assert harness.spin_until(
        lambda: commands and np.allclose(commands[-1].data, with_twist, atol=1e-7), 5, every=stream, period=0.005
    )
    told.clear()
    harness.spin_for(0.05, every=stream, period=0.005)
    assert told and all(told), told
    # The twists stop: once goal_twist_timeout has passed the law is the pose error alone.
    without = _expected(GOAL)
    assert harness.spin_until(
        lambda: np.allclose(commands[-1].data, without, atol=1e-7),
        5,
        every=lambda: harness.publish("/joint_states", _joint_state(Q0)),
    )
    told.clear()
    harness.spin_for(0.05, every=lambda: harness.publish("/joint_states", _joint_state(Q0)))
    assert told and not any(told), told


def test_bad_goals_rejected_previous_goal_kept(harness, capfd):
    node, commands, _ = _start(harness)
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    assert harness.spin_until(lambda: node.inputs.goal is not None, 3, every=stream)
    nan_goal = make_pose_stamped(GOAL, "base_link")
    nan_goal.pose.position.x = math.nan
    long_quat = make_pose_stamped(GOAL, "base_link")
    long_quat.pose.orientation.w, long_quat.pose.orientation.x = 0.9, 0.9
    wrong_frame = make_pose_stamped(make_transform(np.eye(3), [0.1, 0.1, 0.1]), "world")
    bad_twist = make_twist_stamped([math.inf, 0, 0], [0, 0, 0], "base_link")
    for msg in (nan_goal, long_quat, wrong_frame):
        harness.publish("/goal_pose", msg)
    harness.publish("/goal_twist", bad_twist)
    harness.publish("/joint_states", make_joint_state(MODEL.joint_names[:3], [0.0, 0.0, 0.0]))
    assert harness.spin_until(
        lambda: (
            node.inputs.rejected_goals == 3
            and node.inputs.rejected_twists == 1
            and node.inputs.rejected_joint_states == 1
        ),
        3,
        every=stream,
    )
    commands.clear()
    harness.spin_for(0.1, every=stream)
    np.testing.assert_allclose(commands[-1].data, _expected(GOAL), atol=1e-7)
    logged = capfd.readouterr().err
    assert "NaN or infinity" in logged and "has length" in logged and "'world' is not the base frame" in logged
    assert "lacks joints" in logged


def test_converged_state(harness):
    node, commands, diagnostics = _start(harness, position_tolerance=1e-3, orientation_tolerance=1e-2)
    goal = frame_pose(MODEL, Q0)
    goal[2, 3] += 5e-4  # within the (non-default) tolerance; the default 1e-4 would say tracking
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    harness.publish("/goal_pose", make_pose_stamped(goal, "base_link"))
    assert harness.spin_until(lambda: node.state == "converged", 3, every=stream)
    assert harness.spin_until(
        lambda: any(s.message == "converged" for s in statuses(diagnostics, "cartesian_controller")), 2, every=stream
    )
    # Converged still commands the law's small correction of the remaining 0.5 mm (not zeros,
    # not something else): K e through the pseudo-inverse.
    commands.clear()
    harness.spin_for(0.05, every=stream)
    expected = _expected(goal)
    assert np.linalg.norm(expected) > 1e-4
    np.testing.assert_allclose(commands[-1].data, expected, atol=1e-8)


def test_gains_frame_task_and_base_frame_parameters(harness, capfd):
    """Non-default gains, the ee frame, a position task and goals in 'world': all four change
    the expected command, computed from the ee's FK and its position Jacobian."""
    node, commands, _ = _start(
        harness, gain_linear=1.7, gain_angular=0.3, frame="ee", task="position", base_frame="world"
    )
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    ee = frame_pose(MODEL, Q0, "ee")
    goal = make_transform(rpy_to_matrix(0.3, 0.0, 0.2) @ ee[:3, :3], ee[:3, 3] + [0.03, -0.02, 0.04])
    harness.publish("/goal_pose", make_pose_stamped(goal, "base_link"))  # not the base frame now
    harness.publish("/goal_pose", make_pose_stamped(goal, "world"))
    assert harness.spin_until(lambda: node.inputs.goal is not None and node.inputs.rejected_goals == 1, 3, every=stream)
    commands.clear()
    harness.spin_for(0.1, every=stream)
    expected = _expected(goal, frame="ee", rows=(3, 4, 5), gains=(0.3, 1.7))
    np.testing.assert_allclose(commands[-1].data, expected, atol=1e-7)
    # Ignoring any one of them would give a different command.
    for other in (
        _expected(goal, frame="ee", rows=(3, 4, 5)),
        _expected(goal, rows=(3, 4, 5), gains=(0.3, 1.7)),
        _expected(goal, frame="ee", gains=(0.3, 1.7)),
    ):
        assert np.abs(other - expected).max() > 1e-3
    assert "'base_link' is not the base frame" in capfd.readouterr().err


def test_damping_parameters_at_a_singularity(harness):
    """irb120 with the wrist singular (q5 = 0): λ_max and ε set the damped command."""
    q = np.array([0.3, 0.2, -0.4, 0.5, 0.0, -0.2])
    model = load_robot("irb120")
    node, commands, _ = _start(
        harness, robot="irb120", damping_max=0.2, singular_threshold=0.1, respect_velocity_limits=False
    )
    stream = lambda: harness.publish("/joint_states", make_joint_state(model.joint_names, q))  # noqa: E731
    current = frame_pose(model, q)
    goal = make_transform(rpy_to_matrix(0.0, 0.0, 0.4) @ current[:3, :3], current[:3, 3] + [0.02, -0.03, 0.01])
    harness.publish("/goal_pose", make_pose_stamped(goal, "base_link"))
    assert harness.spin_until(lambda: node.state == "singular", 3, every=stream)
    commands.clear()
    harness.spin_for(0.1, every=stream)
    expected = _expected(goal, q=q, model=model, damping=(0.2, 0.1), velocity_limits=False)
    np.testing.assert_allclose(commands[-1].data, expected, atol=1e-6)
    default = _expected(goal, q=q, model=model, velocity_limits=False)
    assert np.abs(default - expected).max() > 1e-2  # the defaults would give another command


def test_velocity_and_position_limit_switches(harness):
    """respect_velocity_limits and respect_position_limits off: the raw law, over the limits."""
    q = Q0.copy()
    q[5] = 0.0  # the prismatic joint on its lower limit
    node, commands, _ = _start(
        harness, gain_linear=20.0, gain_angular=20.0, respect_velocity_limits=False, respect_position_limits=False
    )
    stream = lambda: harness.publish("/joint_states", _joint_state(q))  # noqa: E731
    current = frame_pose(MODEL, q)
    goal = make_transform(current[:3, :3], current[:3, 3] + [0.0, 0.0, -0.1])
    raw = _expected(goal, q=q, gains=(20.0, 20.0), velocity_limits=False)
    assert raw[5] < 0 and np.max(np.abs(raw) / MODEL.velocity_limits) > 1.0  # both limits matter here
    harness.publish("/goal_pose", make_pose_stamped(goal, "base_link"))
    assert harness.spin_until(lambda: node.inputs.goal is not None, 3, every=stream)
    commands.clear()
    harness.spin_for(0.1, every=stream)
    np.testing.assert_allclose(commands[-1].data, raw, rtol=1e-6, atol=1e-6)


def test_predict_state_and_command_latency_parameters(harness):
    """The law runs on the reported state moved on by its velocities to the middle of the robot
    period the command will drive (robot cycles on the grid of the state stamps). Simulated time
    (/clock from here) fixes each state's age exactly."""
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    period = 1.0 / RATE
    qdot = np.array([0.3, -0.2, 0.25, -0.3, 0.2, 0.01, -0.4])  # within every velocity limit
    now_ns = 1_000 * 1_000_000_000
    state_age = [0.0]

    def stream():
        harness.publish("/clock", Clock(clock=ns_to_stamp(now_ns)))
        stamp = ns_to_stamp(now_ns - int(round(state_age[0] * 1e9)))
        harness.publish("/joint_states", make_joint_state(MODEL.joint_names, Q0, qdot, stamp))

    def expected(age: float, latency: float):
        # The robot holds the command `latency` from now; it drives the period that ends at the
        # first grid point (stamp + k periods, k >= 1) from then, and the law sees that
        # period's middle.
        k = 1
        while k * period < age + latency - 1e-12:
            k += 1
        return _expected(GOAL, q=Q0 + qdot * (k * period - period / 2))

    node, commands, _ = _start(harness, command_latency=0.0, use_sim_time=True)
    harness.executor.add_node(node)  # its clock subscription runs in the executor
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    assert harness.spin_until(lambda: node.inputs.goal is not None, 3, every=stream)
    # (state age [s], command_latency [s], predict_state): each row changes one thing.
    cases = [(0.0, 0.0, True), (0.0, 1.25 * period, True), (2.5 * period, 1.25 * period, True), (0.0, 0.0, False)]
    results = []
    for age, latency, predict in cases:
        state_age[0] = age
        node.set_parameters([Parameter("command_latency", value=latency), Parameter("predict_state", value=predict)])
        wanted = expected(age, latency) if predict else _expected(GOAL)
        results.append(wanted)
        assert harness.spin_until(
            lambda wanted=wanted: commands and np.allclose(commands[-1].data, wanted, atol=1e-7),
            5,
            every=stream,
            period=0.005,
        ), (age, latency, predict, commands[-1].data if commands else None, wanted)
    # The expectations differ from one another: each case tests something.
    assert min(np.abs(a - b).max() for i, a in enumerate(results) for b in results[i + 1 :]) > 1e-5


def test_goal_timeout_drops_an_old_goal(harness):
    node, commands, diagnostics = _start(harness, goal_timeout=0.3)
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    assert harness.spin_until(lambda: node.state == "idle", 3, every=stream)
    published = time.monotonic()
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    assert harness.spin_until(lambda: node.state in ("tracking", "joint-limited"), 3, every=stream)
    assert harness.spin_until(lambda: node.state == "stale input", 5, every=stream)
    # A lower bound only: the node took the goal after it was published, so it cannot expire
    # sooner than 0.3 s after that (a loaded machine can only make it later).
    assert time.monotonic() - published > 0.3
    assert node.detail.startswith("goal ") and node.detail.endswith(" s old")
    commands.clear()
    harness.spin_for(0.05, every=stream)
    assert commands and not any(commands[-1].data)
    # A new goal is taken again.
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    assert harness.spin_until(lambda: node.state in ("tracking", "joint-limited"), 3, every=stream)


def test_quaternion_tolerance_parameter(harness):
    node, commands, _ = _start(harness, quaternion_tolerance=0.2)
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    loose = make_pose_stamped(GOAL, "base_link")
    q = loose.pose.orientation
    q.x, q.y, q.z, q.w = (1.1 * v for v in (q.x, q.y, q.z, q.w))  # length 1.1: within 0.2, not 0.01
    harness.publish("/goal_pose", loose)
    assert harness.spin_until(lambda: node.inputs.goal is not None, 3, every=stream)
    assert node.inputs.rejected_goals == 0
    commands.clear()
    harness.spin_for(0.1, every=stream)
    np.testing.assert_allclose(commands[-1].data, _expected(GOAL), atol=1e-6)  # used normalised


def test_realtime_priority_reports_whether_it_was_applied(harness):
    """realtime_priority needs CAP_SYS_NICE (or an RLIMIT_RTPRIO): where this machine refuses it,
    the loop runs normally and says why in realtime_error; where it permits it, the loop thread
    is SCHED_FIFO (read back from the kernel)."""
    from pipeline_checks import fast_dds_receive_threads, realtime_scheduling_error

    refused = realtime_scheduling_error(10)
    node, commands, _ = _start(harness, realtime_priority=10)
    assert harness.spin_until(lambda: node.loop.stats().cycles > 5, 5)
    if refused:
        assert "SCHED_FIFO priority 10 not set" in node.loop.realtime_error
        print(f"SCHED_FIFO refused on this machine, checked the fallback: {refused}")
    else:
        assert node.loop.realtime_error == ""
        assert os.sched_getscheduler(node.loop._thread.native_id) == os.SCHED_FIFO
        # The threads it waits on run at its priority while it runs: this (the executor's) thread,
        # which may hold the GIL, and the middleware's receive threads (Fast DDS: dds.shm.<port>).
        main = threading.get_native_id()
        receive = fast_dds_receive_threads()
        assert len(receive) >= 2, receive
        for thread_id in [main, *receive]:
            assert os.sched_getscheduler(thread_id) == os.SCHED_FIFO, thread_id
            assert os.sched_getparam(thread_id).sched_priority == 10
        assert set(node.loop.shared_priority.middleware_threads) == set(receive)
        assert harness.spin_until(lambda: len(commands) > 5, 5)
        node.loop.stop()  # and back to normal scheduling when it stops
        for thread_id in [main, *receive]:
            assert os.sched_getscheduler(thread_id) == os.SCHED_OTHER, thread_id
    assert harness.spin_until(lambda: len(commands) > 5, 5)  # it runs either way


def test_scheduler_slice_parameter_reaches_the_loop_thread_and_its_status(harness):
    """scheduler_slice 0.0005 s (default 0.0001): the loop thread's slice as the kernel reports
    it, and ``loop_scheduling`` in the status; a kernel without per-thread slices says why."""
    from pipeline_checks import thread_slice_ns

    node, commands, diagnostics = _start(harness, scheduler_slice=0.0005)
    assert harness.spin_until(lambda: node.loop.stats().cycles > 5, 5)
    if node.loop.scheduler_slice_error:
        assert "scheduler slice 0.5 ms not set" in node.loop.scheduler_slice_error
        expected = "default"
        print(f"this kernel refused the slice: {node.loop.scheduler_slice_error}")
    else:
        assert thread_slice_ns(node.loop._thread.native_id) in (500_000, None)
        expected = "slice 0.5 ms"

    def scheduling_reported():
        values = [dict((kv.key, kv.value) for kv in s.values) for s in statuses(diagnostics, "cartesian_controller")]
        return any(v.get("loop_scheduling") == expected for v in values)

    assert harness.spin_until(scheduling_reported, 5)
    assert harness.spin_until(lambda: len(commands) > 5, 5)  # it runs either way


def test_a_blocked_cycle_is_logged_and_counted_and_commands_go_on(harness, capfd):
    """A cycle blocked for 80 ms (many periods: what a middleware call can do) gives one WARN
    line with its duration and ``loop_stalls`` in the status; the commands go on."""
    node, commands, diagnostics = _start(harness)
    assert harness.spin_until(lambda: len(commands) > 5, 5)
    cycle = node.loop._cycle
    blocked = []

    def once_blocked(now_ns):
        if not blocked:
            blocked.append(now_ns)
            time.sleep(0.08)
        cycle(now_ns)

    node.loop._cycle = once_blocked
    assert harness.spin_until(lambda: node.loop.stats().stalls == 1, 5)
    count = len(commands)
    assert harness.spin_until(lambda: len(commands) > count + 20, 5)

    def stall_reported():
        values = [dict((kv.key, kv.value) for kv in s.values) for s in statuses(diagnostics, "cartesian_controller")]
        return any(v.get("loop_stalls") == "1" and float(v.get("loop_longest_cycle_ms", 0)) >= 80 for v in values)

    assert harness.spin_until(stall_reported, 5)
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if "a cycle took" in line]
    assert len(lines) == 1 and "WARN" in lines[0] and f"of a {1000 / RATE:g} ms period" in lines[0], err[-2000:]
    assert 80.0 <= float(lines[0].split("a cycle took ")[1].split(" ms")[0]) < 1000.0


def test_diagnostics_rate_parameter(harness):
    """diagnostics_rate_hz 2 (default 10): in a steady state statuses come 0.5 s apart, never closer."""
    node, _, diagnostics = _start(harness, diagnostics_rate_hz=2.0)
    stream = lambda: harness.publish("/joint_states", _joint_state(Q0))  # noqa: E731
    assert harness.spin_until(lambda: node.state == "idle", 5, every=stream)
    diagnostics.clear()
    assert harness.spin_until(lambda: len(statuses(diagnostics, "cartesian_controller")) >= 3, 10, every=stream)
    stamps = [stamp_to_ns(msg.header.stamp) for msg in diagnostics]
    # A lower bound (a loaded machine can only space them further): 0.5 s less 20 ms of
    # stamping jitter; at the default 10 Hz they would be 0.1 s apart.
    assert min(np.diff(stamps)) > 0.48e9, np.diff(stamps)
