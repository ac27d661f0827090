"""Pre-serialised (CDR) messages for the 1 kHz loops, and decoders of the 1 kHz inputs.

rclpy converts a Python message to C field by field (~10 µs for a PoseStamped) before
serialising it; publishing bytes that are already CDR skips both and halves the cost of a
publish. The encoders write the little-endian CDR (XCDR1, what rmw_fastrtps and
rmw_cyclonedds exchange) of the few fixed-shape messages the loops publish, into one
precompiled ``struct.Struct`` each; the tests check every one against
``rclpy.serialization.serialize_message``. The decoders read the inputs that arrive every
cycle straight from their bytes, falling back to ``deserialize_message`` for anything
unusual.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from std_msgs.msg import Float64MultiArray

from manip_kin.cdr import CDR_LE, CdrLayout, align, stamp_parts
from manip_kin.core.rotations import matrix_to_quat, quaternion_from_entries
from manip_kin.errors import ProblemKind
from manip_kin.ros.wire.validation import InvalidMessageError, JointStateMapper

_NS_PER_S = 1_000_000_000


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
        layout = CdrLayout()
        self._frame = layout.header(frame_id)
        self._frame_length = len(self._frame)
        layout.add("d", 8, 7)
        self._struct = layout.compile()

    def encode(self, stamp_ns: int, matrix: np.ndarray) -> bytes:
        """CDR bytes of the pose ``matrix`` (4x4) stamped ``stamp_ns`` [ns since epoch]."""
        sec, nanosec = stamp_parts(stamp_ns)
        qx, qy, qz, qw = matrix_to_quat(matrix[:3, :3]).tolist()
        x, y, z = matrix[:3, 3].tolist()
        return self._struct.pack(CDR_LE, sec, nanosec, self._frame_length, self._frame, x, y, z, qx, qy, qz, qw)

    def encode_values(self, stamp_ns: int, values) -> bytes:
        """CDR bytes of a pose given as 16 row-major floats (the unrolled kinematics' output)."""
        sec, nanosec = stamp_parts(stamp_ns)
        qx, qy, qz, qw = quaternion_of_pose_values(values)
        return self._struct.pack(
            CDR_LE, sec, nanosec, self._frame_length, self._frame, values[3], values[7], values[11], qx, qy, qz, qw
        )


class TwistStampedCdr:
    """Serialised ``geometry_msgs/TwistStamped`` with a fixed frame id."""

    def __init__(self, frame_id: str):
        layout = CdrLayout()
        self._frame = layout.header(frame_id)
        self._frame_length = len(self._frame)
        layout.add("d", 8, 6)
        self._struct = layout.compile()

    def encode(self, stamp_ns: int, angular: np.ndarray, linear: np.ndarray) -> bytes:
        """CDR bytes of ``linear`` [m/s] and ``angular`` [rad/s] velocity stamped ``stamp_ns``."""
        sec, nanosec = stamp_parts(stamp_ns)
        return self._struct.pack(
            CDR_LE, sec, nanosec, self._frame_length, self._frame, *linear.tolist(), *angular.tolist()
        )

    def encode_values(self, stamp_ns: int, twist) -> bytes:
        """CDR bytes of a twist given as 6 floats ``(wx, wy, wz, vx, vy, vz)``."""
        sec, nanosec = stamp_parts(stamp_ns)
        wx, wy, wz, vx, vy, vz = twist
        return self._struct.pack(CDR_LE, sec, nanosec, self._frame_length, self._frame, vx, vy, vz, wx, wy, wz)


class JointStateCdr:
    """Serialised ``sensor_msgs/JointState`` with fixed names, positions, velocities and optional efforts.

    Args:
        names: joint names, model order.
        frame_id: the header's frame id (empty for joint states, as robot drivers send them).
        with_effort: True: the message carries ``effort`` (n values, a physics plant's joint
            torques/forces [N·m | N]); False: ``effort`` is empty (a kinematic plant has none).
    """

    def __init__(self, names: Sequence[str], frame_id: str = "", with_effort: bool = False):
        layout = CdrLayout()
        self._frame = layout.header(frame_id)
        self._frame_length = len(self._frame)
        layout.add("I", 4)
        self._names: list[object] = [len(names)]
        for name in names:
            data = layout.add_string(name)
            self._names += [len(data), data]
        count = len(names)
        for _ in range(3 if with_effort else 2):  # position, velocity (, effort)
            layout.add("I", 4)
            if count:
                layout.add("d", 8, count)
        if not with_effort:
            layout.add("I", 4)  # effort: empty
        self._count = count
        self._with_effort = with_effort
        self._struct = layout.compile()

    def encode(
        self, stamp_ns: int, position: np.ndarray, velocity: np.ndarray, effort: np.ndarray | None = None
    ) -> bytes:
        """CDR bytes of ``position``, ``velocity`` (and ``effort`` when built with it), shape (n,), stamped ``stamp_ns``."""
        return self.encode_values(
            stamp_ns, position.tolist(), velocity.tolist(), None if effort is None else effort.tolist()
        )

    def encode_values(self, stamp_ns: int, position, velocity, effort=None) -> bytes:
        """CDR bytes of positions, velocities (and efforts when built with them) as float sequences of length n."""
        sec, nanosec = stamp_parts(stamp_ns)
        n = self._count
        if self._with_effort:
            return self._struct.pack(
                CDR_LE,
                sec,
                nanosec,
                self._frame_length,
                self._frame,
                *self._names,
                n,
                *position,
                n,
                *velocity,
                n,
                *effort,
            )
        return self._struct.pack(
            CDR_LE, sec, nanosec, self._frame_length, self._frame, *self._names, n, *position, n, *velocity, 0
        )


class Float64ArrayCdr:
    """Serialised ``std_msgs/Float64MultiArray`` of ``size`` values with an empty layout."""

    def __init__(self, size: int):
        layout = CdrLayout()
        layout.add("I", 4)  # layout.dim: empty sequence
        layout.add("I", 4)  # layout.data_offset
        layout.add("I", 4)  # data length
        if size:
            layout.add("d", 8, size)
        self._size = size
        self._struct = layout.compile()

    def encode(self, values: np.ndarray | list[float]) -> bytes:
        """CDR bytes of ``values``, shape (size,) (an array, or a list of floats)."""
        return self._struct.pack(
            CDR_LE, 0, 0, self._size, *(values.tolist() if isinstance(values, np.ndarray) else values)
        )


# --- decoding the 1 kHz inputs from their CDR bytes ---------------------------------------------


class JointStateSample(NamedTuple):
    """One decoded joint state, in model order.

    Attributes:
        positions: [rad | m], shape (n,), checked (finite, within the accepted ranges).
        velocities: [rad/s | m/s], shape (n,), or None when the message has none for every
            joint (velocities are not checked here: see their use).
        stamp_ns: the header stamp [ns].
    """

    positions: np.ndarray
    velocities: np.ndarray | None
    stamp_ns: int


class JointStateDecoder:
    """Model-order positions (and velocities, stamp) from serialised ``JointState`` bytes
    (``take_message(raw=True)``).

    Building the Python message costs ~30 µs per ``JointState``; a driver sends the same
    names in the same order every time, so after the first message the decoder checks
    that the header's frame id and the names are byte-identical to the learned ones and
    reads the positions and velocities straight from the buffer. Anything else (other
    names or order, other frame id) goes through ``deserialize_message`` and
    :class:`JointStateMapper`.

    Args:
        joint_names: the model's joint names in model order.
        lower, upper: accepted position range per joint (see :class:`JointStateMapper`).
    """

    def __init__(self, joint_names: Sequence[str], lower=None, upper=None):
        from sensor_msgs.msg import JointState as _JointState

        self._msg_type = _JointState
        self._mapper = JointStateMapper(joint_names, lower, upper)
        self._count = len(joint_names)
        self._blob: bytes | None = None
        self._count_at = 0
        self._values_at = 0
        self._velocity_count_at = 0
        self._velocity_values_at = 0
        # The learned layout's hot path reads plain floats with one struct unpack (a cold cache
        # at 1 kHz makes every numpy call on a handful of values cost several µs).
        self._values = struct.Struct(f"<{self._count}d")

    def positions(self, data: bytes) -> np.ndarray:
        """Positions in model order, shape (n,); :class:`InvalidMessageError` as :class:`JointStateMapper`."""
        return self.sample(data).positions

    def sample(self, data: bytes) -> JointStateSample:
        """Positions, velocities and stamp; :class:`InvalidMessageError` as :class:`JointStateMapper`."""
        blob = self._blob
        if blob is not None and data[12 : 12 + len(blob)] == blob and len(data) >= self._count_at + 4:
            count = struct.unpack_from("<I", data, self._count_at)[0]
            if count == self._count and len(data) >= self._velocity_count_at + 4:
                positions = self._mapper.checked_values(self._values.unpack_from(data, self._values_at))
                velocities = None
                if struct.unpack_from("<I", data, self._velocity_count_at)[0] == count and len(data) >= (
                    self._velocity_values_at + 8 * count
                ):
                    velocities = np.array(self._values.unpack_from(data, self._velocity_values_at))
                sec, nanosec = struct.unpack_from("<iI", data, 4)
                return JointStateSample(positions, velocities, sec * _NS_PER_S + nanosec)
        msg = _deserialize(data, self._msg_type, "joint state")
        positions = self._mapper.positions(msg)
        velocities = self._mapper.velocities(msg)
        if list(msg.name) == self._mapper.joint_names and len(msg.position) == self._count:
            self._learn(data)
        return JointStateSample(positions, velocities, msg.header.stamp.sec * _NS_PER_S + msg.header.stamp.nanosec)

    def _learn(self, data: bytes) -> None:
        # Payload offsets (after the 4-byte encapsulation): stamp 0..8, frame_id at 8.
        (frame_length,) = struct.unpack_from("<I", data, 4 + 8)
        offset = align(8 + 4 + frame_length, 4)
        (name_count,) = struct.unpack_from("<I", data, 4 + offset)
        offset += 4
        for _ in range(name_count):
            offset = align(offset, 4)
            (length,) = struct.unpack_from("<I", data, 4 + offset)
            offset += 4 + length
        self._blob = bytes(data[12 : 4 + offset])
        count_offset = align(offset, 4)
        values_offset = align(count_offset + 4, 8)
        velocity_count_offset = values_offset + 8 * self._count  # 8-aligned, so 4-aligned
        self._count_at = 4 + count_offset
        self._values_at = 4 + values_offset
        self._velocity_count_at = 4 + velocity_count_offset
        self._velocity_values_at = 4 + align(velocity_count_offset + 4, 8)


class _Time(NamedTuple):
    sec: int
    nanosec: int


class _Header(NamedTuple):
    stamp: _Time
    frame_id: str


class _Point(NamedTuple):
    x: float
    y: float
    z: float


class _Quaternion(NamedTuple):
    x: float
    y: float
    z: float
    w: float


class _Pose(NamedTuple):
    position: _Point
    orientation: _Quaternion


class DecodedPoseStamped(NamedTuple):
    """A ``PoseStamped`` read straight from its bytes, with the message's attribute paths
    (``header.stamp.sec``, ``header.frame_id``, ``pose.position.x``, ``pose.orientation.w``...)
    so that the checks and conversions of a message apply to it unchanged."""

    header: _Header
    pose: _Pose


_STAMP_AND_STRING_LENGTH = struct.Struct("<iII")  # header.stamp, then the frame id's length
_POSE_VALUES = struct.Struct("<7d")  # position x y z, orientation x y z w


def decode_pose_stamped(data: bytes, what: str = "goal pose"):
    """The ``PoseStamped`` of CDR bytes (``take(raw=True)``), without building the rclpy message.

    A goal wakes the controller's loop, and rclpy's conversion of the bytes into a Python
    ``PoseStamped`` (six message objects, each field set through a checked property) was the
    largest part of the woken cycle (~0.1 ms of a ~0.25 ms reaction at 1 kHz). Well-formed
    bytes are read with two ``struct`` unpacks into a :class:`DecodedPoseStamped`; anything
    else goes through ``deserialize_message`` (the rclpy message, or
    :class:`InvalidMessageError` naming ``what`` for bytes that do not decode).
    """
    if len(data) >= 16 and data[:4] == CDR_LE:
        sec, nanosec, length = _STAMP_AND_STRING_LENGTH.unpack_from(data, 4)
        values_at = 4 + align(12 + length, 8)
        # A CDR string: its length counts the terminating NUL, which must be there.
        if length >= 1 and len(data) >= values_at + _POSE_VALUES.size and data[16 + length - 1] == 0:
            try:
                frame_id = data[16 : 16 + length - 1].decode()
            except UnicodeDecodeError:
                frame_id = "\0"  # not ours to judge: deserialize_message says what it makes of it
            if "\0" not in frame_id:
                x, y, z, qx, qy, qz, qw = _POSE_VALUES.unpack_from(data, values_at)
                return DecodedPoseStamped(
                    _Header(_Time(sec, nanosec), frame_id), _Pose(_Point(x, y, z), _Quaternion(qx, qy, qz, qw))
                )
    from geometry_msgs.msg import PoseStamped

    return _deserialize(data, PoseStamped, what)


def decode_float64_array(data: bytes) -> np.ndarray:
    """The ``data`` of serialised ``Float64MultiArray`` bytes as a float64 vector (a copy)."""
    dimensions = struct.unpack_from("<I", data, 4)[0] if len(data) >= 8 else 1
    if dimensions == 0 and len(data) >= 16:
        (count,) = struct.unpack_from("<I", data, 12)
        if len(data) >= 20 + 8 * count:
            return np.frombuffer(data, dtype="<f8", count=count, offset=20).copy() if count else np.zeros(0)
    return np.array(_deserialize(data, Float64MultiArray, "joint velocity command").data, dtype=float)


def _deserialize(data: bytes, msg_type, what: str):
    """``deserialize_message``, with undecodable bytes as :class:`InvalidMessageError`."""
    from rclpy.serialization import deserialize_message

    try:
        return deserialize_message(data, msg_type)
    except Exception as error:  # noqa: BLE001 - whatever the C layer raises for bad bytes
        raise InvalidMessageError(
            f"{what} bytes cannot be decoded ({type(error).__name__}); valid: CDR of {msg_type.__name__}",
            kind=ProblemKind.OTHER,
        ) from None
