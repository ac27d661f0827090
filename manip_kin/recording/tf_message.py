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

from manip_kin.cdr import CdrReader, CdrWriter
from manip_kin.core.tf_tree import LinkTransform
from manip_kin.recording.qos import OfferedProfiles, default_offer

TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"

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


def encode_tf_message(stamp_ns: int, transforms: Sequence[LinkTransform]) -> bytes:
    """CDR bytes of a TFMessage whose every transform is stamped ``stamp_ns`` [ns since epoch]."""
    writer = CdrWriter()
    writer.count(len(transforms))
    for transform in transforms:
        writer.stamp(stamp_ns)
        writer.string(transform.parent)
        writer.string(transform.child)
        x, y, z = (float(v) for v in transform.translation)
        qx, qy, qz, qw = (float(v) for v in transform.rotation_xyzw)
        writer.pack(_SEVEN_DOUBLES, x, y, z, qx, qy, qz, qw, alignment=8)
    return writer.bytes()


def decode_tf_message(data: bytes) -> list[tuple[int, LinkTransform]]:
    """``[(stamp_ns, transform), ...]`` of a TFMessage in CDR (little or big endian).

    Raises:
        ValueError: when ``data`` is not a TFMessage in plain CDR.
    """
    import numpy as np

    reader = CdrReader(data)
    (count,) = reader.read("I", 4, 4)
    result = []
    for _ in range(count):
        sec, nanosec = reader.read("iI", 8, 4)
        parent = reader.string()
        child = reader.string()
        x, y, z, qx, qy, qz, qw = reader.read("7d", 56, 8)
        transform = LinkTransform(parent, child, np.array([x, y, z]), np.array([qx, qy, qz, qw]))
        result.append((sec * 1_000_000_000 + nanosec, transform))
    return result
