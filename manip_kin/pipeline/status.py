"""Names and statuses of a pipeline's nodes in ``/diagnostics`` (no rclpy here)."""

from __future__ import annotations

from dataclasses import dataclass

from manip_kin.errors import InvalidArgumentError


def normalize_namespace(namespace: str | None) -> str:
    """``"left"``, ``"/left/"`` → ``"/left"``; ``""``, ``"/"``, None → ``""`` (the root namespace).

    Raises:
        InvalidArgumentError: not a valid ROS namespace (letters, digits, ``_`` and ``/``;
            no token starting with a digit, no ``//``).
    """
    text = (namespace or "").strip().strip("/")
    if not text:
        return ""
    tokens = text.split("/")
    for token in tokens:
        if not token or token[0].isdigit() or not all(c.isalnum() or c == "_" for c in token) or not token.isascii():
            raise InvalidArgumentError(
                f"namespace {namespace!r} is not a valid ROS namespace; valid: names of letters, digits and _ "
                "separated by /, each not starting with a digit (e.g. /left or /cell1/arm)"
            )
    return "/" + "/".join(tokens)


def status_name(node_name: str, namespace: str = "") -> str:
    """The ``/diagnostics`` status name of node ``node_name`` in ``namespace``.

    Nodes name their status by their fully qualified name without the leading slash:
    ``cartesian_controller`` in the root namespace, ``left/cartesian_controller`` in
    ``/left``. A ``node_name`` that already holds a ``/`` is taken as fully qualified.
    """
    if "/" in node_name.strip("/"):
        return node_name.strip("/")
    return f"{normalize_namespace(namespace)}/{node_name}".lstrip("/")


@dataclass(frozen=True)
class Status:
    """One ``DiagnosticStatus`` as received.

    Attributes:
        name: status name (the node name).
        message: its message (the node's state).
        values: key/value pairs.
        received_ns: receive time, ``time.monotonic_ns()``.
        stamp_ns: the ``DiagnosticArray``'s header stamp: when the node published it, on the
            ROS clock [ns] (0: unstamped).
    """

    name: str
    message: str
    values: dict
    received_ns: int
    stamp_ns: int = 0

    def number(self, key: str) -> float:
        """A value as a float (NaN when empty or missing)."""
        text = self.values.get(key, "")
        try:
            return float(text)
        except ValueError:
            return float("nan")
