"""A streamed goal moved to the instant the command acts at (manip_kin.control.streamed_goal)."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.control.streamed_goal import StreamedGoal, StreamedTwist, advance_pose, advance_reference, reference_at
from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.motion.lines import LineTrajectory, MotionLimits

PERIOD_NS = 1_000_000


def _skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _expm(matrix: np.ndarray) -> np.ndarray:
    """The matrix exponential by its power series (independent of Rodrigues' closed form)."""
    total, term = np.eye(3), np.eye(3)
    for k in range(1, 40):
        term = term @ matrix / k
        total = total + term
    return total


vectors = st.lists(st.floats(-5.0, 5.0), min_size=3, max_size=3).map(np.array)


@settings(max_examples=200, deadline=None)
@given(vectors, vectors, st.floats(-0.05, 0.05), st.floats(-math.pi, math.pi), st.floats(-1.5, 1.5))
def test_advance_pose_is_the_exponential_of_the_twist(angular, linear, seconds, yaw, pitch):
    pose = make_transform(rpy_to_matrix(0.3, pitch, yaw), [0.4, -0.2, 0.6])
    advanced = advance_pose(pose, angular, linear, seconds)
    # Independently: scipy's matrix exponential of the rotation vector, and the origin's travel.
    np.testing.assert_allclose(advanced[:3, :3], _expm(_skew(angular * seconds)) @ pose[:3, :3], atol=1e-12)
    np.testing.assert_allclose(advanced[:3, 3], pose[:3, 3] + linear * seconds, atol=1e-12)
    np.testing.assert_array_equal(advanced[3], [0.0, 0.0, 0.0, 1.0])
    # The rotation between them turns by the twist's angle, about its axis (which it keeps).
    turn = advanced[:3, :3] @ pose[:3, :3].T
    angle = np.linalg.norm(angular * seconds)
    assert math.isclose(math.acos(max(-1.0, min(1.0, (np.trace(turn) - 1.0) / 2.0))), angle, abs_tol=1e-6)
    np.testing.assert_allclose(turn @ (angular * seconds), angular * seconds, atol=1e-12)


def test_advance_reference_moves_along_the_velocities():
    np.testing.assert_allclose(advance_reference([0.1, -0.2], [1.0, 2.0], 0.003), [0.103, -0.194], atol=1e-15)
    # For an instant: moved from its stamp, back too; further than the bound, as it came.
    np.testing.assert_allclose(reference_at([0.1], [2.0], 5 * PERIOD_NS, 8 * PERIOD_NS, 0.01), [0.106], atol=1e-15)
    np.testing.assert_allclose(reference_at([0.1], [2.0], 5 * PERIOD_NS, 4 * PERIOD_NS, 0.01), [0.098], atol=1e-15)
    assert reference_at([0.1], [2.0], 5 * PERIOD_NS, 16 * PERIOD_NS, 0.01) == [0.1]


def _trapezoid_line(kind: str = "trapezoidal") -> LineTrajectory:
    down = rpy_to_matrix(0.0, math.pi / 2, 0.0)
    start, end = make_transform(down, [0.4, 0.1, 0.6]), make_transform(down, [-0.4, 0.3, 0.5])
    return LineTrajectory.plan(start, end, kind, MotionLimits(0.4, 0.5, 1.0))


def test_the_twist_is_moved_along_its_rate_through_an_acceleration_phase():
    line = _trapezoid_line()
    twist = StreamedTwist(0.01)
    for k in range(100, 104):  # 0.1 s in: accelerating at 0.5 m/s² along the line
        twist.update(k * PERIOD_NS, *line.sample(k * 1e-3)[1])
    for seconds in (0.0, 0.0005, 0.0015, 0.004, -0.002):
        angular, linear = twist.at(seconds)
        np.testing.assert_allclose(linear, line.sample(0.103 + seconds)[1][1], atol=1e-12)
        np.testing.assert_allclose(angular, 0.0, atol=1e-12)
    assert math.isclose(np.linalg.norm(twist.linear_rate), 0.5, rel_tol=1e-9)  # the line's acceleration


def test_a_step_or_a_corner_is_not_extrapolated():
    twist = StreamedTwist(0.01)
    moving = np.array([0.4, 0.0, 0.0])
    for k in range(3):
        twist.update(k * PERIOD_NS, np.zeros(3), moving)
    twist.update(3 * PERIOD_NS, np.zeros(3), np.zeros(3))  # a new motion starts at rest
    np.testing.assert_array_equal(twist.at(0.002)[1], np.zeros(3))
    # A corner: accelerating, then constant speed: no rate from the first constant sample on.
    twist = StreamedTwist(0.01)
    for k, speed in enumerate([0.10, 0.11, 0.12, 0.12]):
        twist.update(k * PERIOD_NS, np.zeros(3), np.array([speed, 0.0, 0.0]))
    np.testing.assert_array_equal(twist.at(0.003)[1], [0.12, 0.0, 0.0])
    # Samples further apart than max_gap give no rate.
    twist = StreamedTwist(0.002)
    for k, speed in enumerate([0.10, 0.11, 0.12]):
        twist.update(k * 5 * PERIOD_NS, np.zeros(3), np.array([speed, 0.0, 0.0]))
    np.testing.assert_array_equal(twist.at(0.001)[1], [0.12, 0.0, 0.0])


@settings(max_examples=100, deadline=None)
@given(st.integers(3, 2600), st.integers(0, 3), st.integers(-500_000, 3_500_000))
def test_a_goal_that_came_late_is_the_line_at_the_instant(sample_ms, late_periods, ahead_ns):
    """However many periods late the newest sample is, the goal at an instant near it is the
    line's own pose and twist there (within the second order of the acceleration's corners)."""
    line = _trapezoid_line()
    streamed = StreamedGoal(0.01)
    newest = sample_ms - late_periods
    for k in range(max(newest - 3, 0), newest + 1):
        pose, (angular, linear) = line.sample(k * 1e-3)
        streamed.pose_received(k * PERIOD_NS, pose)
        streamed.twist_received(k * PERIOD_NS, angular, linear)
    instant_ns = sample_ms * PERIOD_NS + ahead_ns
    pose, (angular, linear) = streamed.at(instant_ns)
    true_pose, (true_angular, true_linear) = line.sample(min(max(instant_ns * 1e-9, 0.0), line.duration))
    reach = (instant_ns - newest * PERIOD_NS) * 1e-9
    # A trapezoid's acceleration changes at two corners only: near one, the error is bounded by
    # the step in acceleration (0.5 m/s²) over the reach; away from them it is exact.
    bound_velocity = 0.5 * abs(reach) + 1e-12
    bound_position = 0.5 * 0.5 * reach * reach + 1e-12
    assert np.linalg.norm(linear - true_linear) <= bound_velocity
    assert np.linalg.norm(pose[:3, 3] - true_pose[:3, 3]) <= bound_position
    np.testing.assert_allclose(pose[:3, :3], true_pose[:3, :3], atol=1e-12)
    np.testing.assert_allclose(angular, true_angular, atol=1e-12)


def test_a_goal_in_the_cruise_is_exact_however_late():
    line = _trapezoid_line()
    streamed = StreamedGoal(0.01)
    for k in range(1200, 1204):  # cruising at 0.4 m/s
        pose, twist = line.sample(k * 1e-3)
        streamed.pose_received(k * PERIOD_NS, pose)
        streamed.twist_received(k * PERIOD_NS, *twist)
    for late_ns in (400_000, 1_500_000, 2_500_000, 9_000_000):
        pose, _ = streamed.at(1203 * PERIOD_NS + late_ns)
        np.testing.assert_allclose(pose, line.sample(1.203 + late_ns * 1e-9)[0], atol=1e-12)
    # Beyond max_offset (a stalled stream): the goal as it came.
    pose, _ = streamed.at(1203 * PERIOD_NS + 20_000_000)
    np.testing.assert_array_equal(pose, line.sample(1.203)[0])


def _line_with_jitter(
    move_goal: bool,
    seed: int = 3,
    kind: str = "trapezoidal",
    late: float = 0.1,
    late_cycles: float = 0.0,
    feed_forward: bool = True,
) -> tuple[float, float]:
    """The irb120 line at 0.4 m/s (timed ``kind``) through the law and the command filter at 1 kHz, as the
    controller node composes them, with a goal stream that runs late: one sample in ten comes
    a period late (``late``: the fraction; the law then has the one before). Each command drives the next period, and
    the state is predicted to its middle. With ``late_cycles`` the controller is starved: after
    a cycle, with that chance, the next comes 2 to 10 periods late, the arm driving the last
    command meanwhile; the filter is told the time that passed and, with ``feed_forward``, that
    the law follows the line. Returns (max deviation from the segment [mm], fraction of cycles
    the filter limited)."""
    from manip_kin.control.command_filter import CommandFilter, FilterResult
    from manip_kin.control.joint_limits import JointLimits
    from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
    from manip_kin.control.state_prediction import predict_positions
    from manip_kin.core.kinematics import pose_in_base
    from manip_kin.core.robots import load_robot
    from manip_kin.ik.iterative import solve_ik
    from manip_kin.motion.lines import distance_to_segment

    model = load_robot("irb120")
    line = _trapezoid_line(kind)
    limits = JointLimits.of(model)
    controller = CartesianController(model, ControllerConfig(gain_angular=6.0, gain_linear=6.0))
    command_filter = CommandFilter(limits, model.lower, model.upper, 1e-3)
    horizon = max(1e-3, limits.stopping_time(limits.velocity))
    rng = np.random.default_rng(seed)
    q = solve_ik(model, line.sample(0.0)[0], np.zeros(model.dof)).q
    applied = np.zeros(model.dof)  # what the robot drove the last period with (its reported velocity)
    streamed = StreamedGoal(0.01)
    newest = None
    points, limited = [], 0
    steps = int(line.duration * 1000)
    starving = np.random.default_rng(seed + 1)
    next_cycle, last_cycle = 0, None
    for k in range(steps):  # the state at k ms, before period k (k to k+1 ms) is driven
        if newest is None or rng.random() >= late:  # else this period's sample is late
            newest = k
            pose, twist = line.sample(k * 1e-3)
            streamed.pose_received(k * PERIOD_NS, pose)
            streamed.twist_received(k * PERIOD_NS, *twist)
        if k >= next_cycle:
            ahead = 0.5e-3  # the middle of the period this command drives
            q_law = predict_positions(q, applied, ahead, model.lower, model.upper)
            if move_goal:
                goal, twist = streamed.at(k * PERIOD_NS + int(ahead * 1e9))
            else:
                goal, twist = line.sample(newest * 1e-3)
            output = controller.step(q_law, goal, twist, horizon)
            elapsed = None if last_cycle is None else (k - last_cycle) * 1e-3
            applied = np.asarray(command_filter.update(output.qdot, q, elapsed, feed_forward))
            limited += command_filter.result is FilterResult.LIMITED
            last_cycle = k
            next_cycle = k + (int(starving.integers(2, 11)) if late_cycles and starving.random() < late_cycles else 1)
        q = q + 1e-3 * applied
        points.append(pose_in_base(model, q, controller.frame_index)[:3, 3])
    start, end = line.sample(0.0)[0][:3, 3], line.sample(line.duration)[0][:3, 3]
    return float(distance_to_segment(np.array(points), start, end).max() * 1e3), limited / steps


def test_a_goal_moved_to_the_states_instant_keeps_the_line_within_its_tolerance():
    moved_deviation, moved_limited = _line_with_jitter(move_goal=True)
    as_it_came_deviation, as_it_came_limited = _line_with_jitter(move_goal=False)
    assert moved_deviation <= 0.05, moved_deviation  # issue 24's tolerance for this line: 0.2 mm
    # Taken as it came, a late sample makes the command jump by the gain times a period's travel:
    # the filter limits a third of the cycles, and the tool leaves the line by more.
    assert as_it_came_limited > 0.3 and moved_limited < 0.05, (as_it_came_limited, moved_limited)
    assert as_it_came_deviation > 1.5 * moved_deviation, (as_it_came_deviation, moved_deviation)
    # Even so each joint's own time-optimal step keeps it near the line: 0.025 mm here, where
    # ruckig's synchronised profiles (and, after them, a step with the jerk held) gave 0.16 mm.
    assert as_it_came_deviation <= 0.08, as_it_came_deviation


def test_a_jerk_limited_line_asks_for_no_jerk_step_the_filter_must_round_off():
    """On time, the trapezoid's corners (acceleration steps) are the cycles the filter limits,
    and where the tool leaves the line; the jerk-limited line has none of them."""
    trapezoid_deviation, trapezoid_limited = _line_with_jitter(move_goal=True, late=0.0)
    rounded_deviation, rounded_limited = _line_with_jitter(move_goal=True, late=0.0, kind="jerk_limited")
    assert trapezoid_limited > 0.003 and rounded_limited == 0.0, (trapezoid_limited, rounded_limited)
    assert rounded_deviation < 0.5 * trapezoid_deviation, (rounded_deviation, trapezoid_deviation)


def test_a_starved_controller_makes_up_what_its_late_cycles_cost_the_line():
    """2 % of the cycles late by 2-10 periods, the arm holding the last command: the jerk limit
    closes each lag late, and the tool leaves the line; made up, it stays within issue 24's
    0.2 mm, and nearer than without the filter's make-up."""
    deviations = {
        feed_forward: [
            _line_with_jitter(True, seed, "jerk_limited", 0.0, late_cycles=0.02, feed_forward=feed_forward)[0]
            for seed in (0, 1, 2)
        ]
        for feed_forward in (True, False)
    }
    made_up, not_made_up = deviations[True], deviations[False]
    assert max(made_up) <= 0.2, deviations
    assert all(a < 0.8 * b for a, b in zip(made_up, not_made_up)), deviations


samples = st.tuples(
    st.integers(-(2**40), 2**40),
    st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(samples, min_size=1, max_size=8), st.integers(-(2**41), 2**41))
def test_hostile_stamps_give_a_bounded_finite_goal(stream, instant_ns):
    """Stamps nanoseconds apart (rates without bound), out of order or far away: the goal and
    its twist stay finite, the twist within the speeds a sample may have (the controller
    rejects a faster sample)."""
    streamed = StreamedGoal(0.01, max_linear=1.0, max_angular=2.0)
    pose = make_transform(rpy_to_matrix(0.1, 0.2, 0.3), [0.3, 0.0, 0.5])
    for stamp_ns, angular, linear in stream:
        angular, linear = np.array(angular) / math.sqrt(3.0), np.array(linear) / math.sqrt(3.0)
        streamed.pose_received(stamp_ns, pose)
        streamed.twist_received(stamp_ns, angular, linear)
    goal, (angular, linear) = streamed.at(instant_ns)
    assert np.all(np.isfinite(goal)) and np.all(np.isfinite(angular)) and np.all(np.isfinite(linear))
    assert np.linalg.norm(linear) <= 1.0 + 1e-12 and np.linalg.norm(angular) <= 2.0 + 1e-12
    # Moved at most 10 ms at those speeds.
    assert np.linalg.norm(goal[:3, 3] - pose[:3, 3]) <= 0.01 * 1.0 + 1e-12


def test_samples_nanoseconds_apart_do_not_fling_the_twist():
    twist = StreamedTwist(0.01, max_linear=1.0, max_angular=2.0)
    for k in range(3):  # 1e8 m/s² from the stamps
        twist.update(k, np.array([0.0, 0.0, 0.1 * k]), np.array([0.1 * k, 0.0, 0.0]))
    angular, linear = twist.at(0.005)
    np.testing.assert_allclose(linear, [1.0, 0.0, 0.0], atol=1e-12)  # capped, direction kept
    np.testing.assert_allclose(angular, [0.0, 0.0, 2.0], atol=1e-12)
