"""Pure conversions between ROS messages and numpy, and the checks every node applies.

Nothing here touches a node, a clock or a topic: each function takes messages or
arrays and returns arrays, messages, or a reason string, so they are tested
without spinning.

Conventions (shared/interfaces.md):
    * poses are 4x4 homogeneous transforms ``[[R, p], [0, 1]]`` in the base frame [m];
    * twists are ``(angular [rad/s], linear [m/s])``, each shape (3,), velocity w.r.t.
      the base expressed in the base frame;
    * joint vectors are in model joint order, shape (n,);
    * quaternions are ``(x, y, z, w)``.

Hot-path fillers (``fill_*``) write into an existing message so a node can reuse one
message object per topic; the ``make_*`` helpers build a new one.

Validation helpers come in two flavours: ``*_problem(...)`` returns ``None`` for a good
message or a one-line reason (what is wrong and what is valid) for a log line, and
``check_*(...)`` raises :class:`InvalidMessageError` with the same reason.
"""

from __future__ import annotations

import array
import math
import struct
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseStamped, Twist, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.errors import ManipKinError
from manip_kin.rotations import matrix_to_quat, quaternion_from_entries

#: Default tolerance on ``| |q| - 1 |`` for a goal quaternion: hand-typed quaternions
#: such as ``0 0.707 0 0.707`` pass, a zero or unnormalised one does not.
QUATERNION_TOLERANCE = 1e-2

_NS_PER_S = 1_000_000_000


class InvalidMessageError(ManipKinError):
    """A message a node must reject: non-finite values, wrong length, wrong frame, bad quaternion."""


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


# --- poses -----------------------------------------------------------------------------------


def quaternion_to_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a quaternion, normalised first, shape (3, 3).

    Raises:
        InvalidMessageError: for a zero-length or non-finite quaternion.
    """
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or norm < 1e-12:
        raise InvalidMessageError(f"quaternion ({x}, {y}, {z}, {w}) has length {norm}; valid: a unit quaternion")
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


class JointStateMapper:
    """Reorders ``JointState`` messages into model joint order, matching by name.

    The index map is rebuilt only when a message's name list differs from the last one,
    so the per-message cost is one list comparison and one fancy index.

    Args:
        joint_names: the model's joint names in model order.
    """

    def __init__(self, joint_names: Sequence[str]):
        self.joint_names = list(joint_names)
        self._last_names: list[str] | None = None
        self._index: np.ndarray | None = None
        self._problem: str | None = None

    def positions(self, msg: JointState) -> np.ndarray:
        """Positions of ``msg`` in model order, shape (n,).

        Raises:
            InvalidMessageError: a model joint missing, position and name counts differing,
                or a non-finite position.
        """
        names = msg.name
        if names != self._last_names:
            self._rebuild(list(names))
        if self._problem is not None:
            raise InvalidMessageError(self._problem)
        position = (
            np.frombuffer(msg.position, dtype=np.float64)
            if isinstance(msg.position, array.array)
            else np.asarray(msg.position, dtype=float)
        )
        if position.shape[0] != len(names):
            raise InvalidMessageError(
                f"joint state has {len(names)} names but {position.shape[0]} positions; valid: one position per name"
            )
        ordered = position[self._index]
        if not np.all(np.isfinite(ordered)):
            raise InvalidMessageError("joint state positions contain NaN or infinity; valid: finite numbers")
        return ordered

    def _rebuild(self, names: list[str]) -> None:
        self._last_names = names
        lookup = {name: i for i, name in enumerate(names)}
        missing = [name for name in self.joint_names if name not in lookup]
        if missing:
            self._problem = f"joint state lacks joints {missing}; valid: names including {self.joint_names}"
            self._index = None
            return
        self._problem = None
        self._index = np.array([lookup[name] for name in self.joint_names], dtype=np.intp)


# --- validation ----------------------------------------------------------------------------------


def frame_problem(frame_id: str, base_frame: str, what: str) -> str | None:
    """Reason to reject a header frame that is not the base frame (no tf2 here), or None."""
    if frame_id != base_frame:
        return f"{what} frame_id {frame_id!r} is not the base frame; valid: {base_frame!r} (no tf2 transforms)"
    return None


def pose_problem(
    msg: PoseStamped, base_frame: str, what: str = "pose", quaternion_tolerance: float = QUATERNION_TOLERANCE
) -> str | None:
    """Reason to reject a goal ``PoseStamped``, or None when it is usable.

    Checks, in order: frame id equals ``base_frame``; position and quaternion finite;
    quaternion length within ``quaternion_tolerance`` of 1.
    """
    problem = frame_problem(msg.header.frame_id, base_frame, what)
    if problem:
        return problem
    p, o = msg.pose.position, msg.pose.orientation
    values = (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
    if not all(math.isfinite(v) for v in values):
        return f"{what} contains NaN or infinity {values}; valid: finite position and quaternion"
    norm = math.sqrt(o.x * o.x + o.y * o.y + o.z * o.z + o.w * o.w)
    if abs(norm - 1.0) > quaternion_tolerance:
        return (
            f"{what} quaternion ({o.x:g}, {o.y:g}, {o.z:g}, {o.w:g}) has length {norm:.6g}; "
            f"valid: unit length within {quaternion_tolerance:g}"
        )
    return None


def twist_problem(msg: TwistStamped, base_frame: str, what: str = "twist") -> str | None:
    """Reason to reject a ``TwistStamped`` (wrong frame, non-finite), or None."""
    problem = frame_problem(msg.header.frame_id, base_frame, what)
    if problem:
        return problem
    a, v = msg.twist.angular, msg.twist.linear
    values = (a.x, a.y, a.z, v.x, v.y, v.z)
    if not all(math.isfinite(value) for value in values):
        return f"{what} contains NaN or infinity {values}; valid: finite numbers"
    return None


def command_problem(values: np.ndarray, dof: int, what: str = "joint velocity command") -> str | None:
    """Reason to reject a joint-rate command (wrong length, non-finite), or None."""
    if values.shape[0] != dof:
        return f"{what} has {values.shape[0]} values; valid: {dof} (one per joint, model order)"
    if not np.all(np.isfinite(values)):
        return f"{what} contains NaN or infinity; valid: finite numbers"
    return None


def _raise_if(problem: str | None) -> None:
    if problem is not None:
        raise InvalidMessageError(problem)


def check_pose_stamped(
    msg: PoseStamped, base_frame: str, what: str = "pose", quaternion_tolerance: float = QUATERNION_TOLERANCE
) -> np.ndarray:
    """The pose of a valid ``PoseStamped`` as a 4x4 transform, or :class:`InvalidMessageError`."""
    _raise_if(pose_problem(msg, base_frame, what, quaternion_tolerance))
    return pose_stamped_to_matrix(msg)


def check_twist_stamped(msg: TwistStamped, base_frame: str, what: str = "twist") -> tuple[np.ndarray, np.ndarray]:
    """``(angular, linear)`` of a valid ``TwistStamped``, or :class:`InvalidMessageError`."""
    _raise_if(twist_problem(msg, base_frame, what))
    return twist_to_arrays(msg.twist)


def check_command(msg: Float64MultiArray, dof: int, what: str = "joint velocity command") -> np.ndarray:
    """The data of a valid command as a vector of shape (dof,), or :class:`InvalidMessageError`."""
    values = multiarray_to_array(msg)
    _raise_if(command_problem(values, dof, what))
    return values


# --- diagnostics -----------------------------------------------------------------------------

#: DiagnosticStatus levels by name (diagnostic_msgs/DiagnosticStatus constants).
DIAGNOSTIC_LEVELS = {"ok": b"\x00", "warn": b"\x01", "error": b"\x02", "stale": b"\x03"}


def make_diagnostic_status(name: str, level: str, message: str, hardware_id: str, values) -> DiagnosticStatus:
    """A ``DiagnosticStatus`` with ``values`` given as ``(key, text)`` pairs.

    Args:
        name: status name, the node's name (``cartesian_controller``).
        level: ``ok``, ``warn``, ``error`` or ``stale``.
        message: short summary, here the state (``tracking``, ``converged``...).
        hardware_id: the robot name.
        values: iterable of ``(key, value)``; values are converted with ``str``.
    """
    status = DiagnosticStatus()
    status.level = DIAGNOSTIC_LEVELS[level]
    status.name = name
    status.message = message
    status.hardware_id = hardware_id
    status.values = [KeyValue(key=str(key), value=str(value)) for key, value in values]
    return status


def make_diagnostic_array(stamp: Time, statuses) -> DiagnosticArray:
    """A ``DiagnosticArray`` of ``statuses`` stamped ``stamp``."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = list(statuses)
    return msg


def diagnostic_values(status: DiagnosticStatus) -> dict[str, str]:
    """The key/value pairs of a ``DiagnosticStatus`` as a dict."""
    return {kv.key: kv.value for kv in status.values}


# --- pre-serialised messages for the 1 kHz loops ------------------------------------------------
#
# rclpy converts a Python message to C field by field (~10 µs for a PoseStamped) before
# serialising it; publishing bytes that are already CDR skips both and halves the cost of a
# publish. These encoders write the little-endian CDR (XCDR1, what rmw_fastrtps and
# rmw_cyclonedds exchange) of the few fixed-shape messages the loops publish, into one
# precompiled ``struct.Struct`` each; the tests check every one against
# ``rclpy.serialization.serialize_message``.

_CDR_LE = b"\x00\x01\x00\x00"  # encapsulation: CDR, little endian


class _CdrLayout:
    """Builds a ``struct`` format with CDR alignment (relative to the payload start)."""

    def __init__(self):
        self.parts = ["<4s"]  # the encapsulation header, not part of the aligned payload
        self.offset = 0

    def align(self, size: int) -> None:
        pad = (-self.offset) % size
        if pad:
            self.parts.append(f"{pad}x")
            self.offset += pad

    def add(self, code: str, size: int, count: int = 1) -> None:
        self.align(size)
        self.parts.append(f"{count}{code}" if count != 1 else code)
        self.offset += size * count

    def add_string(self, text: str) -> bytes:
        data = text.encode() + b"\x00"
        self.add("I", 4)
        self.parts.append(f"{len(data)}s")
        self.offset += len(data)
        return data

    def header(self, frame_id: str) -> bytes:
        """``std_msgs/Header``: stamp (sec, nanosec), then frame_id; returns the frame bytes."""
        self.add("i", 4)
        self.add("I", 4)
        return self.add_string(frame_id)

    def compile(self) -> struct.Struct:
        return struct.Struct("".join(self.parts))


def _stamp_parts(stamp_ns: int) -> tuple[int, int]:
    return divmod(int(stamp_ns), _NS_PER_S)


def quaternion_of_pose_values(values) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)``, ``w >= 0``, of the rotation in a row-major 4x4 pose."""
    return quaternion_from_entries(
        values[0], values[1], values[2], values[4], values[5], values[6], values[8], values[9], values[10]
    )


class PoseStampedCdr:
    """Serialised ``geometry_msgs/PoseStamped`` with a fixed frame id.

    Args:
        frame_id: the header's frame id.
    """

    def __init__(self, frame_id: str):
        layout = _CdrLayout()
        self._frame = layout.header(frame_id)
        self._frame_length = len(self._frame)
        layout.add("d", 8, 7)
        self._struct = layout.compile()

    def encode(self, stamp_ns: int, matrix: np.ndarray) -> bytes:
        """CDR bytes of the pose ``matrix`` (4x4) stamped ``stamp_ns`` [ns since epoch]."""
        sec, nanosec = _stamp_parts(stamp_ns)
        qx, qy, qz, qw = matrix_to_quat(matrix[:3, :3]).tolist()
        x, y, z = matrix[:3, 3].tolist()
        return self._struct.pack(_CDR_LE, sec, nanosec, self._frame_length, self._frame, x, y, z, qx, qy, qz, qw)

    def encode_values(self, stamp_ns: int, values) -> bytes:
        """CDR bytes of a pose given as 16 row-major floats (the unrolled kinematics' output)."""
        sec, nanosec = _stamp_parts(stamp_ns)
        qx, qy, qz, qw = quaternion_of_pose_values(values)
        return self._struct.pack(
            _CDR_LE, sec, nanosec, self._frame_length, self._frame, values[3], values[7], values[11], qx, qy, qz, qw
        )


class TwistStampedCdr:
    """Serialised ``geometry_msgs/TwistStamped`` with a fixed frame id."""

    def __init__(self, frame_id: str):
        layout = _CdrLayout()
        self._frame = layout.header(frame_id)
        self._frame_length = len(self._frame)
        layout.add("d", 8, 6)
        self._struct = layout.compile()

    def encode(self, stamp_ns: int, angular: np.ndarray, linear: np.ndarray) -> bytes:
        """CDR bytes of ``linear`` [m/s] and ``angular`` [rad/s] velocity stamped ``stamp_ns``."""
        sec, nanosec = _stamp_parts(stamp_ns)
        return self._struct.pack(
            _CDR_LE, sec, nanosec, self._frame_length, self._frame, *linear.tolist(), *angular.tolist()
        )

    def encode_values(self, stamp_ns: int, twist) -> bytes:
        """CDR bytes of a twist given as 6 floats ``(wx, wy, wz, vx, vy, vz)``."""
        sec, nanosec = _stamp_parts(stamp_ns)
        wx, wy, wz, vx, vy, vz = twist
        return self._struct.pack(_CDR_LE, sec, nanosec, self._frame_length, self._frame, vx, vy, vz, wx, wy, wz)


class JointStateCdr:
    """Serialised ``sensor_msgs/JointState`` with fixed names, positions and velocities (no effort).

    Args:
        names: joint names, model order.
        frame_id: the header's frame id (empty for joint states, as robot drivers send them).
    """

    def __init__(self, names: Sequence[str], frame_id: str = ""):
        layout = _CdrLayout()
        self._frame = layout.header(frame_id)
        self._frame_length = len(self._frame)
        layout.add("I", 4)
        self._names: list[object] = [len(names)]
        for name in names:
            data = layout.add_string(name)
            self._names += [len(data), data]
        count = len(names)
        for _ in range(2):  # position, velocity
            layout.add("I", 4)
            if count:
                layout.add("d", 8, count)
        layout.add("I", 4)  # effort: empty
        self._count = count
        self._struct = layout.compile()

    def encode(self, stamp_ns: int, position: np.ndarray, velocity: np.ndarray) -> bytes:
        """CDR bytes of ``position`` and ``velocity`` (shape (n,)) stamped ``stamp_ns``."""
        sec, nanosec = _stamp_parts(stamp_ns)
        n = self._count
        return self._struct.pack(
            _CDR_LE,
            sec,
            nanosec,
            self._frame_length,
            self._frame,
            *self._names,
            n,
            *position.tolist(),
            n,
            *velocity.tolist(),
            0,
        )

    def encode_values(self, stamp_ns: int, position, velocity) -> bytes:
        """CDR bytes of positions and velocities given as float sequences of length n."""
        sec, nanosec = _stamp_parts(stamp_ns)
        n = self._count
        return self._struct.pack(
            _CDR_LE, sec, nanosec, self._frame_length, self._frame, *self._names, n, *position, n, *velocity, 0
        )


class Float64ArrayCdr:
    """Serialised ``std_msgs/Float64MultiArray`` of ``size`` values with an empty layout."""

    def __init__(self, size: int):
        layout = _CdrLayout()
        layout.add("I", 4)  # layout.dim: empty sequence
        layout.add("I", 4)  # layout.data_offset
        layout.add("I", 4)  # data length
        if size:
            layout.add("d", 8, size)
        self._size = size
        self._struct = layout.compile()

    def encode(self, values: np.ndarray) -> bytes:
        """CDR bytes of ``values``, shape (size,)."""
        return self._struct.pack(_CDR_LE, 0, 0, self._size, *values.tolist())


def problem_kind(reason: str) -> str:
    """A short class of a rejection reason (``frame``, ``finite``, ``quaternion``, ``length``, ``other``).

    Log throttling keys on it, so one kind of bad message cannot hide another.
    """
    if "frame_id" in reason:
        return "frame"
    if "NaN" in reason:
        return "finite"
    if "quaternion" in reason:
        return "quaternion"
    if "values; valid" in reason or "names but" in reason or "lacks joints" in reason:
        return "length"
    return "other"


# --- decoding the 1 kHz inputs from their CDR bytes ---------------------------------------------


def _align(offset: int, size: int) -> int:
    return offset + (-offset) % size


class JointStateDecoder:
    """Model-order positions from serialised ``JointState`` bytes (``take_message(raw=True)``).

    Building the Python message costs ~30 µs per ``JointState``; a driver sends the same
    names in the same order every time, so after the first message the decoder checks
    that the header's frame id and the names are byte-identical to the learned ones and
    reads the positions straight from the buffer. Anything else (other names or order,
    other frame id) goes through ``deserialize_message`` and :class:`JointStateMapper`.

    Args:
        joint_names: the model's joint names in model order.
    """

    def __init__(self, joint_names: Sequence[str]):
        from sensor_msgs.msg import JointState as _JointState

        self._msg_type = _JointState
        self._mapper = JointStateMapper(joint_names)
        self._count = len(joint_names)
        self._blob: bytes | None = None
        self._count_at = 0
        self._values_at = 0

    def positions(self, data: bytes) -> np.ndarray:
        """Positions in model order, shape (n,); :class:`InvalidMessageError` as :class:`JointStateMapper`."""
        blob = self._blob
        if blob is not None and data[12 : 12 + len(blob)] == blob:
            (count,) = struct.unpack_from("<I", data, self._count_at)
            if count == self._count and len(data) >= self._values_at + 8 * count:
                values = np.frombuffer(data, dtype="<f8", count=count, offset=self._values_at).copy()
                if not np.all(np.isfinite(values)):
                    raise InvalidMessageError("joint state positions contain NaN or infinity; valid: finite numbers")
                return values
        from rclpy.serialization import deserialize_message

        msg = deserialize_message(data, self._msg_type)
        values = self._mapper.positions(msg)
        if list(msg.name) == self._mapper.joint_names and len(msg.position) == self._count:
            self._learn(data)
        return values

    def _learn(self, data: bytes) -> None:
        # Payload offsets (after the 4-byte encapsulation): stamp 0..8, frame_id at 8.
        (frame_length,) = struct.unpack_from("<I", data, 4 + 8)
        offset = _align(8 + 4 + frame_length, 4)
        (name_count,) = struct.unpack_from("<I", data, 4 + offset)
        offset += 4
        for _ in range(name_count):
            offset = _align(offset, 4)
            (length,) = struct.unpack_from("<I", data, 4 + offset)
            offset += 4 + length
        self._blob = bytes(data[12 : 4 + offset])
        count_offset = _align(offset, 4)
        self._count_at = 4 + count_offset
        self._values_at = 4 + _align(count_offset + 4, 8)


def decode_float64_array(data: bytes) -> np.ndarray:
    """The ``data`` of serialised ``Float64MultiArray`` bytes as a float64 vector (a copy)."""
    (dimensions,) = struct.unpack_from("<I", data, 4)
    if dimensions == 0 and len(data) >= 16:
        (count,) = struct.unpack_from("<I", data, 12)
        if len(data) >= 20 + 8 * count:
            return np.frombuffer(data, dtype="<f8", count=count, offset=20).copy() if count else np.zeros(0)
    from rclpy.serialization import deserialize_message

    return np.array(deserialize_message(data, Float64MultiArray).data, dtype=float)
