"""Message <-> numpy conversions and the message checks, without spinning."""

import array
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.nodes import conversions as conv
from manip_kin.rotations import make_transform, rpy_to_matrix


def _pose(rpy=(0.3, -1.2, 2.5), xyz=(0.1, -0.2, 0.3)) -> np.ndarray:
    return make_transform(rpy_to_matrix(*rpy), xyz)


def test_pose_round_trip_and_fill_in_place():
    matrix = _pose()
    msg = conv.make_pose_stamped(matrix, "base_link", conv.ns_to_stamp(1_500_000_000))
    assert msg.header.frame_id == "base_link"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 500_000_000)
    q = msg.pose.orientation
    assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, rel_tol=1e-12)
    np.testing.assert_allclose(conv.pose_stamped_to_matrix(msg), matrix, atol=1e-12)
    other = _pose((-2.0, 0.4, -0.1), (1.0, 2.0, 3.0))
    same = conv.fill_pose_stamped(msg, other, Time(sec=7), "world")
    assert same is msg and msg.header.frame_id == "world" and msg.header.stamp.sec == 7
    np.testing.assert_allclose(conv.pose_to_matrix(msg.pose), other, atol=1e-12)


def test_pose_to_matrix_normalises_quaternion_and_rejects_zero():
    msg = PoseStamped()
    msg.pose.orientation.z, msg.pose.orientation.w = 2.0, 2.0  # 90 deg about z, length 2.83
    rotation = conv.pose_to_matrix(msg.pose)[:3, :3]
    np.testing.assert_allclose(rotation, rpy_to_matrix(0, 0, math.pi / 2), atol=1e-12)
    msg.pose.orientation.z = msg.pose.orientation.w = 0.0
    with pytest.raises(conv.InvalidMessageError, match="length"):
        conv.pose_to_matrix(msg.pose)


def test_twist_round_trip():
    msg = conv.make_twist_stamped([0.1, 0.2, 0.3], np.array([-1.0, 0.5, 4.0]), "base_link", Time(sec=3))
    angular, linear = conv.twist_to_arrays(msg.twist)
    np.testing.assert_array_equal(angular, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(linear, [-1.0, 0.5, 4.0])
    assert msg.header.frame_id == "base_link" and msg.header.stamp.sec == 3


def test_joint_state_and_multiarray():
    msg = conv.make_joint_state(["a", "b"], [0.5, -1.0], [0.1, 0.2], Time(sec=4, nanosec=5))
    assert list(msg.name) == ["a", "b"]
    assert list(msg.position) == [0.5, -1.0] and list(msg.velocity) == [0.1, 0.2]
    assert isinstance(msg.position, array.array)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (4, 5)
    command = conv.array_to_multiarray(np.array([1.0, 2.0, 3.0]))
    assert list(command.data) == [1.0, 2.0, 3.0] and not command.layout.dim
    np.testing.assert_array_equal(conv.multiarray_to_array(command), [1.0, 2.0, 3.0])


def test_stamps():
    stamp = conv.ns_to_stamp(12_000_000_123)
    assert (stamp.sec, stamp.nanosec) == (12, 123)
    assert conv.stamp_to_ns(stamp) == 12_000_000_123
    assert conv.stamp_key(stamp) == "12.000000123"
    assert math.isclose(conv.stamp_to_seconds(stamp), 12.000000123)


def test_joint_state_mapper_reorders_by_name_and_reports_problems():
    mapper = conv.JointStateMapper(["j1", "j2", "j3"])
    msg = conv.make_joint_state(["j3", "extra", "j1", "j2"], [3.0, 9.0, 1.0, 2.0])
    np.testing.assert_array_equal(mapper.positions(msg), [1.0, 2.0, 3.0])
    msg.position = array.array("d", [30.0, 9.0, 10.0, 20.0])  # same names: cached map
    np.testing.assert_array_equal(mapper.positions(msg), [10.0, 20.0, 30.0])
    with pytest.raises(conv.InvalidMessageError, match=r"lacks joints \['j2'\]"):
        mapper.positions(conv.make_joint_state(["j1", "j3"], [0.0, 0.0]))
    with pytest.raises(conv.InvalidMessageError, match="3 names but 2 positions"):
        mapper.positions(conv.make_joint_state(["j1", "j2", "j3"], [0.0, 0.0]))
    with pytest.raises(conv.InvalidMessageError, match="NaN"):
        mapper.positions(conv.make_joint_state(["j1", "j2", "j3"], [0.0, math.nan, 0.0]))


def test_pose_problem_checks_frame_finite_and_unit_quaternion():
    good = conv.make_pose_stamped(_pose(), "base_link")
    assert conv.pose_problem(good, "base_link") is None
    np.testing.assert_allclose(conv.check_pose_stamped(good, "base_link"), _pose(), atol=1e-12)

    wrong_frame = conv.make_pose_stamped(_pose(), "world")
    assert "'world' is not the base frame" in conv.pose_problem(wrong_frame, "base_link", "goal")
    empty_frame = conv.make_pose_stamped(_pose(), "")
    assert conv.pose_problem(empty_frame, "base_link") is not None

    nan = conv.make_pose_stamped(_pose(), "base_link")
    nan.pose.position.y = math.nan
    assert "NaN" in conv.pose_problem(nan, "base_link")
    inf = conv.make_pose_stamped(_pose(), "base_link")
    inf.pose.orientation.w = math.inf
    assert "NaN or infinity" in conv.pose_problem(inf, "base_link")

    long_quat = conv.make_pose_stamped(_pose(), "base_link")
    long_quat.pose.orientation.w *= 1.5
    long_quat.pose.orientation.x *= 1.5
    assert "length" in conv.pose_problem(long_quat, "base_link")
    with pytest.raises(conv.InvalidMessageError, match="unit length"):
        conv.check_pose_stamped(long_quat, "base_link")
    hand_typed = PoseStamped()
    hand_typed.header.frame_id = "base_link"
    hand_typed.pose.orientation.y, hand_typed.pose.orientation.w = 0.707, 0.707
    assert conv.pose_problem(hand_typed, "base_link") is None


def test_twist_and_command_problems():
    good = conv.make_twist_stamped([0, 0, 1], [1, 0, 0], "base_link")
    assert conv.twist_problem(good, "base_link") is None
    bad = conv.make_twist_stamped([0, 0, math.nan], [1, 0, 0], "base_link")
    assert "NaN" in conv.twist_problem(bad, "base_link")
    assert "not the base frame" in conv.twist_problem(conv.make_twist_stamped([0] * 3, [0] * 3, "tool"), "base_link")

    assert conv.command_problem(np.zeros(6), 6) is None
    assert "has 5 values; valid: 6" in conv.command_problem(np.zeros(5), 6)
    assert "NaN" in conv.command_problem(np.array([0, 0, 0, 0, 0, math.inf]), 6)
    msg = Float64MultiArray(data=[0.0, 1.0])
    with pytest.raises(conv.InvalidMessageError, match="has 2 values"):
        conv.check_command(msg, 3)
    np.testing.assert_array_equal(conv.check_command(msg, 2), [0.0, 1.0])


def test_to_double_array_accepts_non_contiguous():
    values = np.arange(10.0)[::2]
    assert list(conv.to_double_array(values)) == [0.0, 2.0, 4.0, 6.0, 8.0]
    msg = JointState()
    msg.position = conv.to_double_array(values)
    assert list(msg.position) == [0.0, 2.0, 4.0, 6.0, 8.0]
