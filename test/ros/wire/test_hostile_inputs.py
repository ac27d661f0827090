"""Property-based tests: every message handler and planner/control entry point under hostile input.

Inputs are drawn by hypothesis (derandomized: a failure reproduces) from arbitrary floats
with the awkward ones weighted in: ±inf, NaN, ±1e308, 1e300, subnormals, -0.0; wrong
lengths; empty, unknown and duplicated joint names. What must hold:

* a handler either accepts a message or rejects it with :class:`InvalidMessageError` (a
  one-line reason), nothing else escapes;
* what it accepts is finite and bounded, and what is computed from it downstream (control
  step, line plan, integration) is finite, with joint positions inside the limits and
  joint rates inside the velocity limits;
* an entry point of the core either returns such values or raises a ``ManipKinError``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.control.resolved_rate import CartesianController
from manip_kin.control.state_prediction import MAX_STATE_AGE_PERIODS, PLAUSIBLE_RATE_FACTOR, state_for_command
from manip_kin.core.bounds import InputBounds
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.errors import ManipKinError
from manip_kin.ik.iterative import solve_ik
from manip_kin.motion.lines import TIME_SCALINGS, LineTrajectory, MotionLimits, make_time_scaling
from manip_kin.plant import KinematicPlant
from manip_kin.ros.wire.cdr import JointStateDecoder, decode_float64_array
from manip_kin.ros.wire.messages import make_joint_state, pose_stamped_to_matrix, pose_to_matrix, twist_to_arrays
from manip_kin.ros.wire.validation import (
    InvalidMessageError,
    JointStateMapper,
    command_problem,
    pose_problem,
    twist_problem,
)

# Hostile input gets an error, not numpy's overflow warnings on the user's terminal first.
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

MODEL = load_robot("genova7")  # 7 joints, one prismatic: both joint kinds
BOUNDS = InputBounds.of(MODEL)
Q0 = MODEL.start_configuration()
TOOL0 = frame_pose(MODEL, Q0)
CONTROLLER = CartesianController(MODEL)
NAMES = MODEL.joint_names

AWKWARD = [
    math.inf,
    -math.inf,
    math.nan,
    1e308,
    -1e308,
    1e300,
    -1e300,
    1e-308,
    5e-324,
    -5e-324,
    0.0,
    -0.0,
    1.0,
    -1.0,
]
hostile = st.one_of(st.sampled_from(AWKWARD), st.floats(allow_nan=True, allow_infinity=True))
plausible = st.floats(min_value=-3.0, max_value=3.0)
number = st.one_of(hostile, plausible)

SETTINGS = settings(
    derandomize=True,
    max_examples=300,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)


def _finite(*arrays) -> bool:
    return all(np.all(np.isfinite(np.asarray(a, dtype=float))) for a in arrays)


def _assert_control_output_ok(output) -> None:
    assert _finite(output.qdot, output.position_error_norm, output.orientation_error_norm)
    assert np.all(np.abs(output.qdot) <= MODEL.velocity_limits * (1 + 1e-9))


def _pose_msg(values, frame="base_link") -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = (float(v) for v in values)
    return msg


unit_quaternion = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: sum(v * v for v in q) > 1e-6)


@st.composite
def pose_values(draw):
    """Seven pose numbers: mostly hostile, sometimes a plausible pose (so acceptance is exercised)."""
    if draw(st.booleans()):
        return draw(st.lists(number, min_size=7, max_size=7))
    position = draw(st.lists(st.one_of(plausible, hostile), min_size=3, max_size=3))
    quaternion = np.array(draw(unit_quaternion))
    quaternion /= np.linalg.norm(quaternion)
    return position + quaternion.tolist()


# --- message handlers ---------------------------------------------------------------------------


@SETTINGS
@given(pose_values(), st.sampled_from(["base_link", "base_link", "map", ""]))
def test_goal_pose_handler(values, frame):
    msg = _pose_msg(values, frame)
    problem = pose_problem(msg, "base_link", "goal pose", max_distance=BOUNDS.max_target_distance)
    if problem is not None:
        assert isinstance(problem, str) and "valid" in problem and "\n" not in problem
        return
    goal = pose_stamped_to_matrix(msg)
    assert _finite(goal) and np.linalg.norm(goal[:3, 3]) <= BOUNDS.max_target_distance
    np.testing.assert_allclose(goal[:3, :3] @ goal[:3, :3].T, np.eye(3), atol=1e-9)
    # Downstream: one control step and a line plan from the current tool pose.
    _assert_control_output_ok(CONTROLLER.step(Q0, goal, None, 0.002))
    for kind in TIME_SCALINGS:
        line = LineTrajectory.plan(TOOL0, goal, kind, MotionLimits())
        assert math.isfinite(line.duration) and line.duration >= 0
        for t in (0.0, line.duration * 0.37, line.duration, 1e308):
            pose, (angular, linear) = line.sample(t)
            assert _finite(pose, angular, linear)


@SETTINGS
@given(st.lists(number, min_size=6, max_size=6), st.sampled_from(["base_link", "tool0"]))
def test_goal_twist_handler(values, frame):
    msg = TwistStamped()
    msg.header.frame_id = frame
    a, v = msg.twist.angular, msg.twist.linear
    a.x, a.y, a.z, v.x, v.y, v.z = (float(x) for x in values)
    problem = twist_problem(msg, "base_link", "goal twist", BOUNDS.max_twist_linear, BOUNDS.max_twist_angular)
    if problem is not None:
        assert "valid" in problem
        return
    angular, linear = twist_to_arrays(msg.twist)
    assert np.linalg.norm(linear) <= BOUNDS.max_twist_linear and np.linalg.norm(angular) <= BOUNDS.max_twist_angular
    goal = TOOL0.copy()
    goal[2, 3] += 0.05
    _assert_control_output_ok(CONTROLLER.step(Q0, goal, (angular, linear), 0.002))


joint_names = st.lists(st.sampled_from([*NAMES, "extra_joint", ""]), max_size=10)


@SETTINGS
@given(joint_names, st.lists(st.one_of(number, st.floats(-4, 4)), max_size=10), st.booleans())
def test_joint_state_handlers(names, positions, model_order):
    if model_order:  # the common case: every joint, model order, only the values hostile
        names = list(NAMES)
        positions = (positions + Q0.tolist())[: len(NAMES)]
    msg = JointState()
    msg.name = names
    msg.position = [float(v) for v in positions]
    mapper = JointStateMapper(NAMES, BOUNDS.position_lower, BOUNDS.position_upper)
    decoder = JointStateDecoder(NAMES, BOUNDS.position_lower, BOUNDS.position_upper)
    # A decoder that has learned the model-order layout reads such messages on its fast path.
    learned = JointStateDecoder(NAMES, BOUNDS.position_lower, BOUNDS.position_upper)
    learned.positions(serialize_message(make_joint_state(NAMES, Q0)))
    data = serialize_message(msg)
    results = []
    reads = (mapper.positions, decoder.positions, decoder.positions, learned.positions)
    for read, argument in zip(reads, (msg, data, data, data)):
        try:
            results.append(read(argument))
        except InvalidMessageError as error:
            results.append(str(error))
    # The message path and the byte paths (first read, then learned fast paths) agree.
    assert all(type(r) is type(results[0]) for r in results)
    if isinstance(results[0], str):
        assert "valid" in results[0]
        assert len(set(results)) == 1
        return
    for q in results[1:]:
        np.testing.assert_array_equal(q, results[0])
    q = results[0]
    assert q.shape == (len(NAMES),) and _finite(q)
    assert np.all(q >= BOUNDS.position_lower) and np.all(q <= BOUNDS.position_upper)
    _assert_control_output_ok(CONTROLLER.step(q, TOOL0, None, 0.002))


@SETTINGS
@given(
    st.lists(st.one_of(number, st.floats(-10, 10)), max_size=9),
    st.floats(min_value=0.0, max_value=0.006),
    st.integers(0, 3),
)
def test_command_handler_and_integrator(values, dt, steps):
    data = serialize_message(Float64MultiArray(data=[float(v) for v in values]))
    command = decode_float64_array(data)
    np.testing.assert_array_equal(command, np.array(values, dtype=float))
    problem = command_problem(command, MODEL.dof, max_abs=BOUNDS.max_command)
    if problem is not None:
        assert "valid" in problem
        return
    integrator = KinematicPlant(MODEL, Q0)
    for _ in range(steps + 1):
        integrator.step(command, dt)
        assert MODEL.within_limits(integrator.q)
        assert np.all(np.abs(integrator.qdot) <= MODEL.velocity_limits * (1 + 1e-9))
        assert _finite(integrator.tool, integrator.ee, *integrator.tool_twist, *integrator.ee_twist)


@SETTINGS
@given(st.binary(max_size=64), st.integers(0, 200))
def test_truncated_or_corrupted_bytes_are_rejected_not_raised(noise, cut):
    valid = serialize_message(make_joint_state(NAMES, Q0))
    decoder = JointStateDecoder(NAMES)
    decoder.positions(valid)  # learn the fast path
    for data in (valid[:cut], valid[:cut] + noise, valid[:12] + noise):
        try:
            q = decoder.positions(data)
        except InvalidMessageError:
            continue
        assert q.shape == (len(NAMES),) and _finite(q)
    command = serialize_message(Float64MultiArray(data=[0.1] * 7))
    for data in (command[:cut], command[:cut] + noise):
        try:
            values = decode_float64_array(data)
        except InvalidMessageError:
            continue
        assert values.ndim == 1


# --- planner and control entry points -----------------------------------------------------------


@SETTINGS
@given(st.sampled_from(TIME_SCALINGS), number, number, st.lists(st.floats(1e-6, 1e6), min_size=4, max_size=4))
def test_time_scaling(kind, length, angle, limit_values):
    limits = MotionLimits(*limit_values)
    try:
        scaling = make_time_scaling(kind, length, angle, limits)
    except ManipKinError as error:
        assert "valid" in str(error)
        return
    assert math.isfinite(scaling.duration) and scaling.duration >= 0
    for t in (0.0, scaling.duration / 3, scaling.duration / 2, scaling.duration, 1e308, 5e-324):
        assert _finite(scaling.evaluate(t))
        s = scaling.evaluate(t)[0]
        assert -1e-12 <= s <= 1 + 1e-12


@SETTINGS
@given(st.lists(number, min_size=7, max_size=7), st.lists(number, min_size=16, max_size=16))
def test_line_plan(pose, raw_matrix):
    goals = [np.array(raw_matrix).reshape(4, 4)]
    try:
        goals.append(pose_to_matrix(_pose_msg(pose).pose))
    except InvalidMessageError:
        pass
    for goal in goals:
        try:
            line = LineTrajectory.plan(TOOL0, goal)
        except ManipKinError:
            continue
        assert math.isfinite(line.duration)
        assert _finite(line.sample(line.duration / 2)[0], *line.sample(line.duration / 2)[1])


@SETTINGS
@given(
    st.lists(number, min_size=7, max_size=7), number, st.floats(0.0, 1.0), st.lists(plausible, min_size=7, max_size=7)
)
def test_state_prediction_from_hostile_velocities_and_stamps(velocities, age, latency, q_offsets):
    """A joint state's velocities and stamp only move the state the law sees within the limits,
    by at most a plausible rate over the largest horizon; the law's output stays bounded."""
    q = np.clip(Q0 + 0.1 * np.array(q_offsets), MODEL.lower, MODEL.upper)
    qdot = np.array(velocities)
    period = 0.002
    plausible_rates = PLAUSIBLE_RATE_FACTOR * MODEL.velocity_limits
    predicted = state_for_command(q, qdot, age, period, latency, MODEL.lower, MODEL.upper, plausible_rates)
    assert predicted.shape == q.shape and _finite(predicted)
    assert np.all(predicted >= MODEL.lower) and np.all(predicted <= MODEL.upper)
    # The longest horizon: the oldest accepted state plus the command latency, then half a period.
    horizon = (MAX_STATE_AGE_PERIODS + 1) * period + latency + period
    assert np.all(np.abs(predicted - q) <= plausible_rates * horizon + 1e-12)
    _assert_control_output_ok(CONTROLLER.step(predicted, TOOL0, None, period))


@SETTINGS
@given(st.lists(number, min_size=7, max_size=7), st.lists(number, min_size=7, max_size=7), number)
def test_control_step(q_values, pose, dt):
    q = np.array(q_values)
    try:
        goal = pose_to_matrix(_pose_msg(pose).pose)
    except InvalidMessageError:
        goal = TOOL0
    try:
        output = CONTROLLER.step(q, goal, None, dt)
    except ManipKinError:
        return
    _assert_control_output_ok(output)


@settings(derandomize=True, max_examples=40, deadline=None)
@given(st.lists(number, min_size=7, max_size=7), st.lists(number, min_size=7, max_size=7))
def test_ik_entry_point(pose, q_values):
    try:
        target = pose_to_matrix(_pose_msg(pose).pose)
    except InvalidMessageError:
        target = np.array(pose[:4] * 4).reshape(4, 4)
    try:
        result = solve_ik(MODEL, target, np.array(q_values), restarts=2, time_budget=0.05, seed=0)
    except ManipKinError:
        return
    assert _finite(result.q) and MODEL.within_limits(result.q)


@pytest.mark.parametrize("bad", [[], [0.1] * 6, [0.1] * 8])
def test_wrong_lengths_named_in_the_reason(bad):
    problem = command_problem(np.array(bad), MODEL.dof)
    assert f"has {len(bad)} values; valid: 7" in problem


# --- joint-space inputs (joint_reference, joint_trajectory) --------------------------------------


@SETTINGS
@given(
    joint_names,
    st.lists(st.one_of(number, st.floats(-4, 4)), max_size=10),
    st.lists(st.one_of(number, st.floats(-4, 4)), max_size=10),
    st.booleans(),
)
def test_joint_reference_handler_and_tracking_law(names, positions, velocities, model_order):
    from manip_kin.control.joint_tracking import joint_tracking_step
    from manip_kin.ros.wire.joint_messages import JointReferenceReader

    if model_order:
        names = list(NAMES)
        positions = (positions + Q0.tolist())[: len(NAMES)]
        velocities = (velocities + [0.0] * len(NAMES))[: len(NAMES)]
    msg = JointState()
    msg.name = names
    msg.position = [float(v) for v in positions]
    msg.velocity = [float(v) for v in velocities]
    try:
        q_reference, qdot_reference = JointReferenceReader(MODEL).read(msg)
    except InvalidMessageError as error:
        assert "valid" in str(error) or "outside its limits" in str(error)
        return
    assert len(set(names)) == len(names)  # repeated names are rejected
    assert _finite(q_reference, qdot_reference) and MODEL.within_limits(q_reference)
    output = joint_tracking_step(MODEL, Q0, q_reference, qdot_reference, 20.0, 0.002)
    assert _finite(output.qdot) and np.all(np.abs(output.qdot) <= MODEL.velocity_limits * (1 + 1e-9))
    assert MODEL.within_limits(Q0 + output.qdot * 0.002, tolerance=1e-9)


@SETTINGS
@given(
    st.lists(
        st.tuples(
            st.one_of(number, st.floats(0.01, 20)),
            st.lists(st.one_of(number, st.floats(-2, 2)), min_size=7, max_size=7),
        ),
        min_size=0,
        max_size=3,
    ),
    st.sampled_from(["cubic", "quintic", "trapezoidal"]),
    st.lists(number, min_size=4, max_size=4),
)
def test_joint_trajectory_planner(points, scaling, times):
    from manip_kin.motion.joint_trajectory import TrajectoryPoint, plan_joint_trajectory

    trajectory = [TrajectoryPoint(float(t), [float(v) for v in q], []) for t, q in points]
    try:
        plan = plan_joint_trajectory(MODEL, Q0, NAMES, trajectory, scaling)
    except ManipKinError as error:
        assert str(error)
        return
    assert math.isfinite(plan.duration) and plan.duration > 0
    for t in [0.0, plan.duration, *[abs(x) for x in times if math.isfinite(x)]]:
        q, qdot = plan.sample(min(t, 1e308))
        assert _finite(q, qdot) and MODEL.within_limits(q, tolerance=1e-6)
