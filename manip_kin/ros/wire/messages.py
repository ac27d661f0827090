"""ROS messages <-> numpy: stamps, poses, twists, joint vectors, command arrays.

Conventions (shared interfaces of the package, see the README):
    * poses are 4x4 homogeneous transforms ``[[R, p], [0, 1]]`` in the base frame [m];
    * twists are ``(angular [rad/s], linear [m/s])``, each shape (3,), velocity w.r.t.
      the base expressed in the base frame;
    * joint vectors are in model joint order, shape (n,);
    * quaternions are ``(x, y, z, w)``.

Hot-path fillers (``fill_*``) write into an existing message so a node can reuse one
message object per topic; the ``make_*`` helpers build a new one. Nothing here touches a
node, a clock or a topic.
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseStamped, Twist, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.core.rotations import matrix_to_quat
from manip_kin.errors import ProblemKind
from manip_kin.ros.wire.validation import QUATERNION_TOLERANCE, InvalidMessageError, pose_problem

_NS_PER_S = 1_000_000_000


# --- time ------------------------------------------------------------------------------------


def stamp_to_ns(stamp: Time) -> int:
    """A ``builtin_interfaces/Time`` as integer nanoseconds."""
    return stamp.sec * _NS_PER_S + stamp.nanosec


def stamp_to_seconds(stamp: Time) -> float:
    """A ``builtin_interfaces/Time`` as seconds (float)."""
    return stamp.sec + stamp.nanosec * 1e-9


def ns_to_stamp(nanoseconds: int, stamp: Time | None = None) -> Time:
    """Integer nanoseconds as a ``builtin_interfaces/Time`` (filled in place when given)."""
    stamp = Time() if stamp is None else stamp
    sec, nanosec = divmod(int(nanoseconds), _NS_PER_S)
    stamp.sec = sec
    stamp.nanosec = nanosec
    return stamp


def stamp_key(stamp: Time) -> str:
    """A stamp as the text ``sec.nanosec`` (9 digits) used to match goals in /diagnostics."""
    return f"{stamp.sec}.{stamp.nanosec:09d}"


def stamp_key_to_ns(key: str) -> int:
    """The time [ns] of a :func:`stamp_key` text; ValueError for any other text."""
    seconds, dot, nanoseconds = key.partition(".")
    if not dot or len(nanoseconds) != 9:
        raise ValueError(f"not a stamp key (sec.nanosec, 9 digits): {key!r}")
    return int(seconds) * 1_000_000_000 + int(nanoseconds)


# --- poses -----------------------------------------------------------------------------------


def quaternion_to_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a quaternion, normalised first, shape (3, 3).

    Raises:
        InvalidMessageError: for a zero-length or non-finite quaternion.
    """
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or norm < 1e-12:
        raise InvalidMessageError(
            f"quaternion ({x}, {y}, {z}, {w}) has length {norm}; valid: a unit quaternion", kind=ProblemKind.QUATERNION
        )
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
            [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
            [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )


def pose_to_matrix(pose: Pose) -> np.ndarray:
    """A ``geometry_msgs/Pose`` as a 4x4 transform (quaternion normalised), shape (4, 4)."""
    o = pose.orientation
    matrix = np.eye(4)
    matrix[:3, :3] = quaternion_to_matrix(o.x, o.y, o.z, o.w)
    p = pose.position
    matrix[0, 3], matrix[1, 3], matrix[2, 3] = p.x, p.y, p.z
    return matrix


def pose_stamped_to_matrix(msg: PoseStamped) -> np.ndarray:
    """The pose of a ``PoseStamped`` as a 4x4 transform; the frame is not checked here."""
    return pose_to_matrix(msg.pose)


def fill_pose(pose: Pose, matrix: np.ndarray) -> Pose:
    """Write a 4x4 transform into ``pose`` (in place) and return it."""
    qx, qy, qz, qw = matrix_to_quat(matrix[:3, :3]).tolist()
    x, y, z = matrix[:3, 3].tolist()
    position = pose.position
    position.x, position.y, position.z = x, y, z
    orientation = pose.orientation
    orientation.x, orientation.y, orientation.z, orientation.w = qx, qy, qz, qw
    return pose


def fill_pose_stamped(msg: PoseStamped, matrix: np.ndarray, stamp: Time, frame_id: str) -> PoseStamped:
    """Write stamp, frame and a 4x4 transform into ``msg`` (in place) and return it."""
    msg.header.stamp = stamp
    if msg.header.frame_id != frame_id:
        msg.header.frame_id = frame_id
    fill_pose(msg.pose, matrix)
    return msg


def make_pose_stamped(matrix: np.ndarray, frame_id: str, stamp: Time | None = None) -> PoseStamped:
    """A new ``PoseStamped`` of a 4x4 transform."""
    return fill_pose_stamped(PoseStamped(), np.asarray(matrix, dtype=float), stamp or Time(), frame_id)


# --- twists ----------------------------------------------------------------------------------


def twist_to_arrays(twist: Twist) -> tuple[np.ndarray, np.ndarray]:
    """A ``geometry_msgs/Twist`` as ``(angular [rad/s], linear [m/s])``, each shape (3,)."""
    a, v = twist.angular, twist.linear
    return np.array([a.x, a.y, a.z]), np.array([v.x, v.y, v.z])


def fill_twist_stamped(
    msg: TwistStamped, angular: np.ndarray, linear: np.ndarray, stamp: Time, frame_id: str
) -> TwistStamped:
    """Write stamp, frame, angular [rad/s] and linear [m/s] velocity into ``msg`` (in place)."""
    msg.header.stamp = stamp
    if msg.header.frame_id != frame_id:
        msg.header.frame_id = frame_id
    a, v = msg.twist.angular, msg.twist.linear
    a.x, a.y, a.z = np.asarray(angular, dtype=float).tolist()
    v.x, v.y, v.z = np.asarray(linear, dtype=float).tolist()
    return msg


def make_twist_stamped(angular, linear, frame_id: str, stamp: Time | None = None) -> TwistStamped:
    """A new ``TwistStamped`` of angular [rad/s] and linear [m/s] velocity, each shape (3,)."""
    return fill_twist_stamped(TwistStamped(), angular, linear, stamp or Time(), frame_id)


# --- joint vectors -----------------------------------------------------------------------------


def to_double_array(values: np.ndarray) -> array.array:
    """A float64 numpy vector as ``array.array('d')``.

    Message sequence fields accept an ``array.array`` of the right type as is; a list is
    checked element by element, which costs tens of microseconds per message.
    """
    return array.array("d", np.ascontiguousarray(values, dtype=np.float64).tobytes())


def make_joint_state(names: Sequence[str], position, velocity=None, stamp: Time | None = None) -> JointState:
    """A ``JointState`` with names, positions [rad | m] and velocities [rad/s | m/s] (model order)."""
    msg = JointState()
    msg.name = list(names)
    fill_joint_state(
        msg,
        np.asarray(position, dtype=float),
        None if velocity is None else np.asarray(velocity, float),
        stamp or Time(),
    )
    return msg


def fill_joint_state(msg: JointState, position: np.ndarray, velocity: np.ndarray | None, stamp: Time) -> JointState:
    """Write stamp, positions and velocities into ``msg`` (names untouched)."""
    msg.header.stamp = stamp
    msg.position = to_double_array(position)
    msg.velocity = to_double_array(velocity) if velocity is not None else array.array("d")
    return msg


def array_to_multiarray(values, msg: Float64MultiArray | None = None) -> Float64MultiArray:
    """A vector as ``std_msgs/Float64MultiArray`` (no layout: ros2_control's command format)."""
    msg = Float64MultiArray() if msg is None else msg
    msg.data = to_double_array(np.asarray(values, dtype=float))
    return msg


def multiarray_to_array(msg: Float64MultiArray) -> np.ndarray:
    """The data of a ``Float64MultiArray`` as a float64 vector (a copy), shape (len,)."""
    return np.array(msg.data, dtype=float)


def check_pose_stamped(
    msg: PoseStamped, base_frame: str, what: str = "pose", quaternion_tolerance: float = QUATERNION_TOLERANCE
) -> np.ndarray:
    """The pose of a valid ``PoseStamped`` as a 4x4 transform, or :class:`InvalidMessageError`."""
    problem = pose_problem(msg, base_frame, what, quaternion_tolerance)
    if problem is not None:
        raise InvalidMessageError(problem)
    return pose_stamped_to_matrix(msg)
