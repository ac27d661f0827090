"""The controller's and generator's state machines, without ROS: made-up clocks, made-up outputs."""

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.control.generator_supervisor import GeneratorState, GeneratorSupervisor
from manip_kin.control.state_machines import (
    ControllerState,
    ControllerSupervisor,
    ControllerSupervisorConfig,
    GoalKind,
)
from manip_kin.control.status import StatusThrottle
from manip_kin.core.pose_rows import parse_task
from manip_kin.errors import InvalidArgumentError

MS = 1_000_000
JOINTS = ["j1", "j2", "j3"]


def _pose_output(orientation=(0.0, 0.0, 0.0), position=(0.0, 0.0, 0.0), singular=False, limited=()):
    return SimpleNamespace(
        orientation_error=np.array(orientation),
        position_error=np.array(position),
        manipulability=0.5,
        damping=0.01 if singular else 0.0,
        limited_joints=tuple(limited),
        singular=singular,
    )


def _controller(**config):
    return ControllerSupervisor(ControllerSupervisorConfig(**config), JOINTS, 100 * MS)


# --- status timing ---------------------------------------------------------------------------------


def test_throttle_reports_first_then_periodically():
    throttle = StatusThrottle(100 * MS)
    assert throttle.due(5 * MS, "idle")
    assert not throttle.due(50 * MS, "idle")
    assert not throttle.due(104 * MS, "idle")
    assert throttle.due(105 * MS, "idle")


def test_throttle_reports_a_change_at_once_but_not_within_20_ms():
    throttle = StatusThrottle(100 * MS)
    assert throttle.due(0, "idle")
    assert not throttle.due(10 * MS, "tracking")  # changed, but only 10 ms after the last report
    assert throttle.due(20 * MS, "tracking")  # the change goes out once 20 ms have passed
    assert not throttle.due(25 * MS, "tracking")
    assert not throttle.due(30 * MS, "converged")
    assert throttle.due(41 * MS, "converged")


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.lists(
        st.tuples(st.integers(1, 40), st.sampled_from(["idle", "tracking", "converged", "singular"])),
        min_size=1,
        max_size=300,
    )
)
def test_throttle_properties(steps):
    """Reports are >= 20 ms apart, no gap exceeds the period (plus one step), and a state that
    differs from the last reported one goes out within 20 ms (plus one step)."""
    period = 100 * MS
    throttle = StatusThrottle(period)
    now = 0
    reports = []  # (time, state)
    pending_since = None  # when the current state first differed from the reported one
    for step_ms, state in steps:
        now += step_ms * MS
        reported_state = reports[-1][1] if reports else None
        if state != reported_state and pending_since is None:
            pending_since = now
        elif state == reported_state:
            pending_since = None
        if throttle.due(now, state):
            reports.append((now, state))
            pending_since = None
        elif pending_since is not None:
            assert now - max(pending_since, reports[-1][0] + 20 * MS) < 40 * MS
        if reports:
            assert now - reports[-1][0] < period + 40 * MS
    times = [t for t, _ in reports]
    assert reports and times[0] == steps[0][0] * MS
    assert all(b - a >= 20 * MS for a, b in zip(times, times[1:]))


def test_throttle_rejects_a_zero_period():
    with pytest.raises(InvalidArgumentError, match="status period"):
        StatusThrottle(0)


# --- the controller --------------------------------------------------------------------------------


def test_controller_stale_idle_tracking_and_timeouts():
    supervisor = _controller(joint_state_timeout=0.1, goal_timeout=1.0)
    assert not supervisor.gate(0)
    assert supervisor.state == ControllerState.STALE_INPUT and supervisor.detail == "no joint state yet"
    supervisor.joint_state_received(10 * MS)
    assert not supervisor.gate(20 * MS) and supervisor.state is ControllerState.IDLE
    supervisor.goal_received(30 * MS, GoalKind.POSE)
    assert supervisor.gate(40 * MS)
    supervisor.pose_step_done(_pose_output(position=(0.1, 0.0, 0.0)), feed_forward_used=False, now_ns=0)
    assert supervisor.state is ControllerState.TRACKING and supervisor.active
    # Joint states stop for longer than the timeout.
    assert not supervisor.gate(111 * MS)
    assert supervisor.state is ControllerState.STALE_INPUT and "0.10 s old" in supervisor.detail
    assert supervisor.level == "warn" and not supervisor.active
    # They come back; later the goal expires.
    supervisor.joint_state_received(500 * MS)
    assert supervisor.gate(500 * MS)
    supervisor.joint_state_received(1100 * MS)
    assert not supervisor.gate(1100 * MS)
    assert supervisor.state is ControllerState.STALE_INPUT and supervisor.detail == "goal 1.07 s old"


def test_goal_timeout_zero_never_expires():
    supervisor = _controller(goal_timeout=0.0)
    supervisor.goal_received(0, GoalKind.POSE)
    supervisor.joint_state_received(10**12)
    assert supervisor.gate(10**12)


def test_feed_forward_freshness():
    supervisor = _controller(goal_twist_timeout=0.02)
    assert not supervisor.feed_forward_fresh(0)
    supervisor.twist_received(100 * MS, moving=True)
    assert supervisor.feed_forward_fresh(120 * MS) and not supervisor.feed_forward_fresh(121 * MS)


def test_pose_convergence_counts_the_task_components_only():
    output = _pose_output(orientation=(0.3, 0.0, 0.0), position=(5e-5, 0.0, 0.0))
    full = _controller()
    full.pose_step_done(output, feed_forward_used=False, now_ns=0)
    assert full.state is ControllerState.TRACKING  # 0.3 rad of orientation error counts
    position_only = _controller(task=parse_task("position"))
    position_only.pose_step_done(output, feed_forward_used=False, now_ns=0)
    assert position_only.state is ControllerState.CONVERGED
    # position_yaw counts rz but not rx.
    yaw = _controller(task=parse_task("position_yaw"))
    yaw.pose_step_done(output, feed_forward_used=False, now_ns=0)
    assert yaw.state is ControllerState.CONVERGED
    yaw.pose_step_done(_pose_output(orientation=(0.0, 0.0, 0.3)), feed_forward_used=False, now_ns=0)
    assert yaw.state is ControllerState.TRACKING
    # Position above tolerance never converges.
    position_only.pose_step_done(_pose_output(position=(2e-4, 0.0, 0.0)), feed_forward_used=False, now_ns=0)
    assert position_only.state is ControllerState.TRACKING


def test_moving_goal_is_not_converged_and_singular_and_limits_are_reported():
    supervisor = _controller()
    supervisor.twist_received(0, moving=True)
    supervisor.pose_step_done(_pose_output(), feed_forward_used=True, now_ns=0)
    assert supervisor.state is ControllerState.TRACKING
    supervisor.pose_step_done(_pose_output(), feed_forward_used=False, now_ns=0)  # twist stale: the goal rests
    assert supervisor.state is ControllerState.CONVERGED
    supervisor.twist_received(0, moving=False)  # a zero twist is a resting goal
    supervisor.pose_step_done(_pose_output(), feed_forward_used=True, now_ns=0)
    assert supervisor.state is ControllerState.CONVERGED
    supervisor.pose_step_done(_pose_output(position=(0.1, 0, 0), singular=True), feed_forward_used=False, now_ns=0)
    assert supervisor.state is ControllerState.SINGULAR and supervisor.level == "warn"
    supervisor.pose_step_done(_pose_output(position=(0.1, 0, 0), limited=(0, 2)), feed_forward_used=False, now_ns=0)
    assert supervisor.state is ControllerState.JOINT_LIMITED and supervisor.detail.endswith("j1, j3")
    assert supervisor.level == "ok"


def _stalled(steps):
    """The state and detail after a goal's error stayed put for a progress window, with
    ``steps``' (braking joints, output keywords) spread over the window."""
    supervisor = _controller()
    window_ns = int(supervisor.config.progress_window * 1e9)
    for i, (braking, output) in enumerate(steps):
        now_ns = i * (window_ns + 1) // (len(steps) - 1)
        supervisor.pose_step_done(_pose_output(position=(0.1, 0, 0), **output), False, now_ns, braking)
    return supervisor.state, supervisor.detail


def test_an_unreachable_goal_names_the_limits_held_all_along_else_the_singularity():
    unreachable = ControllerState.UNREACHABLE
    held = [((), {"limited": (1,)})] * 3
    assert _stalled(held)[0] is unreachable and "joints at their limits: j2;" in _stalled(held)[1]
    braked = [((2,), {})] * 3  # braked before the limit, all along
    assert _stalled(braked)[0] is unreachable and "joints at their limits: j3;" in _stalled(braked)[1]
    both = [((2,), {"limited": (1,), "singular": True})] * 3
    assert "joints at their limits: j2, j3;" in _stalled(both)[1]
    # Singular, a joint limited in some cycles only (the rates swing wide): the singularity.
    swinging = [((), {"singular": True}), ((2,), {"singular": True}), ((), {"limited": (2,), "singular": True})]
    assert _stalled(swinging)[0] is unreachable and "stretched and singular" in _stalled(swinging)[1]
    # Neither singular nor limited all along: not (yet) unreachable.
    assert _stalled([((), {}), ((), {}), ((2,), {})])[0] is not unreachable


def test_the_first_window_waits_for_the_commands_to_ramp_up_but_one_window_at_most():
    """A goal's error stays put while the commands still ramp towards the law's rates (a joint
    limited all along): judged only from when they follow, or one window after the first step."""
    window_ns = int(_controller().config.progress_window * 1e9)

    def state_at(end_ns, ramping_until_ns):
        supervisor = _controller()
        for now_ns in range(0, end_ns + 1, window_ns // 10):
            output = _pose_output(position=(0.1, 0, 0), limited=(1,))
            supervisor.pose_step_done(output, False, now_ns, ramping=now_ns < ramping_until_ns)
        return supervisor.state

    unreachable = ControllerState.UNREACHABLE
    assert state_at(window_ns, ramping_until_ns=0) is unreachable  # following from the start
    # Ramping for 0.4 windows: the first window starts there and has not ended at 1 window.
    assert state_at(window_ns, ramping_until_ns=4 * window_ns // 10) is not unreachable
    assert state_at(14 * window_ns // 10, ramping_until_ns=4 * window_ns // 10) is unreachable
    # Ramping all along (rates that swing faster than the commands follow): judged one window late.
    assert state_at(19 * window_ns // 10, ramping_until_ns=10 * window_ns) is not unreachable
    assert state_at(2 * window_ns, ramping_until_ns=10 * window_ns) is unreachable


def test_step_failure_is_stale_input():
    supervisor = _controller()
    supervisor.step_failed(ValueError("q contains NaN"))
    assert supervisor.state is ControllerState.STALE_INPUT and "q contains NaN" in supervisor.detail


def test_joint_reference_convergence_and_latest_goal_wins():
    supervisor = _controller(joint_tolerance=1e-3)
    supervisor.joint_state_received(0)
    supervisor.goal_received(0, GoalKind.JOINT, moving=True)
    assert supervisor.gate(0) and supervisor.goal_kind is GoalKind.JOINT
    supervisor.joint_step_done(SimpleNamespace(joint_error=np.zeros(3), limited_joints=()), True, now_ns=0)
    assert supervisor.state is ControllerState.TRACKING  # the reference still moves
    supervisor.joint_step_done(SimpleNamespace(joint_error=np.zeros(3), limited_joints=()), False, now_ns=0)
    assert supervisor.state is ControllerState.CONVERGED  # its velocity is stale: it rests
    supervisor.goal_received(1 * MS, GoalKind.JOINT, moving=False)
    supervisor.joint_step_done(
        SimpleNamespace(joint_error=np.array([0.0, -2e-3, 0.0]), limited_joints=()), True, now_ns=0
    )
    assert supervisor.state is ControllerState.TRACKING
    supervisor.joint_step_done(
        SimpleNamespace(joint_error=np.array([0.0, -9e-4, 5e-4]), limited_joints=()), True, now_ns=0
    )
    assert supervisor.state is ControllerState.CONVERGED
    supervisor.joint_step_done(
        SimpleNamespace(joint_error=np.array([0.0, 0.1, 0.0]), limited_joints=(1,)), True, now_ns=0
    )
    assert supervisor.state is ControllerState.JOINT_LIMITED and supervisor.detail.endswith("j2")
    supervisor.goal_received(2 * MS, GoalKind.POSE, moving=True)  # a pose ignores "moving"
    assert supervisor.goal_kind is GoalKind.POSE
    supervisor.joint_state_received(0)
    supervisor.goal_received(0, GoalKind.JOINT)
    assert supervisor.goal_kind is GoalKind.JOINT


def test_joint_reference_age_in_the_stale_detail():
    supervisor = _controller(goal_timeout=0.5, joint_state_timeout=10.0)
    supervisor.joint_state_received(0)
    supervisor.goal_received(0, GoalKind.JOINT)
    assert not supervisor.gate(600 * MS) and supervisor.detail == "joint reference 0.60 s old"


@pytest.mark.parametrize(
    "field, value",
    [
        ("joint_state_timeout", 0.0),
        ("goal_timeout", -1.0),
        ("goal_twist_timeout", float("nan")),
        ("position_tolerance", 0.0),
        ("joint_tolerance", float("inf")),
    ],
)
def test_controller_config_is_validated(field, value):
    with pytest.raises(InvalidArgumentError, match=field):
        ControllerSupervisorConfig(**{field: value})


def test_states_compare_equal_to_their_text():
    assert ControllerState.STALE_INPUT == "stale input" and ControllerState("joint-limited").name == "JOINT_LIMITED"
    assert GeneratorState.HOLDING == "holding"


# --- the generator ---------------------------------------------------------------------------------


class _Motion:
    def __init__(self, duration):
        self.duration = duration

    def progress_at(self, t):
        return t / self.duration


def test_generator_rejects_when_idle_and_keeps_a_running_motion():
    supervisor = GeneratorSupervisor(200 * MS)
    assert supervisor.time_into_motion(0) is None
    assert supervisor.reject("no current /joint_states", "1.000000000") == "nothing to do"
    assert supervisor.state is GeneratorState.REJECTED and supervisor.level == "warn"
    assert not supervisor.start(_Motion(2.0), "line", 1000 * MS, "2.000000000", "a line")
    assert supervisor.state is GeneratorState.STREAMING and supervisor.target_stamp == "2.000000000"
    assert supervisor.rejection_kind == "invalid"
    kept = supervisor.reject("leaves the arm's reach", "3.000000000", "unreachable")
    assert kept == "the running line goes on" and supervisor.state is GeneratorState.STREAMING
    assert supervisor.target_stamp == "2.000000000" and supervisor.rejected_stamp == "3.000000000"
    assert supervisor.rejected_targets == 2 and supervisor.last_rejection == "leaves the arm's reach"
    assert supervisor.rejection_kind == "unreachable"


def test_generator_streams_finishes_and_is_preempted():
    supervisor = GeneratorSupervisor(200 * MS)
    supervisor.start(_Motion(2.0), "joint trajectory", 1000 * MS, "5.0", "three points")
    t, finished = supervisor.time_into_motion(1500 * MS)
    assert t == pytest.approx(0.5) and not finished and supervisor.progress == pytest.approx(0.25)
    t, finished = supervisor.time_into_motion(3200 * MS)
    assert t == 2.0 and finished  # clipped to the duration
    supervisor.finish("6.0")
    assert supervisor.state is GeneratorState.HOLDING and supervisor.final_goal_stamp == "6.0"
    assert supervisor.time_into_motion(3300 * MS) is None and supervisor.progress == 1.0
    assert "joint trajectory finished" in supervisor.detail
    # The same target sent again (a client that missed the report) is one it has; a new is not.
    assert supervisor.has_taken("5.0") and not supervisor.has_taken("5.5") and not supervisor.has_taken("")
    # A new motion while streaming pre-empts; its final stamp starts empty.
    supervisor.start(_Motion(1.0), "line", 4000 * MS, "7.0", "a line")
    assert supervisor.start(_Motion(1.0), "line", 4100 * MS, "8.0", "another line")
    assert supervisor.final_goal_stamp == "" and supervisor.time_into_motion(4600 * MS) == (
        pytest.approx(0.5),
        False,
    )


def test_blocked_halts_until_a_new_goal_with_the_pair_in_the_detail():
    from manip_kin.control.qp.blocked import Blocked

    supervisor = _controller()
    supervisor.joint_state_received(0)
    supervisor.goal_received(0, GoalKind.POSE)
    assert supervisor.gate(1 * MS)
    supervisor.collision_blocked(None)  # nothing blocks: nothing changes
    assert supervisor.state is not ControllerState.BLOCKED
    supervisor.collision_blocked(Blocked("panda_link1-panda_hand", 0.0201, 1e-5, 0.0))
    assert supervisor.state == "blocked" and supervisor.level == "warn" and not supervisor.active
    assert "blocked by panda_link1-panda_hand (0.020 m apart)" in supervisor.detail
    supervisor.joint_state_received(2 * MS)
    assert not supervisor.gate(2 * MS) and supervisor.state == "blocked"  # halted: no step runs
    supervisor.goal_received(3 * MS, GoalKind.POSE)
    assert supervisor.state == "tracking" and supervisor.gate(3 * MS)
