"""Joint-space trajectories and the joint tracking law, without ROS.

Expected values are computed independently: the scaling polynomials written out here,
numeric differentiation of the sampled positions, and the points the trajectory was given.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.control.joint_limits import JointLimit, JointLimits
from manip_kin.control.joint_tracking import joint_tracking_step
from manip_kin.core.robots import load_robot
from manip_kin.errors import InvalidArgumentError
from manip_kin.motion.joint_trajectory import (
    JOINT_TIME_SCALINGS,
    MIN_MOVE_DURATION,
    TrajectoryPoint,
    move_duration,
    plan_joint_trajectory,
)

SCARA = load_robot("scara")
Q_START = np.zeros(4)
Q_GOAL = np.array([math.pi / 4, math.pi / 4, 0.2, 0.0])


def _numeric_velocity(plan, t, h=1e-6):
    return (plan.sample(t + h)[0] - plan.sample(t - h)[0]) / (2 * h)


def test_scara_cubic_move_follows_s_of_tau():
    plan = plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names, [TrajectoryPoint(2.0, Q_GOAL)], "cubic")
    assert plan.duration == 2.0
    for t in np.linspace(0.0, 2.0, 41):
        tau = t / 2.0
        s = 3 * tau**2 - 2 * tau**3
        q, qdot = plan.sample(t)
        np.testing.assert_allclose(q, Q_START + s * (Q_GOAL - Q_START), atol=1e-12)
        # ṡ = (6τ − 6τ²)/T
        np.testing.assert_allclose(qdot, (6 * tau - 6 * tau**2) / 2.0 * (Q_GOAL - Q_START), atol=1e-12)
        if 0.0 < t < 2.0:
            np.testing.assert_allclose(qdot, _numeric_velocity(plan, t), atol=1e-7)
    assert not plan.sample(0.0)[1].any() and not plan.sample(2.0)[1].any()
    np.testing.assert_array_equal(plan.sample(5.0)[0], Q_GOAL)
    assert plan.progress_at(0.5) == 0.25


def test_quintic_and_trapezoidal_scalings():
    quintic = plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names, [TrajectoryPoint(2.0, Q_GOAL)], "quintic")
    trapezoid = plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names, [TrajectoryPoint(3.0, Q_GOAL)], "trapezoidal")
    for tau in np.linspace(0.0, 1.0, 21):
        s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        np.testing.assert_allclose(quintic.sample(2.0 * tau)[0], s * Q_GOAL, atol=1e-12)
    # Trapezoid: the middle third at 1.5 times the mean speed, ramps of constant acceleration.
    mean = Q_GOAL / 3.0
    for t in (1.0, 1.5, 2.0):
        np.testing.assert_allclose(trapezoid.sample(t)[1], 1.5 * mean, atol=1e-12)
    np.testing.assert_allclose(trapezoid.sample(0.5)[1], 0.75 * mean, atol=1e-12)
    np.testing.assert_allclose(trapezoid.sample(1.5)[0], 0.5 * Q_GOAL, atol=1e-12)
    for t in np.linspace(0.05, 2.95, 30):
        np.testing.assert_allclose(trapezoid.sample(t)[1], _numeric_velocity(trapezoid, t), atol=1e-6)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    st.sampled_from(["cubic", "quintic"]),
    st.lists(
        st.tuples(
            st.floats(0.5, 2.0),
            st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4),
            st.lists(st.floats(-0.2, 0.2), min_size=4, max_size=4),
        ),
        min_size=1,
        max_size=4,
    ),
)
def test_multi_point_trajectories_pass_through_their_points_on_time(scaling, raw_points):
    """Random points (positions scaled into the limits, velocities where given): at each point's
    time the sample is that point, position and velocity are continuous across it, and the
    velocity is the derivative of the position."""
    lower, upper = SCARA.lower, SCARA.upper
    points, t = [], 0.0
    for k, (gap, unit, rates) in enumerate(raw_points):
        t += gap
        q = lower + (np.array(unit) + 1.0) / 2.0 * (upper - lower) * 0.9
        velocity = np.zeros(4) if k == len(raw_points) - 1 else np.array(rates) * 0.2
        points.append(TrajectoryPoint(t, q, velocity))
    try:
        plan = plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names, points, scaling)
    except InvalidArgumentError as error:
        assert "too fast" in str(error)  # the only reason such points may be refused
        return
    for point in points:
        q, qdot = plan.sample(point.time_from_start)
        np.testing.assert_allclose(q, point.positions, atol=1e-12)
        before = plan.sample(point.time_from_start - 1e-9)
        np.testing.assert_allclose(before[0], point.positions, atol=1e-7)
        if point is not points[-1]:
            np.testing.assert_allclose(qdot, point.velocities, atol=1e-9)
            np.testing.assert_allclose(before[1], point.velocities, atol=1e-5)
    for t in np.linspace(0.01, plan.duration - 0.01, 25):
        np.testing.assert_allclose(plan.sample(t)[1], _numeric_velocity(plan, t), atol=1e-5)
    # Within the velocity limits everywhere (the plan was accepted).
    speeds = np.array([np.abs(plan.sample(t)[1]) for t in np.linspace(0.0, plan.duration, 400)])
    assert np.all(speeds <= SCARA.velocity_limits * (1 + 1e-6))


def test_names_are_matched_in_any_order():
    names = list(reversed(SCARA.joint_names))
    plan = plan_joint_trajectory(SCARA, Q_START, names, [TrajectoryPoint(2.0, Q_GOAL[::-1])])
    np.testing.assert_allclose(plan.goal, Q_GOAL)


@pytest.mark.parametrize(
    "names, points, scaling, fragment",
    [
        (["joint1", "joint2", "joint3"], [TrajectoryPoint(2.0, [0, 0, 0])], "cubic", "lacks joints ['joint4']"),
        (["joint1", "joint2", "joint3", "elbow"], [TrajectoryPoint(2.0, [0] * 4)], "cubic", "['elbow'] are not joints"),
        (["joint1", "joint1", "joint3", "joint4"], [TrajectoryPoint(2, [0] * 4)], "cubic", "more than once"),
        (None, [], "cubic", "no points"),
        (None, [TrajectoryPoint(0.0, [0] * 4), TrajectoryPoint(1.0, [0] * 4)], "cubic", "is not after 0 (the start)"),
        (None, [TrajectoryPoint(2.0, [0] * 4), TrajectoryPoint(2.0, [0] * 4)], "cubic", "not after point 1's 2 s"),
        (None, [TrajectoryPoint(2.0, [0] * 4), TrajectoryPoint(1.0, [0] * 4)], "cubic", "strictly increasing"),
        (None, [TrajectoryPoint(math.nan, [0] * 4)], "cubic", "time_from_start nan"),
        (None, [TrajectoryPoint(2.0, [0, 0, 0.7, 0])], "cubic", "'joint3' = 0.7 m is outside its limits"),
        (None, [TrajectoryPoint(2.0, [4.0, 0, 0, 0])], "cubic", "valid: [-3.14159, 3.14159] rad"),
        (None, [TrajectoryPoint(2.0, [0, 0, 0])], "cubic", "has 3 positions; valid: 4"),
        (None, [TrajectoryPoint(2.0, [0] * 4, [0, 0])], "cubic", "has 2 velocities"),
        (None, [TrajectoryPoint(2.0, [0, math.inf, 0, 0])], "cubic", "NaN or infinity"),
        (None, [TrajectoryPoint(2.0, [0] * 4, [0.1, 0, 0, 0])], "cubic", "ends at rest"),
        (
            None,
            [TrajectoryPoint(1.0, [0.1] * 4, [0.1, 0, 0, 0]), TrajectoryPoint(2, [0] * 4)],
            "trapezoidal",
            "stops at every point",
        ),
        (None, [TrajectoryPoint(0.1, [1.0, 0, 0, 0])], "cubic", "'joint1' needs 15 rad/s"),
        (None, [TrajectoryPoint(2.0, [0] * 4)], "linear", "valid: cubic, quintic, trapezoidal"),
    ],
)
def test_bad_trajectories_are_rejected_with_the_reason(names, points, scaling, fragment):
    with pytest.raises(InvalidArgumentError) as error:
        plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names if names is None else names, points, scaling)
    assert fragment in str(error.value)


@pytest.mark.parametrize("scaling", ["cubic", "quintic", "trapezoidal"])
def test_move_duration_puts_the_slowest_joint_at_its_limit(scaling):
    duration = move_duration(SCARA, Q_START, Q_GOAL, scaling)
    plan = plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names, [TrajectoryPoint(duration, Q_GOAL)], scaling)
    speeds = np.array([np.abs(plan.sample(t)[1]) for t in np.linspace(0.0, duration, 2001)])
    ratio = (speeds / SCARA.velocity_limits).max()
    assert 0.999 < ratio <= 1.0 + 1e-9
    with pytest.raises(InvalidArgumentError, match="too fast"):
        plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names, [TrajectoryPoint(0.98 * duration, Q_GOAL)], scaling)
    assert move_duration(SCARA, Q_GOAL, Q_GOAL, scaling) == MIN_MOVE_DURATION


@pytest.mark.parametrize("scaling", JOINT_TIME_SCALINGS)
@pytest.mark.parametrize("acceleration", [0.5, 5.0, 50.0])
def test_move_duration_with_acceleration_and_jerk_limits(scaling, acceleration):
    """The shortest duration puts some joint at its velocity, acceleration or jerk limit (from
    samples of the planned move, by finite differences), none beyond; a one-point trajectory at
    time 0 gets it; 2 % faster is refused."""
    per_joint = {
        name: JointLimit(True, v, True, acceleration, False, 1.0, True, 20.0 * acceleration)
        for name, v in zip(SCARA.joint_names, SCARA.velocity_limits)
    }
    limits = JointLimits.of(SCARA, per_joint)
    plan = plan_joint_trajectory(SCARA, Q_START, SCARA.joint_names, [TrajectoryPoint(0.0, Q_GOAL)], scaling, limits)
    duration = plan.duration
    assert duration == pytest.approx(move_duration(SCARA, Q_START, Q_GOAL, scaling, limits))
    step = duration / 4000
    times = np.arange(1, 4000) * step
    speeds = np.array([plan.sample(t)[1] for t in times])
    accelerations = np.diff(speeds, axis=0) / step
    jerks = np.diff(accelerations, axis=0) / step
    ratios = [
        np.max(np.abs(speeds) / SCARA.velocity_limits),
        np.max(np.abs(accelerations) / acceleration),
    ]
    if scaling == "quintic":  # the only one whose jerk is bounded at the ends (see the module doc)
        ratios.append(np.max(np.abs(jerks) / (20.0 * acceleration)))
    assert max(ratios) <= 1.0 + 2e-3 and max(ratios) > 0.97, ratios
    with pytest.raises(InvalidArgumentError, match="too fast"):
        plan_joint_trajectory(
            SCARA, Q_START, SCARA.joint_names, [TrajectoryPoint(0.98 * duration, Q_GOAL)], scaling, limits
        )


# --- the tracking law ------------------------------------------------------------------------------


def test_tracking_law_feed_forward_plus_correction():
    q = np.array([0.1, -0.2, 0.1, 0.0])
    reference = np.array([0.15, -0.1, 0.12, 0.05])
    feed_forward = np.array([0.2, 0.0, -0.05, 0.1])
    out = joint_tracking_step(SCARA, q, reference, feed_forward, gain=2.0, dt=0.002)
    np.testing.assert_allclose(out.qdot, feed_forward + 2.0 * (reference - q), atol=1e-15)
    np.testing.assert_allclose(out.joint_error, reference - q)
    assert out.velocity_scale == 1.0 and out.limited_joints == ()


def test_tracking_law_respects_position_and_velocity_limits():
    # joint3 (prismatic, [0, 0.5] m) 0.5 mm above its lower limit, commanded down hard: a
    # period at its velocity limit (0.5 m/s) would take it 1 mm down.
    q = np.array([0.0, 0.0, 0.0005, 0.0])
    out = joint_tracking_step(SCARA, q, q, np.array([0.0, 0.0, -1.0, 0.0]), gain=1.0, dt=0.002)
    assert out.limited_joints == (2,)
    assert out.qdot[2] == pytest.approx(-0.25)  # lands exactly on the limit in one period
    # 1 mm above: at most its velocity limit, the joint cannot pass the limit in a period, so
    # it is not held; the scaling brings it to the limit's 0.5 m/s, landing on the limit.
    near = joint_tracking_step(SCARA, q * 2, q * 2, np.array([0.0, 0.0, -1.0, 0.0]), gain=1.0, dt=0.002)
    assert near.limited_joints == () and near.qdot[2] == pytest.approx(-0.5)
    at_limit = joint_tracking_step(SCARA, np.array([0, 0, 0.0, 0]), q, np.array([0, 0, -1.0, 0]), 0.0, 0.002)
    assert at_limit.qdot[2] == 0.0 and at_limit.limited_joints == (2,)
    # Far beyond the velocity limits: scaled by one factor, direction kept.
    wanted = np.array([10.0, -5.0, 0.0, 2.0])
    fast = joint_tracking_step(SCARA, np.zeros(4), np.zeros(4) + [0, 0, 0.2, 0], wanted, 0.0, 0.002)
    assert fast.velocity_scale < 1.0
    assert np.max(np.abs(fast.qdot) / SCARA.velocity_limits) == pytest.approx(1.0)
    np.testing.assert_allclose(fast.qdot / np.linalg.norm(fast.qdot), wanted / np.linalg.norm(wanted), atol=1e-12)
    with pytest.raises(InvalidArgumentError, match="dt"):
        joint_tracking_step(SCARA, q, q, None, 1.0, 0.0)
