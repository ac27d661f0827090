"""The kind every rejection carries (manip_kin.errors.ProblemKind), asserted against the check
that should have refused the input, never read back from the reason's words.

Each property draws inputs that break the checks in any combination and predicts the kind
from the order the check applies them in (its docstring); names and frames are arbitrary text,
so a reason quoting ``NaN`` or ``frame_id`` cannot steer the kind.
"""

from __future__ import annotations

import copy
import math
import pickle
from types import SimpleNamespace

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import JointState

from manip_kin.control.servo import SingularityScaling, resolve_frame
from manip_kin.core.bounds import InputBounds
from manip_kin.core.robots import load_robot
from manip_kin.errors import (
    InputError,
    InvalidArgumentError,
    NonFiniteError,
    Problem,
    ProblemKind,
    UnknownFrameError,
)
from manip_kin.motion.joint_trajectory import TrajectoryPoint, plan_joint_trajectory
from manip_kin.ros.nodes.servo_inputs import ServoInputs
from manip_kin.ros.wire.cdr import decode_float64_array, decode_pose_stamped
from manip_kin.ros.wire.joint_messages import JointReferenceReader
from manip_kin.ros.wire.messages import check_pose_stamped, quaternion_to_matrix
from manip_kin.ros.wire.validation import (
    InvalidMessageError,
    JointStateMapper,
    check_command,
    command_problem,
    frame_problem,
    pose_problem,
    twist_problem,
)

K = ProblemKind
MODEL = load_robot("irb120")
BOUNDS = InputBounds.of(MODEL)
SETTINGS = settings(max_examples=200)

#: Numbers that break a check: non-finite, huge, subnormal; and plain ones.
number = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324, 0.0]),
    st.floats(-3.0, 3.0),
)
#: Text that quotes the words the old substring matching looked for.
hostile_text = st.one_of(st.text(max_size=12), st.sampled_from(["NaN", "frame_id", "out of range", "too fast"]))


def _kind(problem) -> ProblemKind | None:
    """The kind of a ``*_problem`` result (None for accepted), checking it is a Problem."""
    if problem is None:
        return None
    assert isinstance(problem, Problem) and isinstance(problem.kind, ProblemKind), repr(problem)
    return problem.kind


# --- the Problem and the errors ---------------------------------------------------------------


def test_problem_is_its_text_and_keeps_its_kind_through_copy_and_pickle():
    problem = Problem(K.RANGE, "joint a is 9, out of range")
    assert problem == "joint a is 9, out of range" and f"x: {problem}" == "x: joint a is 9, out of range"
    assert problem[:7] == "joint a" and type(problem[:7]) is str
    for again in (copy.copy(problem), pickle.loads(pickle.dumps(problem))):
        assert again == problem and again.kind is K.RANGE
    assert "goal:" + problem.kind == "goal:range"
    assert repr(problem) == "Problem(RANGE, 'joint a is 9, out of range')"


def test_errors_carry_the_kind_they_are_given_or_their_problems():
    assert InvalidArgumentError("x", kind=K.LENGTH).kind is K.LENGTH
    assert InvalidMessageError(Problem(K.FRAME, "f")).kind is K.FRAME
    assert InvalidMessageError(Problem(K.FRAME, "f"), kind=K.SPEED).kind is K.SPEED  # said outright wins
    assert InputError("contains NaN").kind is K.OTHER  # the words do not count
    assert NonFiniteError("q").kind is K.NON_FINITE
    assert Problem.of(InvalidArgumentError("x", kind=K.REACH)).kind is K.REACH
    assert Problem.of(RuntimeError("contains NaN")).kind is K.OTHER
    assert Problem.of("quaternion has length 2").kind is K.OTHER
    assert Problem.of(SimpleNamespace(kind="unreachable")).kind is K.OTHER  # a kind of something else


# --- poses and twists ---------------------------------------------------------------------------


def _pose(frame: str, values) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = (float(v) for v in values)
    return msg


def _pose_kind(frame: str, values, max_distance: float) -> ProblemKind | None:
    if frame != "base_link":
        return K.FRAME
    if not all(math.isfinite(v) for v in values):
        return K.NON_FINITE
    if math.hypot(*values[:3]) > max_distance:
        return K.REACH
    if not abs(math.hypot(*values[3:]) - 1.0) <= 1e-2:
        return K.QUATERNION
    return None


@SETTINGS
@given(st.one_of(st.just("base_link"), hostile_text), st.lists(number, min_size=7, max_size=7))
def test_pose_problem_kind_is_the_first_check_that_fails(frame, values):
    limit = BOUNDS.max_target_distance
    msg = _pose(frame, values)
    assert _kind(pose_problem(msg, "base_link", "goal pose", max_distance=limit)) == _pose_kind(frame, values, limit)
    expected = _pose_kind(frame, values, math.inf)  # check_pose_stamped has no reach bound
    if expected is not None:
        with pytest.raises(InvalidMessageError) as raised:
            check_pose_stamped(msg, "base_link")
        assert raised.value.kind is expected


@SETTINGS
@given(st.one_of(st.just("base_link"), hostile_text), st.lists(number, min_size=6, max_size=6))
def test_twist_problem_kind_is_the_first_check_that_fails(frame, values):
    msg = TwistStamped()
    msg.header.frame_id = frame
    a, v = msg.twist.angular, msg.twist.linear
    a.x, a.y, a.z, v.x, v.y, v.z = (float(x) for x in values)
    linear_limit, angular_limit = BOUNDS.max_twist_linear, BOUNDS.max_twist_angular
    if frame != "base_link":
        expected = K.FRAME
    elif not all(math.isfinite(x) for x in values):
        expected = K.NON_FINITE
    elif math.hypot(*values[3:]) > linear_limit or math.hypot(*values[:3]) > angular_limit:
        expected = K.SPEED
    else:
        expected = None
    assert _kind(twist_problem(msg, "base_link", "goal twist", linear_limit, angular_limit)) == expected


@given(hostile_text)
def test_frame_problem_is_a_frame_problem_whatever_the_name(frame):
    assert _kind(frame_problem(frame, "base_link", "marker")) == (None if frame == "base_link" else K.FRAME)


@given(st.lists(number, min_size=4, max_size=4))
def test_quaternion_to_matrix_refuses_a_zero_or_non_finite_quaternion_as_quaternion(values):
    norm = math.sqrt(sum(v * v for v in values))
    if math.isfinite(norm) and norm >= 1e-12:
        quaternion_to_matrix(*values)
        return
    with pytest.raises(InvalidMessageError) as raised:
        quaternion_to_matrix(*values)
    assert raised.value.kind is K.QUATERNION


def test_undecodable_bytes_are_other():
    for decode in (lambda data: decode_pose_stamped(data, "goal pose"), decode_float64_array):
        with pytest.raises(InvalidMessageError) as raised:
            decode(b"\x00\x01\x00\x00\xff\xff\xff\xff")
        assert raised.value.kind is K.OTHER


# --- joint commands, states and references --------------------------------------------------------


@SETTINGS
@given(st.lists(number, min_size=5, max_size=7))
def test_command_problem_kind(values):
    values = np.array(values)
    max_abs = 100.0 * MODEL.velocity_limits
    if values.shape[0] != MODEL.dof:
        expected = K.LENGTH
    elif not np.isfinite(values).all():
        expected = K.NON_FINITE
    elif (np.abs(values) > max_abs).any():
        expected = K.SPEED
    else:
        expected = None
    assert _kind(command_problem(values, MODEL.dof, max_abs=max_abs)) == expected
    if values.shape[0] != MODEL.dof or not np.isfinite(values).all():
        with pytest.raises(InvalidMessageError) as raised:
            check_command(SimpleNamespace(data=values.tolist()), MODEL.dof)
        assert raised.value.kind == expected


def _names_sent(data, model_names) -> list[str]:
    """Names a message might carry: mostly every model joint once, shuffled; else any mix of
    them and an extra name, some missing or repeated."""
    if data.draw(st.booleans(), "complete"):
        return data.draw(st.permutations([*model_names, *data.draw(st.sampled_from([[], ["extra"]]))]), "names")
    return data.draw(st.lists(st.sampled_from([*model_names, "extra"]), max_size=len(model_names) + 2), "names")


def _values_for(data, names, what: str) -> list[float]:
    """Mostly one value a name; sometimes one too few or too many."""
    count = len(names) + data.draw(st.sampled_from([0, 0, 0, -1, 1]), f"{what} count")
    return data.draw(st.lists(number, min_size=max(0, count), max_size=max(0, count)), what)


def _assert_read_as(read, msg, expected: ProblemKind | None) -> None:
    """``read(msg)`` accepts ``msg`` (``expected`` None) or refuses it as ``expected``."""
    if expected is None:
        read(msg)
        return
    with pytest.raises(InvalidMessageError) as raised:
        read(msg)
    assert raised.value.kind is expected, str(raised.value)


def _joint_state(names, positions) -> JointState:
    msg = JointState()
    msg.name = list(names)
    msg.position = [float(p) for p in positions]
    return msg


def _expected_state_kind(model_names, names, positions, lower, upper) -> ProblemKind | None:
    if any(names.count(n) > 1 for n in model_names) or any(n not in names for n in model_names):
        return K.LENGTH
    if len(positions) != len(names):
        return K.LENGTH
    ordered = np.array([positions[names.index(n)] for n in model_names])
    if not np.isfinite(ordered).all():
        return K.NON_FINITE
    if ((ordered < lower) | (ordered > upper)).any():
        return K.RANGE
    return None


@SETTINGS
@given(st.data())
def test_joint_state_mapper_kind(data):
    # Arbitrary joint names (as a URDF may have them: "NaN", "frame_id" ...), sent in any order,
    # some missing or repeated, with positions of any count and value.
    model_names = data.draw(st.lists(hostile_text, min_size=1, max_size=4, unique=True), "model names")
    names = _names_sent(data, model_names)
    positions = _values_for(data, names, "positions")
    lower, upper = -np.ones(len(model_names)), np.ones(len(model_names))
    expected = _expected_state_kind(model_names, names, positions, lower, upper)
    _assert_read_as(JointStateMapper(model_names, lower, upper).positions, _joint_state(names, positions), expected)


@SETTINGS
@given(st.data())
def test_joint_reference_reader_kind(data):
    model_names = MODEL.joint_names
    names = _names_sent(data, model_names)
    positions = _values_for(data, names, "positions")
    velocities = [] if data.draw(st.booleans(), "no velocities") else _values_for(data, names, "velocities")
    msg = _joint_state(names, positions)
    msg.velocity = [float(v) for v in velocities]
    if any(names.count(n) > 1 for n in names) or any(n not in names for n in model_names):
        expected = K.LENGTH
    elif len(positions) != len(names) or len(velocities) not in (0, len(names)):
        expected = K.LENGTH
    else:
        q = np.array([positions[names.index(n)] for n in model_names])
        qdot = np.array([velocities[names.index(n)] for n in model_names]) if velocities else np.zeros(6)
        if not (np.isfinite(q).all() and np.isfinite(qdot).all()):
            expected = K.NON_FINITE
        elif ((q < MODEL.lower - 1e-9) | (q > MODEL.upper + 1e-9)).any():
            expected = K.RANGE
        else:
            expected = None
    _assert_read_as(JointReferenceReader(MODEL).read, msg, expected)


# --- jog and twist commands (servo) -----------------------------------------------------------------


def _servo() -> ServoInputs:
    servo = ServoInputs.__new__(ServoInputs)  # the checks only: no node, no subscriptions
    servo.node = SimpleNamespace(inputs=SimpleNamespace(bounds=BOUNDS), base_frame=MODEL.base_frame)
    servo.configure(MODEL, SingularityScaling())
    return servo


@SETTINGS
@given(st.lists(st.sampled_from([*MODEL.joint_names, "NaN", "frame_id"]), max_size=4), st.lists(number, max_size=4))
def test_jog_problem_kind(names, velocities):
    limits = dict(zip(MODEL.joint_names, MODEL.velocity_limits))
    expected = None
    if not names or len(names) != len(velocities):
        expected = K.LENGTH
    else:
        for name, value in zip(names, velocities):
            if name not in limits:
                expected = K.OTHER
            elif not math.isfinite(value):
                expected = K.NON_FINITE
            elif abs(value) > limits[name] * 1.0000001:
                expected = K.SPEED
            if expected is not None:
                break
    msg = JointState()
    msg.name, msg.velocity = list(names), [float(v) for v in velocities]
    assert _kind(_servo()._jog_problem(msg)) == expected


@given(hostile_text)
def test_twist_command_in_an_unknown_frame_is_a_frame_problem(frame):
    msg = TwistStamped()
    msg.header.frame_id = frame
    try:
        resolve_frame(MODEL, frame or MODEL.base_frame)
        expected = None
    except UnknownFrameError:
        expected = K.FRAME
    assert _kind(_servo()._twist_problem(msg)) == expected


# --- joint trajectories (the generator's targets) ---------------------------------------------------


def _plan(names, *points: TrajectoryPoint):
    return plan_joint_trajectory(MODEL, np.zeros(MODEL.dof), names, list(points))


def _planning_kind(names, *points: TrajectoryPoint) -> ProblemKind:
    with pytest.raises(InvalidArgumentError) as raised:
        _plan(names, *points)
    return raised.value.kind


def test_joint_trajectory_refusals_carry_their_kind():
    names = list(MODEL.joint_names)
    at = TrajectoryPoint
    assert _planning_kind([*names, names[0]], at(1.0, [0.0] * 7)) is K.LENGTH
    assert _planning_kind(names[:-1], at(1.0, [0.0] * 5)) is K.LENGTH
    assert _planning_kind([*names, "NaN"], at(1.0, [0.0] * 7)) is K.OTHER  # not a joint of the arm
    assert _planning_kind(names, at(1.0, [0.0] * 5)) is K.LENGTH
    assert _planning_kind(names, at(1.0, [0.0] * 6, [0.0] * 2)) is K.LENGTH
    assert _planning_kind(names, at(1.0, [math.nan] + [0.0] * 5)) is K.NON_FINITE
    assert _planning_kind(names, at(1.0, [100.0] + [0.0] * 5)) is K.RANGE
    assert _planning_kind(names, at(1e-3, [1.0] + [0.0] * 5)) is K.SPEED
    assert _planning_kind(names, at(math.nan, [0.0] * 6)) is K.OTHER  # a time, not a value
    assert _planning_kind(names, at(1.0, [0.0] * 6, [0.1] * 6)) is K.OTHER  # does not end at rest
