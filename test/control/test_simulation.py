"""Offline simulation of the control law: the robots.md scenarios and convergence properties.

Expected times and rates come from the control law's own closed form (the error decays
as exp(-K t)), expected poses from the forward kinematics; nothing is copied from a table.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from kin_reference import rodrigues

from manip_kin.control.resolved_rate import ControllerConfig, pose_error
from manip_kin.control.simulation import simulate
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.errors import InvalidArgumentError, ManipKinError

GENOVA7_GOAL = make_transform(rpy_to_matrix(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])


@pytest.fixture(scope="module")
def genova7():
    return load_robot("genova7")


@pytest.fixture(scope="module")
def pose_goal_run(genova7):
    return simulate(
        genova7, genova7.initial_positions, GENOVA7_GOAL, ControllerConfig(), dt=0.001, duration=18.0, record_every=10
    )


def test_genova7_pose_goal_converges_within_18_s(genova7, pose_goal_run):
    result = pose_goal_run
    assert result.converged, result.reason
    # The law's time: both errors decay as exp(-0.8 t), so the larger initial one reaches the
    # 1e-6 tolerance at ln(e0 / 1e-6) / 0.8 (~17 s). Margin 1 %: the discrete step decays by
    # (1 - K dt) <= exp(-K dt), i.e. at most K dt / 2 = 0.04 % faster, and a stall at the
    # prismatic limit would cost seconds, not 0.17 s.
    orientation, position = pose_error(frame_pose(genova7, genova7.initial_positions), GENOVA7_GOAL)
    law = math.log(max(np.linalg.norm(orientation), np.linalg.norm(position)) / 1e-6) / 0.8
    assert abs(result.time_to_converge - law) <= 0.01 * law, (result.time_to_converge, law)
    assert result.final_position_error < 1e-6 and result.final_orientation_error < 1e-6
    # The final configuration really puts the tool on the goal (independent FK call).
    orientation, position = pose_error(frame_pose(genova7, result.q_final), GENOVA7_GOAL)
    assert np.linalg.norm(position) < 1e-6 and np.linalg.norm(orientation) < 1e-6
    assert result.steps == round(result.time_to_converge / 0.001)


def test_genova7_pose_goal_takes_about_the_pure_exponential_time(genova7, pose_goal_run):
    # With e(t) = e0 exp(-K t) per component, the slower of the two reaches 1e-6 at
    # ln(e0 / 1e-6) / K (the discrete step decays by (1 - K dt) per step).
    orientation, position = pose_error(frame_pose(genova7, genova7.initial_positions), GENOVA7_GOAL)
    slowest = max(np.linalg.norm(orientation), np.linalg.norm(position))
    per_step = math.log(1 - 0.8 * 0.001)
    pure = math.ceil(math.log(1e-6 / slowest) / per_step) * 0.001
    assert pose_goal_run.time_to_converge == pytest.approx(pure, abs=0.05)


def test_genova7_pose_goal_hits_the_prismatic_limit_without_exceeding_any(genova7, pose_goal_run):
    result = pose_goal_run
    prismatic = 5
    assert genova7.joints[prismatic].type.value == "prismatic"
    assert result.limited[:, prismatic].any()  # the limit handling was needed
    assert result.q[:, prismatic].min() == 0.0  # it sits exactly on its lower limit
    # The commanded rates never asked for more than the limits allow; no clamp was needed.
    assert result.max_limit_violation <= 1e-12
    assert np.all(result.q >= genova7.lower) and np.all(result.q <= genova7.upper)
    assert result.max_velocity_ratio <= 1.0 + 1e-12


def test_clamping_the_position_alone_stalls_millimetres_short(genova7, pose_goal_run):
    config = ControllerConfig(respect_position_limits=False)
    result = simulate(
        genova7, genova7.initial_positions, GENOVA7_GOAL, config, dt=0.001, duration=18.0, record_every=100
    )
    assert not result.converged
    assert result.time_to_converge is None
    assert 1e-3 < result.final_position_error < 0.05  # millimetres short of the goal
    assert result.max_limit_violation > 0.0  # the clamp was doing the work
    assert "joint6" in result.reason and "limit" in result.reason
    # Same start, same gains: only the limit handling differs.
    assert pose_goal_run.final_position_error < 1e-3 * result.final_position_error


def _log_slope(times, values) -> float:
    return float(np.polyfit(times, np.log(values), 1)[0])


def test_error_decays_at_the_rate_the_gains_set(genova7):
    start = np.array(genova7.initial_positions)
    current = frame_pose(genova7, start)
    goal = make_transform(rodrigues([1, -2, 0.5], 0.2) @ current[:3, :3], current[:3, 3] + [0.03, -0.02, 0.04])
    config = ControllerConfig(gain_angular=1.5, gain_linear=0.6)
    result = simulate(genova7, start, goal, config, dt=0.001, duration=6.0, tolerance=1e-12, record_every=50)
    assert not result.limited.any() and np.all(result.velocity_scale == 1.0) and np.all(result.damping == 0.0)
    window = (result.time > 0.5) & (result.time < 5.0)
    orientation = np.linalg.norm(result.orientation_error, axis=1)[window]
    position = np.linalg.norm(result.position_error, axis=1)[window]
    # Discrete Euler steps decay by (1 - K dt) per step: slope ln(1 - K dt) / dt.
    for norms, gain in ((orientation, 1.5), (position, 0.6)):
        expected = math.log(1 - gain * 0.001) / 0.001
        assert _log_slope(result.time[window], norms) == pytest.approx(expected, rel=2e-3)


def _line_goal(start_pose, velocity):
    def goal_pose(t):
        return make_transform(start_pose[:3, :3], start_pose[:3, 3] + velocity * t)

    def goal_twist(t):
        return np.zeros(3), velocity

    return goal_pose, goal_twist


def test_feed_forward_tracks_a_moving_goal_to_discretisation_level(genova7):
    start = np.array(genova7.initial_positions)
    start_pose = frame_pose(genova7, start)
    velocity = np.array([0.02, 0.03, -0.01])  # [m/s]
    goal_pose, goal_twist = _line_goal(start_pose, velocity)
    errors = {}
    for dt in (0.002, 0.001):
        result = simulate(
            genova7,
            start,
            goal_pose(0.0),
            dt=dt,
            duration=3.0,
            goal_pose_fn=goal_pose,
            goal_twist_fn=goal_twist,
            record_every=10,
        )
        errors[dt] = (result.final_position_error, result.final_orientation_error)
    without = simulate(genova7, start, goal_pose(0.0), dt=0.001, duration=3.0, goal_pose_fn=goal_pose, record_every=10)
    # Without feed-forward the goal is followed with the lag v / K of a first-order loop.
    lag = np.linalg.norm(velocity) / 0.8
    assert without.final_position_error == pytest.approx(lag * (1 - math.exp(-0.8 * 3.0)), rel=0.05)
    # With it the error is set by the integration step alone (the arm's curvature over one
    # Euler step): tiny, and halving with dt.
    assert errors[0.001][0] < 1e-4 * lag and errors[0.001][1] < 1e-5
    for component in (0, 1):
        assert errors[0.001][component] == pytest.approx(errors[0.002][component] / 2, rel=0.15)


def test_moving_goal_convergence_time(genova7):
    start = np.array(genova7.initial_positions)
    goal_pose, goal_twist = _line_goal(frame_pose(genova7, start), np.array([0.0, 0.01, 0.0]))
    result = simulate(
        genova7,
        start,
        goal_pose(0.0),
        dt=0.001,
        duration=1.0,
        tolerance=1e-5,
        goal_pose_fn=goal_pose,
        goal_twist_fn=goal_twist,
    )
    assert result.converged and result.time_to_converge == 0.0  # starts on the goal and stays there
    assert result.steps == 1000


def test_stretched_scara_leaves_the_singularity_and_converges():
    model = load_robot("scara")
    goal = make_transform(rodrigues([0, 0, 1], math.pi / 4), [0.7, 0.7, 0.2])
    result = simulate(model, np.zeros(4), goal, dt=0.001, duration=30.0, record_every=20)
    assert result.task == "position_yaw"
    assert result.converged, result.reason
    assert result.damping[0] > 0.0  # it starts singular
    assert result.max_velocity_ratio <= 1.0 + 1e-12 and np.all(np.isfinite(result.qdot))
    pose = frame_pose(model, result.q_final)
    np.testing.assert_allclose(pose[:3, 3], [0.7, 0.7, 0.2], atol=1e-6)
    assert math.atan2(pose[1, 0], pose[0, 0]) == pytest.approx(math.pi / 4, abs=1e-6)


def test_irb120_from_the_wrist_singularity_rates_stay_bounded_and_it_converges():
    model = load_robot("irb120")
    q0 = np.array([0.0, 0.3, -0.2, 0.0, 0.0, 0.0])
    current = frame_pose(model, q0)
    goal = make_transform(rodrigues([0, 0, 1], 0.6) @ current[:3, :3], current[:3, 3] + [-0.05, 0.05, 0.0])
    result = simulate(model, q0, goal, dt=0.001, duration=30.0, record_every=20)
    assert result.damping[0] > 0.0
    assert result.max_velocity_ratio <= 1.0 + 1e-12 and np.all(np.isfinite(result.qdot))
    assert result.converged, result.reason


def test_irb120_out_of_reach_goal_stays_bounded_and_says_why():
    model = load_robot("irb120")
    goal = make_transform(np.eye(3), [2.0, 0.0, 0.5])
    result = simulate(model, np.zeros(6), goal, dt=0.001, duration=4.0, record_every=10)
    assert not result.converged and result.time_to_converge is None
    assert "out of reach" in result.reason
    assert np.all(np.isfinite(result.qdot)) and result.max_velocity_ratio <= 1.0 + 1e-12
    assert result.max_limit_violation <= 1e-12


def test_out_of_reach_position_ends_at_the_closest_reachable_point():
    model = load_robot("irb120")
    target = np.array([2.0, 0.3, 0.5])
    config = ControllerConfig(task="position")
    result = simulate(
        model, np.zeros(6), make_transform(np.eye(3), target), config, dt=0.001, duration=6.0, record_every=50
    )
    assert not result.converged and "out of reach" in result.reason
    # No configuration gets closer than where the arm stopped (dense random sampling).
    rng = np.random.default_rng(11)
    from manip_kin.core.kinematics import batch_frame_pose

    samples = batch_frame_pose(model, np.array([model.random_configuration(rng) for _ in range(20000)]))
    closest_sampled = np.min(np.linalg.norm(samples[:, :3, 3] - target, axis=1))
    assert result.final_position_error <= closest_sampled + 1e-4
    assert result.final_position_error > 1.0


def test_recording_shapes_and_twists(genova7):
    start = np.array(genova7.initial_positions)
    current = frame_pose(genova7, start)
    goal = make_transform(current[:3, :3], current[:3, 3] + [0.05, 0, 0])
    result = simulate(genova7, start, goal, dt=0.001, duration=0.5, tolerance=1e-9, record_every=5)
    count = len(result.time)
    assert count == 101  # every 5th of 500 steps, plus the final state
    assert (
        result.q.shape == (count, 7) and result.frame_pose.shape == (count, 4, 4) and result.twist.shape == (count, 6)
    )
    np.testing.assert_allclose(result.time[1] - result.time[0], 0.005)
    np.testing.assert_allclose(result.frame_pose[0], current, atol=1e-12)
    # Recorded linear velocity = central difference of the recorded positions (samples 5 ms apart).
    positions = result.frame_pose[:, :3, 3]
    velocity = (positions[2:] - positions[:-2]) / 0.010
    # Each Euler step moves the frame by J q̇ dt plus a second-order term O(|q̇|² dt²).
    np.testing.assert_allclose(velocity[10:20], result.twist[11:21, 3:], atol=2e-5)
    assert np.abs(result.twist[11:21, 3]).min() > 0.01  # a meaningful velocity to compare
    np.testing.assert_allclose(result.tool_pose, result.frame_pose)


def test_simulation_rejects_bad_input(genova7):
    start = genova7.initial_positions
    with pytest.raises(InvalidArgumentError, match="dt"):
        simulate(genova7, start, GENOVA7_GOAL, dt=-1.0)
    with pytest.raises(InvalidArgumentError, match="duration"):
        simulate(genova7, start, GENOVA7_GOAL, duration=0.0)
    with pytest.raises(InvalidArgumentError, match="q0 is outside"):
        simulate(genova7, np.array([0, 0, 0, 0, 0, 0.5, 0]), GENOVA7_GOAL)
    skewed = GENOVA7_GOAL.copy()
    skewed[:3, :3] *= 1.1
    with pytest.raises(ManipKinError, match="rotation"):
        simulate(genova7, start, skewed)
    with pytest.raises(InvalidArgumentError, match="record_every"):
        simulate(genova7, start, GENOVA7_GOAL, record_every=0)
