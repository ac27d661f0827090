"""State prediction (manip_kin.control.state_prediction): the horizon against an enumeration of robot
cycles, the fallbacks, and the claim it exists for: a line tracked through a delayed loop."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.control.state_prediction import (
    MAX_STATE_AGE_PERIODS,
    command_horizon,
    predict_positions,
    state_for_command,
)
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.ik.iterative import solve_ik
from manip_kin.motion.lines import LineTrajectory, MotionLimits, distance_to_segment


def _horizon_by_enumeration(age: float, period: float, latency: float) -> float:
    """Walk the robot's cycles (stamp + k·period, k >= 1) to the first one at or after the
    command's arrival; the command drives the period ending there: its middle."""
    arrival = max(age, 0.0) + latency
    k = 1
    while k * period < arrival:
        k += 1
    return k * period - period / 2


@settings(max_examples=300)
@given(
    age=st.floats(-0.01, 0.05, allow_nan=False),
    period=st.floats(1e-4, 0.02),
    latency=st.floats(0.0, 0.05),
)
def test_horizon_is_the_middle_of_the_period_the_command_drives(age, period, latency):
    cycles = (max(age, 0.0) + latency) / period
    assume(abs(cycles - round(cycles)) > 1e-6)  # exactly on a cycle: either side is right
    assert math.isclose(
        command_horizon(age, period, latency), _horizon_by_enumeration(age, period, latency), abs_tol=1e-9 * period
    )


def test_prediction_stops_at_limits_and_leaves_an_outside_joint_where_it_is():
    lower, upper = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])
    q = np.array([0.99, 0.0, 1.002])  # the last joint reported just past its limit
    predicted = predict_positions(q, np.array([10.0, 0.5, 0.0]), 0.01, lower, upper)
    np.testing.assert_array_equal(predicted, [1.0, 0.005, 1.002])
    np.testing.assert_array_equal(
        predict_positions(q, np.array([-1.0, 0.0, -1.0]), 0.01, lower, upper), [0.98, 0.0, 0.992]
    )


finite = st.floats(-4.0, 4.0, allow_nan=False)


@settings(max_examples=300)
@given(
    st.lists(st.tuples(finite, finite, st.floats(-1.0, 0.0), st.floats(0.0, 1.0)), min_size=1, max_size=8),
    st.floats(0.0, 0.05),
)
def test_prediction_is_clamped_into_the_limits_widened_to_the_reported_position(joints, horizon):
    """Each joint ends in [min(lower, q), max(upper, q)]: stopped on a limit it would cross from
    inside, never moved outward by a limit it is already beyond (both sides, both directions)."""
    q, qdot, lower, upper = (np.array(column) for column in zip(*joints))
    expected = np.clip(q + qdot * horizon, np.minimum(lower, q), np.maximum(upper, q))
    np.testing.assert_array_equal(predict_positions(q, qdot, horizon, lower, upper), expected)
    # Lists of floats (what the controller passes for the limits) give the same answer.
    np.testing.assert_array_equal(predict_positions(q, qdot, horizon, list(lower), list(upper)), expected)


def test_state_is_used_as_reported_without_plausible_velocities_or_age():
    q = np.array([0.1, 0.2])
    qdot = np.array([0.5, -0.5])
    limits = (np.array([-3.0, -3.0]), np.array([3.0, 3.0]))
    max_rate = np.array([1.0, 1.0])
    period = 0.001

    def use(velocities, age):
        return state_for_command(q, velocities, age, period, 0.0, *limits, max_rate)

    np.testing.assert_allclose(use(qdot, 0.0), q + qdot * period / 2)
    np.testing.assert_allclose(use(qdot, 1.5 * period), q + qdot * 1.5 * period)
    for velocities, age in (
        (None, 0.0),
        (np.array([math.nan, 0.0]), 0.0),
        (np.array([0.0, math.inf]), 0.0),
        (np.array([1.5, 0.0]), 0.0),  # above max_rate
        (qdot, -1.5 * period),  # stamped in the future: clocks disagree
        (qdot, (MAX_STATE_AGE_PERIODS + 0.5) * period),  # too old to extrapolate
    ):
        assert use(velocities, age) is q


def _line_deviation(
    controller_phase: float, generator_phase: float, predict: bool, delivery: float = 0.2e-3
) -> tuple[float, float]:
    """Largest distance [m] of the irb120 tool from a 0.4 m/s line ``(while the reference moves,
    overall)``: the second includes overshooting the end. Robot,
    generator and controller run 1 kHz loops in separate processes (robot cycles at k ms, the
    others ``*_phase`` s later). Every message arrives ``delivery`` s after it is sent; the
    controller takes the newest joint state and goal that have arrived; the robot integrates
    the newest command that has arrived at each cycle and stamps the result."""
    model = load_robot("irb120")
    period = 0.001
    down = rpy_to_matrix(0.0, math.pi / 2, 0.0)
    start, end = make_transform(down, [0.4, 0.1, 0.6]), make_transform(down, [0.2, 0.2, 0.55])
    line = LineTrajectory.plan(start, end, "constant", MotionLimits(0.4, 1.0, 1.0, 1.0))
    controller = CartesianController(model, ControllerConfig(gain_linear=6.0, gain_angular=6.0))
    q = np.asarray(solve_ik(model, start, np.zeros(6)).q)
    lower, upper = model.lower, model.upper
    states = [(0.0, q.copy(), np.zeros(6))]  # (sent, positions, velocities)
    goals = [(0.0, start, (np.zeros(3), np.zeros(3)))]  # (sent, pose, twist)
    commands = [(0.0, np.zeros(6))]  # (sent, rates)
    moving = overall = 0.0
    for cycle in range(1, int(line.duration / period) + 100):
        robot_time = cycle * period
        rates = [rates for sent, rates in commands if sent + delivery <= robot_time][-1]
        q = np.clip(q + rates * period, lower, upper)
        states.append((robot_time, q.copy(), rates))
        position = frame_pose(model, q, controller.frame_index)[:3, 3]
        deviation = float(distance_to_segment(position[None], start[:3, 3], end[:3, 3])[0])
        overall = max(overall, deviation)
        if robot_time < line.duration:
            moving = max(moving, deviation)
        generator_time = robot_time + generator_phase
        goals.append((generator_time, *line.sample(generator_time)))
        now = robot_time + controller_phase
        stamp, q_seen, qdot_seen = [state for state in states if state[0] + delivery <= now][-1]
        _, goal, twist = [goal for goal in goals if goal[0] + delivery <= now][-1]
        if predict:
            q_seen = state_for_command(
                q_seen, qdot_seen, now - stamp, period, delivery, lower, upper, model.velocity_limits
            )
        commands.append((now, np.asarray(controller.step(q_seen, goal, twist, period).qdot)))
        states, goals, commands = states[-5:], goals[-5:], commands[-5:]
    return moving, overall


@pytest.mark.parametrize("controller_phase, generator_phase", [(0.05e-3, 0.1e-3), (0.5e-3, 0.6e-3), (0.9e-3, 0.3e-3)])
def test_prediction_keeps_a_line_through_a_delayed_loop(controller_phase, generator_phase):
    # Without prediction the tool runs beside the line by ~0.06 mm per period of delay (1 or 2
    # periods here, by phase); with it, by a few µm. The overshoot at the end shrinks too, but
    # less: it depends on when the generator's stop gets through (the goal's own delay).
    moving, overall = _line_deviation(controller_phase, generator_phase, predict=False)
    predicted_moving, predicted_overall = _line_deviation(controller_phase, generator_phase, predict=True)
    assert moving > 0.05e-3, moving
    assert predicted_moving < 0.01e-3, predicted_moving
    assert predicted_overall < overall / 2, (predicted_overall, overall)
