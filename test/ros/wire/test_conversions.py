"""Message <-> numpy conversions and the message checks, without spinning."""

import array
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from hypothesis import given
from hypothesis import strategies as st
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.ros.wire.cdr import (
    DecodedPoseStamped,
    Float64ArrayCdr,
    JointStateCdr,
    JointStateDecoder,
    PoseStampedCdr,
    TwistStampedCdr,
    decode_float64_array,
    decode_pose_stamped,
    quaternion_of_pose_values,
)
from manip_kin.ros.wire.diagnostics import (
    DIAGNOSTIC_LEVELS,
    diagnostic_array_cdr,
    diagnostic_values,
    make_diagnostic_array,
    make_diagnostic_status,
)
from manip_kin.ros.wire.messages import (
    array_to_multiarray,
    check_pose_stamped,
    fill_pose_stamped,
    make_joint_state,
    make_pose_stamped,
    make_twist_stamped,
    multiarray_to_array,
    ns_to_stamp,
    pose_stamped_to_matrix,
    pose_to_matrix,
    stamp_key,
    stamp_key_to_ns,
    stamp_to_ns,
    stamp_to_seconds,
    to_double_array,
    twist_to_arrays,
)
from manip_kin.ros.wire.validation import (
    InvalidMessageError,
    JointStateMapper,
    check_command,
    command_problem,
    pose_problem,
    twist_problem,
)


def _pose(rpy=(0.3, -1.2, 2.5), xyz=(0.1, -0.2, 0.3)) -> np.ndarray:
    return make_transform(rpy_to_matrix(*rpy), xyz)


def test_pose_round_trip_and_fill_in_place():
    matrix = _pose()
    msg = make_pose_stamped(matrix, "base_link", ns_to_stamp(1_500_000_000))
    assert msg.header.frame_id == "base_link"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 500_000_000)
    q = msg.pose.orientation
    assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, rel_tol=1e-12)
    np.testing.assert_allclose(pose_stamped_to_matrix(msg), matrix, atol=1e-12)
    other = _pose((-2.0, 0.4, -0.1), (1.0, 2.0, 3.0))
    same = fill_pose_stamped(msg, other, Time(sec=7), "world")
    assert same is msg and msg.header.frame_id == "world" and msg.header.stamp.sec == 7
    np.testing.assert_allclose(pose_to_matrix(msg.pose), other, atol=1e-12)


def test_pose_to_matrix_normalises_quaternion_and_rejects_zero():
    msg = PoseStamped()
    msg.pose.orientation.z, msg.pose.orientation.w = 2.0, 2.0  # 90 deg about z, length 2.83
    rotation = pose_to_matrix(msg.pose)[:3, :3]
    np.testing.assert_allclose(rotation, rpy_to_matrix(0, 0, math.pi / 2), atol=1e-12)
    msg.pose.orientation.z = msg.pose.orientation.w = 0.0
    with pytest.raises(InvalidMessageError, match="length"):
        pose_to_matrix(msg.pose)


def test_twist_round_trip():
    msg = make_twist_stamped([0.1, 0.2, 0.3], np.array([-1.0, 0.5, 4.0]), "base_link", Time(sec=3))
    angular, linear = twist_to_arrays(msg.twist)
    np.testing.assert_array_equal(angular, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(linear, [-1.0, 0.5, 4.0])
    assert msg.header.frame_id == "base_link" and msg.header.stamp.sec == 3


def test_joint_state_and_multiarray():
    msg = make_joint_state(["a", "b"], [0.5, -1.0], [0.1, 0.2], Time(sec=4, nanosec=5))
    assert list(msg.name) == ["a", "b"]
    assert list(msg.position) == [0.5, -1.0] and list(msg.velocity) == [0.1, 0.2]
    assert isinstance(msg.position, array.array)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (4, 5)
    command = array_to_multiarray(np.array([1.0, 2.0, 3.0]))
    assert list(command.data) == [1.0, 2.0, 3.0] and not command.layout.dim
    np.testing.assert_array_equal(multiarray_to_array(command), [1.0, 2.0, 3.0])


def test_stamps():
    stamp = ns_to_stamp(12_000_000_123)
    assert (stamp.sec, stamp.nanosec) == (12, 123)
    assert stamp_to_ns(stamp) == 12_000_000_123
    assert stamp_key(stamp) == "12.000000123"
    assert math.isclose(stamp_to_seconds(stamp), 12.000000123)


@given(st.integers(0, 2**31 - 1), st.integers(0, 999_999_999))
def test_stamp_key_reads_back_to_its_time(sec, nanosec):
    stamp = Time(sec=sec, nanosec=nanosec)
    assert stamp_key_to_ns(stamp_key(stamp)) == stamp_to_ns(stamp)


@pytest.mark.parametrize("text", ["", "12", "12.5", "12.0000001234", "a.000000001", "1.00000000x"])
def test_stamp_key_to_ns_refuses_other_text(text):
    with pytest.raises(ValueError):
        stamp_key_to_ns(text)


def test_joint_state_mapper_reorders_by_name_and_reports_problems():
    mapper = JointStateMapper(["j1", "j2", "j3"])
    msg = make_joint_state(["j3", "extra", "j1", "j2"], [3.0, 9.0, 1.0, 2.0])
    np.testing.assert_array_equal(mapper.positions(msg), [1.0, 2.0, 3.0])
    msg.position = array.array("d", [30.0, 9.0, 10.0, 20.0])  # same names: cached map
    np.testing.assert_array_equal(mapper.positions(msg), [10.0, 20.0, 30.0])
    with pytest.raises(InvalidMessageError, match=r"lacks joints \['j2'\]"):
        mapper.positions(make_joint_state(["j1", "j3"], [0.0, 0.0]))
    with pytest.raises(InvalidMessageError, match="3 names but 2 positions"):
        mapper.positions(make_joint_state(["j1", "j2", "j3"], [0.0, 0.0]))
    with pytest.raises(InvalidMessageError, match="NaN"):
        mapper.positions(make_joint_state(["j1", "j2", "j3"], [0.0, math.nan, 0.0]))


def test_pose_problem_checks_frame_finite_and_unit_quaternion():
    good = make_pose_stamped(_pose(), "base_link")
    assert pose_problem(good, "base_link") is None
    np.testing.assert_allclose(check_pose_stamped(good, "base_link"), _pose(), atol=1e-12)

    wrong_frame = make_pose_stamped(_pose(), "world")
    assert "'world' is not the base frame" in pose_problem(wrong_frame, "base_link", "goal")
    empty_frame = make_pose_stamped(_pose(), "")
    assert pose_problem(empty_frame, "base_link") is not None

    nan = make_pose_stamped(_pose(), "base_link")
    nan.pose.position.y = math.nan
    assert "NaN" in pose_problem(nan, "base_link")
    inf = make_pose_stamped(_pose(), "base_link")
    inf.pose.orientation.w = math.inf
    assert "NaN or infinity" in pose_problem(inf, "base_link")

    long_quat = make_pose_stamped(_pose(), "base_link")
    long_quat.pose.orientation.w *= 1.5
    long_quat.pose.orientation.x *= 1.5
    assert "length" in pose_problem(long_quat, "base_link")
    with pytest.raises(InvalidMessageError, match="unit length"):
        check_pose_stamped(long_quat, "base_link")
    hand_typed = PoseStamped()
    hand_typed.header.frame_id = "base_link"
    hand_typed.pose.orientation.y, hand_typed.pose.orientation.w = 0.707, 0.707
    assert pose_problem(hand_typed, "base_link") is None


def test_twist_and_command_problems():
    good = make_twist_stamped([0, 0, 1], [1, 0, 0], "base_link")
    assert twist_problem(good, "base_link") is None
    bad = make_twist_stamped([0, 0, math.nan], [1, 0, 0], "base_link")
    assert "NaN" in twist_problem(bad, "base_link")
    assert "not the base frame" in twist_problem(make_twist_stamped([0] * 3, [0] * 3, "tool"), "base_link")

    assert command_problem(np.zeros(6), 6) is None
    assert "has 5 values; valid: 6" in command_problem(np.zeros(5), 6)
    assert "NaN" in command_problem(np.array([0, 0, 0, 0, 0, math.inf]), 6)
    msg = Float64MultiArray(data=[0.0, 1.0])
    with pytest.raises(InvalidMessageError, match="has 2 values"):
        check_command(msg, 3)
    np.testing.assert_array_equal(check_command(msg, 2), [0.0, 1.0])


def test_to_double_array_accepts_non_contiguous():
    values = np.arange(10.0)[::2]
    assert list(to_double_array(values)) == [0.0, 2.0, 4.0, 6.0, 8.0]
    msg = JointState()
    msg.position = to_double_array(values)
    assert list(msg.position) == [0.0, 2.0, 4.0, 6.0, 8.0]


# --- pre-serialised messages and byte decoders ------------------------------------------------

from geometry_msgs.msg import TwistStamped as _TwistStamped  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from std_msgs.msg import MultiArrayDimension  # noqa: E402


@pytest.mark.parametrize("frame", ["base_link", "", "abc", "frame_with_7"])
def test_pose_and_twist_cdr_match_rclpy(frame):
    matrix = _pose()
    stamp_ns = 1_234_567_890_123
    expected = make_pose_stamped(matrix, frame, ns_to_stamp(stamp_ns))
    data = PoseStampedCdr(frame).encode(stamp_ns, matrix)
    assert len(data) == len(serialize_message(expected))
    assert deserialize_message(data, PoseStamped) == expected
    angular, linear = np.array([0.1, -0.2, 0.3]), np.array([1.0, 2.0, -3.0])
    twist = TwistStampedCdr(frame).encode(99, angular, linear)
    assert deserialize_message(twist, _TwistStamped) == make_twist_stamped(angular, linear, frame, ns_to_stamp(99))


@pytest.mark.parametrize("names", [["j1", "joint_2", "a"], [], ["abcde"] * 7])
def test_joint_state_and_command_cdr_match_rclpy(names):
    position, velocity = np.arange(len(names)) * 1.5, -np.arange(len(names)) * 0.25
    data = JointStateCdr(names).encode(5_000_000_001, position, velocity)
    assert deserialize_message(data, JointState) == make_joint_state(
        names, position, velocity, ns_to_stamp(5_000_000_001)
    )
    values = np.arange(len(names)) * 0.5
    command = Float64ArrayCdr(len(names)).encode(values)
    assert deserialize_message(command, Float64MultiArray) == array_to_multiarray(values)
    np.testing.assert_array_equal(decode_float64_array(command), values)


def test_decode_float64_array_with_layout_falls_back():
    msg = Float64MultiArray(data=[1.0, 2.0])
    msg.layout.dim = [MultiArrayDimension(label="joints", size=2, stride=2)]
    np.testing.assert_array_equal(decode_float64_array(serialize_message(msg)), [1.0, 2.0])


def test_joint_state_decoder_fast_path_and_fallbacks():
    names = ["joint1", "j2", "joint_three"]
    decoder = JointStateDecoder(names)
    first = serialize_message(make_joint_state(names, [1.0, 2.0, 3.0], [0.0, 0.0, 0.0]))
    np.testing.assert_array_equal(decoder.positions(first), [1.0, 2.0, 3.0])
    fast = serialize_message(make_joint_state(names, [4.0, 5.0, 6.0]))
    np.testing.assert_array_equal(decoder.positions(fast), [4.0, 5.0, 6.0])
    # Other order and an extra joint: matched by name through the slow path.
    other = serialize_message(make_joint_state(["j2", "extra", "joint_three", "joint1"], [2.0, 9.0, 3.0, 1.0]))
    np.testing.assert_array_equal(decoder.positions(other), [1.0, 2.0, 3.0])
    framed = make_joint_state(names, [7.0, 8.0, 9.0])
    framed.header.frame_id = "base_link"  # different bytes before the names: not the fast path
    np.testing.assert_array_equal(decoder.positions(serialize_message(framed)), [7.0, 8.0, 9.0])
    with pytest.raises(InvalidMessageError, match="NaN"):
        decoder.positions(serialize_message(make_joint_state(names, [1.0, math.inf, 3.0])))
    with pytest.raises(InvalidMessageError, match="lacks joints"):
        decoder.positions(serialize_message(make_joint_state(names[:2], [1.0, 2.0])))
    with pytest.raises(InvalidMessageError, match="3 names but 2 positions"):
        decoder.positions(serialize_message(make_joint_state(names, [1.0, 2.0])))


def test_joint_state_decoder_matches_rclpy_on_a_random_stream():
    """One decoder fed a seeded stream of layouts (the fast path learns one, others fall back):
    every answer (positions, velocities, stamp) equals rclpy's own deserialization matched by name."""

    seed = 20261127
    rng = np.random.default_rng(seed)
    names = ["joint1", "j2", "joint_three", "a_long_joint_name_4"]
    decoder = JointStateDecoder(names)
    fast_layout = make_joint_state(names, [0.0] * 4, [0.0] * 4)
    for index in range(400):
        if rng.random() < 0.6:  # same layout as the learned one: new values only
            velocity_count = 4 if rng.random() < 0.8 else int(rng.choice([0, 3]))
            message = make_joint_state(names, rng.normal(size=4) * 3)
            message.velocity = rng.normal(size=velocity_count).tolist()
        else:
            order = list(rng.permutation(names)) + (["extra"] if rng.random() < 0.5 else [])
            message = make_joint_state(order, rng.normal(size=len(order)) * 3)
            if rng.random() < 0.5:
                message.velocity = rng.normal(size=len(order)).tolist()
            message.header.frame_id = "base_link" if rng.random() < 0.5 else ""
        if rng.random() < 0.5:
            message.effort = rng.normal(size=int(rng.integers(0, 6))).tolist()
        message.header.stamp.sec = int(rng.integers(0, 2**31 - 1))
        message.header.stamp.nanosec = int(rng.integers(0, 1_000_000_000))
        data = serialize_message(message)
        decoded = deserialize_message(data, JointState)
        order = [list(decoded.name).index(name) for name in names]
        context = f"seed {seed}, message {index}"
        sample = decoder.sample(data)
        np.testing.assert_array_equal(sample.positions, [decoded.position[i] for i in order], err_msg=context)
        if len(decoded.velocity) == len(decoded.name):
            np.testing.assert_array_equal(sample.velocities, [decoded.velocity[i] for i in order], err_msg=context)
        else:
            assert sample.velocities is None, context
        assert sample.stamp_ns == decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec, context
    np.testing.assert_array_equal(decoder.positions(serialize_message(fast_layout)), [0.0] * 4)


def test_diagnostic_helpers():
    status = make_diagnostic_status("n", "warn", "tracking", "genova7", [("a", 1), ("b", "x")])
    assert status.level == b"\x01" and status.message == "tracking" and status.hardware_id == "genova7"
    assert diagnostic_values(status) == {"a": "1", "b": "x"}
    array_msg = make_diagnostic_array(Time(sec=3), [status])
    assert array_msg.header.stamp.sec == 3 and array_msg.status[0].name == "n"


_TEXT = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=12)


@given(
    stamp_ns=st.integers(-(2**31) * 10**9, (2**31 - 1) * 10**9),
    level=st.sampled_from(sorted(DIAGNOSTIC_LEVELS)),
    texts=st.tuples(_TEXT, _TEXT, _TEXT),
    values=st.lists(st.tuples(_TEXT, st.one_of(_TEXT, st.integers(), st.floats(allow_nan=False))), max_size=12),
)
def test_diagnostic_array_cdr_is_what_rclpy_makes_of_the_message(stamp_ns, level, texts, values):
    """The status the nodes publish as bytes reads back as the message built the slow way: field
    for field, and byte for byte but the padding (rclpy leaves its padding bytes unset)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message, serialize_message

    name, message, hardware_id = texts
    data = diagnostic_array_cdr(stamp_ns, name, level, message, hardware_id, values)
    sec, nanosec = divmod(stamp_ns, 10**9)
    expected = make_diagnostic_array(
        Time(sec=sec, nanosec=nanosec), [make_diagnostic_status(name, level, message, hardware_id, values)]
    )
    reference = serialize_message(expected)
    assert len(data) == len(reference)
    decoded = deserialize_message(data, DiagnosticArray)
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (sec, nanosec)
    assert decoded.header.frame_id == ""
    assert len(decoded.status) == 1
    status = decoded.status[0]
    assert (status.level, status.name, status.message, status.hardware_id) == (
        DIAGNOSTIC_LEVELS[level],
        name,
        message,
        hardware_id,
    )
    assert [(kv.key, kv.value) for kv in status.values] == [(str(k), str(v)) for k, v in values]


def test_encode_values_paths_match_array_paths():
    from manip_kin.core.rotations import matrix_to_quat

    rng = np.random.default_rng(3)
    encoder = PoseStampedCdr("base_link")
    for _ in range(200):
        rpy = rng.uniform(-math.pi, math.pi, 3)
        rpy[1] /= 2
        matrix = _pose(tuple(rpy), tuple(rng.normal(size=3)))
        values = matrix.reshape(-1).tolist()
        np.testing.assert_allclose(quaternion_of_pose_values(values), matrix_to_quat(matrix[:3, :3]), atol=1e-12)
        decoded = deserialize_message(encoder.encode_values(7, values), PoseStamped)
        assert decoded.header.stamp.nanosec == 7 and decoded.header.frame_id == "base_link"
        np.testing.assert_allclose(pose_stamped_to_matrix(decoded), matrix, atol=1e-12)
    for special in (
        np.eye(3),
        rpy_to_matrix(math.pi, 0, 0),
        rpy_to_matrix(0, math.pi, 0),
        rpy_to_matrix(0, 0, math.pi),
    ):
        values = make_transform(special, [0, 0, 0]).reshape(-1).tolist()
        np.testing.assert_allclose(quaternion_of_pose_values(values), matrix_to_quat(special), atol=1e-12)
    twist = TwistStampedCdr("base_link")
    assert twist.encode_values(5, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]) == twist.encode(
        5, np.array([1.0, 2.0, 3.0]), np.array([4.0, 5.0, 6.0])
    )
    joints = JointStateCdr(["a", "b"])
    assert joints.encode_values(5, [1.0, 2.0], [3.0, 4.0]) == joints.encode(
        5, np.array([1.0, 2.0]), np.array([3.0, 4.0])
    )


def _pose_stamped_fields(msg) -> tuple:
    """Every field of a PoseStamped (rclpy's or decoded), floats as their bit patterns (NaN == NaN)."""
    p, o = msg.pose.position, msg.pose.orientation
    floats = np.array([p.x, p.y, p.z, o.x, o.y, o.z, o.w]).view(np.int64).tolist()
    return msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id, floats


any_float = st.floats(allow_nan=True, allow_infinity=True)


@given(
    st.integers(-(2**31), 2**31 - 1),
    st.integers(0, 2**32 - 1),
    st.text(st.characters(blacklist_characters="\0"), max_size=40),
    st.lists(any_float, min_size=7, max_size=7),
)
def test_pose_stamped_read_from_its_bytes_equals_rclpy_deserialization(sec, nanosec, frame_id, values):
    msg = PoseStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = sec, nanosec, frame_id
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = values
    data = serialize_message(msg)
    decoded = decode_pose_stamped(data)
    assert isinstance(decoded, DecodedPoseStamped)  # the fast path, not the fallback
    assert _pose_stamped_fields(decoded) == _pose_stamped_fields(deserialize_message(data, PoseStamped))
    # What the controller does with a goal reads it the same way.
    assert pose_problem(decoded, "base_link") == pose_problem(msg, "base_link")
    assert stamp_key(decoded.header.stamp) == stamp_key(msg.header.stamp)
    if pose_problem(msg, frame_id) is None:
        np.testing.assert_array_equal(pose_stamped_to_matrix(decoded), pose_stamped_to_matrix(msg))


@given(st.binary(max_size=120), st.integers(0, 120), st.booleans())
def test_pose_stamped_bytes_cut_or_corrupted_decode_as_rclpy_does_or_are_rejected(noise, cut, splice):
    msg = make_pose_stamped(make_transform(rpy_to_matrix(0.1, 0.2, 0.3), [0.4, 0.5, 0.6]), "base_link")
    valid = serialize_message(msg)
    data = valid[:cut] + noise if splice else (valid[:cut] + noise + valid[cut:])[: len(valid) + 8]
    try:
        expected = _pose_stamped_fields(deserialize_message(data, PoseStamped))
    except Exception:  # noqa: BLE001 - whatever rclpy raises for bytes it cannot read
        expected = None
    try:
        got = _pose_stamped_fields(decode_pose_stamped(data))
    except InvalidMessageError as error:
        assert expected is None, (data, expected)
        assert "goal pose bytes cannot be decoded" in str(error)
        return
    assert got == expected


def test_pose_stamped_with_a_frame_id_that_is_not_utf8_decodes_as_rclpy_does():
    data = bytearray(serialize_message(make_pose_stamped(np.eye(4), "ab")))
    assert data[16:19] == b"ab\0"
    data[16:18] = b"\xff\xfe"
    decoded = decode_pose_stamped(bytes(data))
    assert _pose_stamped_fields(decoded) == _pose_stamped_fields(deserialize_message(bytes(data), PoseStamped))
    assert "base_link" in pose_problem(decoded, "base_link")  # a wrong frame, said as for any other
