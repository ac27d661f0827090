"""Builders of ``diagnostic_msgs`` statuses, the way every node reports on ``/diagnostics``."""

from __future__ import annotations

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

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
