"""Builders of ``diagnostic_msgs`` statuses, the way every node reports on ``/diagnostics``.

The nodes publish their status as CDR bytes built here (:func:`diagnostic_array_cdr`): building
the messages and letting rclpy serialise them took ~0.45 ms of a 1 ms cycle, and the cycle that
reported came late (docs/performance_limits.md). :func:`make_diagnostic_status` and
:func:`make_diagnostic_array` build the same as messages, for clients and tests.
"""

from __future__ import annotations

import struct

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from manip_kin.cdr import CdrWriter

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


_LEVEL = struct.Struct("<c")


def diagnostic_array_cdr(stamp_ns: int, name: str, level: str, message: str, hardware_id: str, values) -> bytes:
    """The serialised ``DiagnosticArray`` (empty frame_id) of one status: what rclpy makes of
    ``make_diagnostic_array(stamp, [make_diagnostic_status(name, level, message, hardware_id, values)])``,
    but with zero padding bytes (rclpy leaves them unset).

    Args:
        stamp_ns: the header's stamp [ns, ROS clock].
        name, level, message, hardware_id, values: as :func:`make_diagnostic_status`.
    """
    writer = CdrWriter()
    writer.stamp(stamp_ns)
    writer.string("")  # header.frame_id
    writer.count(1)  # one status
    writer.pack(_LEVEL, DIAGNOSTIC_LEVELS[level], alignment=1)
    writer.strings((name, message, hardware_id))
    pairs = [(str(key), str(value)) for key, value in values]
    writer.count(len(pairs))
    writer.strings([text for pair in pairs for text in pair])
    return writer.bytes()


def diagnostic_values(status: DiagnosticStatus) -> dict[str, str]:
    """The key/value pairs of a ``DiagnosticStatus`` as a dict."""
    return {kv.key: kv.value for kv in status.values}
