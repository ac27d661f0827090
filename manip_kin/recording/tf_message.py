"""``tf2_msgs/msg/TFMessage`` as CDR bytes, written without the ``tf2_msgs`` Python package.

``tf2_msgs`` is not on PyPI, so recordings made here encode ``/tf`` and ``/tf_static``
themselves: XCDR1 little endian, as Fast DDS writes it (``uint32`` count, then per
``geometry_msgs/TransformStamped`` the header stamp and frame ids as NUL-terminated
strings with a ``uint32`` length, and seven ``float64`` aligned to 8 bytes relative to
the end of the 4-byte encapsulation header). The schema comes from
:data:`manip_kin.recording.msgdef.BUNDLED_MSG_TEXTS` when the package is not installed.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from manip_kin.core.tf_tree import LinkTransform
from manip_kin.recording.qos import OfferedProfiles, default_offer

TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"

_ENCAPSULATION_LE = b"\x00\x01\x00\x00"
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_SEVEN_DOUBLES = struct.Struct("<7d")


def tf_message_class():
    """``tf2_msgs.msg.TFMessage`` where it imports (a ROS install), else None."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


def tf_offer(static: bool) -> OfferedProfiles:
    """What tf2_ros's broadcasters offer: ``/tf`` reliable, volatile, depth 100;
    ``/tf_static`` reliable, transient local, depth 1."""
    return default_offer(transient_local=static, depth=1 if static else 100)


def _align(position: int, size: int) -> int:
    return (position + size - 1) & ~(size - 1)


def _append_string(body: bytearray, text: str) -> None:
    encoded = text.encode("utf-8") + b"\x00"
    body.extend(b"\x00" * (_align(len(body), 4) - len(body)))
    body.extend(_U32.pack(len(encoded)))
    body.extend(encoded)


def encode_tf_message(stamp_ns: int, transforms: Sequence[LinkTransform]) -> bytes:
    """CDR bytes of a TFMessage whose every transform is stamped ``stamp_ns`` [ns since epoch]."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    body = bytearray(_U32.pack(len(transforms)))  # positions count from here (after encapsulation)
    for transform in transforms:
        body.extend(b"\x00" * (_align(len(body), 4) - len(body)))
        body.extend(_STAMP.pack(sec, nanosec))
        _append_string(body, transform.parent)
        _append_string(body, transform.child)
        body.extend(b"\x00" * (_align(len(body), 8) - len(body)))
        x, y, z = (float(v) for v in transform.translation)
        qx, qy, qz, qw = (float(v) for v in transform.rotation_xyzw)
        body.extend(_SEVEN_DOUBLES.pack(x, y, z, qx, qy, qz, qw))
    return _ENCAPSULATION_LE + bytes(body)


def decode_tf_message(data: bytes) -> list[tuple[int, LinkTransform]]:
    """``[(stamp_ns, transform), ...]`` of a TFMessage in CDR (little or big endian).

    Raises:
        ValueError: when ``data`` is not a TFMessage in plain CDR.
    """
    import numpy as np

    if len(data) < 8 or data[0] != 0 or data[1] > 1:
        raise ValueError("not a plain CDR buffer")
    order = "<" if data[1] == 1 else ">"
    body = memoryview(data)[4:]
    position = 0

    def read(fmt: str, size: int, align: int):
        nonlocal position
        position = _align(position, align)
        values = struct.unpack_from(order + fmt, body, position)
        position += size
        return values

    def read_string() -> str:
        nonlocal position
        (length,) = read("I", 4, 4)
        text = bytes(body[position : position + length - 1]).decode("utf-8")
        position += length
        return text

    (count,) = read("I", 4, 4)
    result = []
    for _ in range(count):
        sec, nanosec = read("iI", 8, 4)
        parent = read_string()
        child = read_string()
        x, y, z, qx, qy, qz, qw = read("7d", 56, 8)
        transform = LinkTransform(parent, child, np.array([x, y, z]), np.array([qx, qy, qz, qw]))
        result.append((sec * 1_000_000_000 + nanosec, transform))
    return result
