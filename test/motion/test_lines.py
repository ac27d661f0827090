"""Straight-line trajectories: time scalings, sampling, twists, reachability."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import (
    make_transform,
    matrix_to_quat,
    matrix_to_rotvec,
    quat_slerp,
    quat_to_matrix,
    rpy_to_matrix,
)
from manip_kin.errors import InvalidArgumentError, NonFiniteError, NotARotationError
from manip_kin.motion.line_reach import check_line_reachable
from manip_kin.motion.lines import TIME_SCALINGS, LineTrajectory, MotionLimits, distance_to_segment, make_time_scaling

START = make_transform(rpy_to_matrix(0.2, -0.4, 1.0), [0.4, 0.1, 0.6])
GOAL = make_transform(rpy_to_matrix(-0.5, 0.3, 2.2), [-0.4, 0.3, 0.5])
LIMITS = MotionLimits(
    max_linear_velocity=0.4, max_linear_acceleration=0.8, max_angular_velocity=0.6, max_angular_acceleration=1.5
)


def _rates(scaling, count=20001):
    t = np.linspace(0.0, scaling.duration, count)
    values = np.array([scaling.evaluate(x) for x in t])
    return t, values[:, 0], values[:, 1], values[:, 2]


@pytest.mark.parametrize("kind", TIME_SCALINGS)
def test_scaling_boundaries_and_monotone(kind):
    scaling = make_time_scaling(kind, 0.8, 0.3, LIMITS)
    t, s, sdot, sddot = _rates(scaling)
    assert s[0] == 0.0 and s[-1] == 1.0
    assert np.all(np.diff(s) >= -1e-15)
    # ṡ is the derivative of s (central differences away from the jumps of 'constant').
    numeric = np.gradient(s, t)
    assert np.allclose(numeric[2:-2], sdot[2:-2], atol=2e-3 / scaling.duration)
    if kind != "constant":
        assert sdot[0] == 0.0 and sdot[-1] == 0.0
        assert scaling.evaluate(0.0)[1] == 0.0 and scaling.evaluate(scaling.duration)[1] == 0.0
        assert scaling.evaluate(1e-9)[1] < 1e-6 and scaling.evaluate(scaling.duration - 1e-9)[1] < 1e-6
    else:
        assert math.isclose(scaling.evaluate(1e-9)[1], 1.0 / scaling.duration)
    if kind == "quintic":
        assert abs(sddot[0]) < 1e-12 and abs(sddot[-1]) < 1e-9


@pytest.mark.parametrize("kind", TIME_SCALINGS)
def test_peak_velocity_and_acceleration_respected(kind):
    length, angle = 0.8, 0.3
    scaling = make_time_scaling(kind, length, angle, LIMITS)
    _, _, sdot, sddot = _rates(scaling)
    assert sdot.max() * length <= LIMITS.max_linear_velocity * (1 + 1e-9)
    assert sdot.max() * angle <= LIMITS.max_angular_velocity * (1 + 1e-9)
    # The fastest scaling within the limits: some limit is active.
    linear_peak = sdot.max() * length
    assert math.isclose(scaling.peak_rate * length, linear_peak, rel_tol=1e-3)
    if kind != "constant":
        assert np.abs(sddot).max() * length <= LIMITS.max_linear_acceleration * (1 + 1e-9)
    active = max(
        linear_peak / LIMITS.max_linear_velocity, np.abs(sddot).max() * length / LIMITS.max_linear_acceleration
    )
    assert active > 0.999 or kind == "constant"


def test_trapezoid_cruises_at_limit_and_triangle_for_short_lines():
    long = make_time_scaling("trapezoidal", 1.0, 0.0, LIMITS)
    assert math.isclose(long.ramp_time, 0.5)  # 0.4 / 0.8
    assert math.isclose(long.duration, 1.0 / 0.4 + 0.5)
    assert math.isclose(long.evaluate(long.duration / 2)[1] * 1.0, 0.4)
    short = make_time_scaling("trapezoidal", 0.05, 0.0, LIMITS)
    assert math.isclose(short.duration, 2 * math.sqrt(0.05 / 0.8))
    assert short.evaluate(short.duration / 2)[1] * 0.05 < 0.4


@settings(max_examples=60, deadline=None)
@given(
    length=st.floats(1e-3, 3.0),
    speed=st.floats(0.01, 2.0),
    acceleration=st.floats(0.05, 10.0),
    jerk=st.floats(0.5, 500.0),
)
def test_jerk_limited_line_keeps_speed_acceleration_and_jerk_and_is_the_fastest(length, speed, acceleration, jerk):
    """The double-S line: rates from the profile's own samples by finite differences."""
    limits = MotionLimits(speed, acceleration, 1.0, 1.0, max_linear_jerk=jerk)
    scaling = make_time_scaling("jerk_limited", length, 0.0, limits)
    t, s, sdot, sddot = _rates(scaling, 20001)
    dt = t[1] - t[0]
    assert s[0] == 0.0 and s[-1] == 1.0 and sdot[0] == 0.0 and sdot[-1] == 0.0
    # Each of s, ṡ, s̈ is the derivative of the one before (central differences, at every sample
    # and on both sides of each phase's ends), and none steps: across a phase's end the values
    # agree to the first order of the gap.
    h = 1e-6 * scaling.duration
    ends = [scaling.jerk_time, scaling.ramp_time - scaling.jerk_time, scaling.ramp_time]
    ends += [scaling.duration - end for end in ends]
    for instant in [*t[1:-1:50], *(e + side * 10 * h for e in ends for side in (-1, 1))]:
        before, after = scaling.evaluate(instant - h), scaling.evaluate(instant + h)
        now = scaling.evaluate(instant)
        # to the differences' truncation (the jerk times h², or h near a corner of s̈) and round-off
        assert abs((after[0] - before[0]) / (2 * h) - now[1]) <= jerk / length * h * h + 1e-12 / h
        assert abs((after[1] - before[1]) / (2 * h) - now[2]) <= jerk / length * h + 1e-12 / h
    for end in ends:
        before, after = scaling.evaluate(end - h), scaling.evaluate(end + h)
        assert abs(after[2] - before[2]) <= 2 * h * jerk / length * (1 + 1e-6) + 1e-12
    assert abs(sddot[0]) < 1e-9 / scaling.duration**2 and abs(sddot[-1]) < 1e-9 / scaling.duration**2
    numeric_jerk = np.abs(np.diff(sddot)).max() / dt * length
    assert numeric_jerk <= jerk * (1 + 1e-6)
    assert np.abs(sdot).max() * length <= speed * (1 + 1e-9)
    assert np.abs(sddot).max() * length <= acceleration * (1 + 1e-9)
    # Rest to rest as fast as the limits let it: with a cruise, the time at the speed plus one
    # ramp (v/a + a/j when the acceleration limit is reached, else 2·sqrt(v/j)).
    ramp = (
        speed / acceleration + acceleration / jerk if speed * jerk >= acceleration**2 else 2 * math.sqrt(speed / jerk)
    )
    if speed * ramp <= length:
        assert math.isclose(scaling.duration, length / speed + ramp, rel_tol=1e-9)
    else:  # no cruise: some limit other than the speed is reached
        assert np.abs(sddot).max() * length > acceleration * 0.999 or numeric_jerk > jerk * 0.99
    # Never faster than the trapezoid, which has the same speed and acceleration limits.
    assert scaling.duration >= make_time_scaling("trapezoidal", length, 0.0, limits).duration * (1 - 1e-12)


def test_constant_velocity_line_irb120_scenario():
    line = LineTrajectory.plan(START, GOAL, "constant", MotionLimits(0.4, 1.0, 10.0, 10.0))
    length = math.sqrt(0.8**2 + 0.2**2 + 0.1**2)
    assert math.isclose(line.length, length)
    assert math.isclose(line.duration, length / 0.4)
    _, (_, linear) = line.sample(0.3 * line.duration)
    assert math.isclose(np.linalg.norm(linear), 0.4)


def test_zero_length_line_is_instant():
    line = LineTrajectory.plan(START, START, "quintic", LIMITS)
    assert line.duration == 0.0
    pose, (angular, linear) = line.sample(0.0)
    np.testing.assert_allclose(pose, START, atol=1e-12)
    assert not angular.any() and not linear.any()


@pytest.mark.parametrize("kind", TIME_SCALINGS)
def test_zero_length_pure_rotation_line(kind):
    """Same position, other orientation: the angular limits alone size the motion."""
    goal = make_transform(rpy_to_matrix(0.2, -0.4, 1.0 + 0.9), START[:3, 3])
    angle = np.linalg.norm(matrix_to_rotvec(goal[:3, :3] @ START[:3, :3].T))
    line = LineTrajectory.plan(START, goal, kind, LIMITS)
    assert line.length == 0.0 and line.duration > 0.0
    t, _, sdot, sddot = _rates(line.scaling)
    # Peak angular rate at (not above) its limit for the constant and trapezoidal profiles' cruise.
    assert sdot.max() * angle <= LIMITS.max_angular_velocity * (1 + 1e-9)
    if kind != "constant":
        assert np.abs(sddot).max() * angle <= LIMITS.max_angular_acceleration * (1 + 1e-9)
        active = max(
            sdot.max() * angle / LIMITS.max_angular_velocity,
            np.abs(sddot).max() * angle / LIMITS.max_angular_acceleration,
        )
        assert active > 0.999  # the fastest profile within the angular limits
    else:
        assert math.isclose(line.duration, angle / LIMITS.max_angular_velocity)
    for time in np.linspace(0.0, line.duration, 7):
        pose, (angular, linear) = line.sample(time)
        np.testing.assert_array_equal(pose[:3, 3], START[:3, 3])  # the position never moves
        assert not linear.any()
        s_value, s_rate, _ = line.scaling.evaluate(time)
        expected = quat_to_matrix(quat_slerp(matrix_to_quat(START[:3, :3]), matrix_to_quat(goal[:3, :3]), s_value))
        np.testing.assert_allclose(pose[:3, :3], expected, atol=1e-9)
        # ω is about the fixed rotation axis at s' times the total angle.
        axis = matrix_to_rotvec(goal[:3, :3] @ START[:3, :3].T) / angle
        np.testing.assert_allclose(angular, axis * angle * s_rate, atol=1e-9)
    np.testing.assert_allclose(line.sample(line.duration)[0], goal, atol=1e-12)


@pytest.mark.parametrize("kind", ["trapezoidal", "cubic", "quintic"])
def test_angular_acceleration_limit_sizes_a_rotation_heavy_line(kind):
    """A short move with a large rotation under a low angular acceleration: that limit decides."""
    limits = MotionLimits(
        max_linear_velocity=1.0, max_linear_acceleration=10.0, max_angular_velocity=5.0, max_angular_acceleration=0.5
    )
    length, angle = 0.01, 1.2
    scaling = make_time_scaling(kind, length, angle, limits)
    _, _, sdot, sddot = _rates(scaling)
    peak_angular_acceleration = np.abs(sddot).max() * angle
    assert peak_angular_acceleration <= 0.5 * (1 + 1e-9)
    assert peak_angular_acceleration == pytest.approx(0.5, rel=1e-3)  # active
    assert sdot.max() * angle < 5.0 and np.abs(sddot).max() * length < 10.0  # the others are not
    # Without that limit the same move is faster: the limit was what made it slow.
    loose = MotionLimits(1.0, 10.0, 5.0, 50.0)
    assert make_time_scaling(kind, length, angle, loose).duration < scaling.duration


@pytest.mark.parametrize("kind", TIME_SCALINGS)
def test_sample_positions_on_segment_and_orientation_is_slerp(kind):
    line = LineTrajectory.plan(START, GOAL, kind, LIMITS)
    np.testing.assert_allclose(line.sample(0.0)[0], START, atol=1e-12)
    np.testing.assert_allclose(line.sample(line.duration)[0], GOAL, atol=1e-12)
    np.testing.assert_allclose(line.sample(line.duration + 5.0)[0], GOAL, atol=1e-12)
    q0, q1 = matrix_to_quat(START[:3, :3]), matrix_to_quat(GOAL[:3, :3])
    for t in np.linspace(0.0, line.duration, 13):
        pose, _ = line.sample(t)
        assert distance_to_segment(pose[:3, 3], START[:3, 3], GOAL[:3, 3]) < 1e-12
        s = line.scaling.evaluate(t)[0]
        np.testing.assert_allclose(pose[:3, :3], quat_to_matrix(quat_slerp(q0, q1, s)), atol=1e-9)
        np.testing.assert_allclose(pose[:3, 3], START[:3, 3] + s * (GOAL[:3, 3] - START[:3, 3]), atol=1e-12)


@pytest.mark.parametrize("kind", TIME_SCALINGS)
def test_twist_equals_numeric_derivative_of_pose(kind):
    line = LineTrajectory.plan(START, GOAL, kind, LIMITS)
    h = 1e-6
    for t in np.linspace(0.05, line.duration - 0.05, 9) * 1.0:
        before, _ = line.sample(t - h)
        after, _ = line.sample(t + h)
        _, (angular, linear) = line.sample(t)
        np.testing.assert_allclose((after[:3, 3] - before[:3, 3]) / (2 * h), linear, atol=1e-6)
        # ω in base: log(R(t+h) R(t-h)ᵀ) / 2h
        np.testing.assert_allclose(matrix_to_rotvec(after[:3, :3] @ before[:3, :3].T) / (2 * h), angular, atol=1e-6)
    _, (angular, linear) = line.sample(-1.0)
    assert not angular.any() and not linear.any()


def test_bad_inputs_raise():
    with pytest.raises(InvalidArgumentError, match="valid: trapezoidal"):
        make_time_scaling("linear", 1.0, 0.0, LIMITS)
    with pytest.raises(InvalidArgumentError, match="max_linear_velocity"):
        MotionLimits(max_linear_velocity=0.0)
    bad = START.copy()
    bad[0, 3] = math.nan
    with pytest.raises(NonFiniteError, match="start pose contains NaN or infinity"):
        LineTrajectory.plan(bad, GOAL)
    skewed = START.copy()
    skewed[:3, :3] *= 2.0
    with pytest.raises(NotARotationError, match=r"start pose rotation is not a rotation matrix \(det 8,"):
        LineTrajectory(skewed, GOAL, make_time_scaling("cubic", 1, 0, LIMITS))


def test_distance_to_segment():
    d = distance_to_segment(np.array([[0.5, 1.0, 0.0], [2.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]), [0, 0, 0], [1, 0, 0])
    np.testing.assert_allclose(d, [1.0, 1.0, 1.0])


def test_reach_check_irb120_line_down_and_unreachable_line():
    model = load_robot("irb120")
    down = rpy_to_matrix(0.0, math.pi / 2, 0.0)
    start = make_transform(down, [0.4, 0.1, 0.6])
    approach = LineTrajectory.plan(frame_pose(model, np.zeros(6)), start)
    report = check_line_reachable(model, approach, np.zeros(6))
    assert report.reachable, report.reason
    np.testing.assert_allclose(frame_pose(model, report.q_end)[:3, 3], [0.4, 0.1, 0.6], atol=1e-4)
    line = LineTrajectory.plan(
        start, make_transform(down, [-0.4, 0.3, 0.5]), "constant", MotionLimits(0.4, 1.0, 1.0, 1.0)
    )
    assert check_line_reachable(model, line, report.q_end).reachable
    too_far = LineTrajectory.plan(start, make_transform(down, [1.5, 0.1, 0.6]))
    far = check_line_reachable(model, too_far, report.q_end)
    assert not far.reachable
    assert 0.0 < far.progress_reached < 0.5
    assert "leaves the arm's reach" in far.reason and far.position_error > 1e-4


def test_reach_check_genova7_through_prismatic_limit():
    model = load_robot("genova7")
    q0 = model.start_configuration()
    goal = make_transform(rpy_to_matrix(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])
    report = check_line_reachable(model, LineTrajectory.plan(frame_pose(model, q0), goal), q0)
    assert report.reachable, report.reason
    assert model.within_limits(report.q_end)
    np.testing.assert_allclose(frame_pose(model, report.q_end), goal, atol=2e-4)
