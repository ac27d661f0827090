"""Log lines throttled per kind of problem, through a path that cannot raise.

Two rclpy pitfalls shape this module:

* rclpy keys its logging context on the *call site* (file, line, instruction) and raises
  ``ValueError: Logger severity cannot be changed between calls`` when one call site logs
  at two severities. A helper that forwards to ``logger.warning`` for one caller and to
  ``logger.error`` for another is exactly that, and it once ended a node's loop thread
  from inside its error handler. Here every severity has its own call site
  (:func:`_emit_warning`, :func:`_emit_error`, ...), whoever calls.
* ``throttle_duration_sec`` throttles per call site, which would hide a second kind of
  problem reported from the same place; :class:`ThrottledLog` keys on a ``kind`` string.

Whatever goes wrong while logging (a shut-down context, a closed stream) is swallowed
after one best-effort line on stderr: a log line must never end the caller.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

#: Kinds remembered at most; the oldest is forgotten first (kinds built from exception
#: messages could otherwise grow the table without bound over a long run).
MAX_KINDS = 256


def _emit_debug(logger, line: str) -> None:
    logger.debug(line)


def _emit_info(logger, line: str) -> None:
    logger.info(line)


def _emit_warning(logger, line: str) -> None:
    logger.warning(line)


def _emit_error(logger, line: str) -> None:
    logger.error(line)


def _emit_fatal(logger, line: str) -> None:
    logger.fatal(line)


_EMITTERS = {
    "debug": _emit_debug,
    "info": _emit_info,
    "warn": _emit_warning,
    "warning": _emit_warning,
    "error": _emit_error,
    "fatal": _emit_fatal,
}


def _stderr_line(line: str) -> None:
    try:
        os.write(2, (line.rstrip("\n") + "\n").encode(errors="replace"))
    except Exception:  # noqa: BLE001 - nowhere left to report to
        pass


def _resolve(log) -> Callable[[str], None]:
    """A callable writing one line; bound rclpy logger methods go through :data:`_EMITTERS`."""
    logger = getattr(log, "__self__", None)
    name = getattr(log, "__name__", "")
    if logger is not None and hasattr(logger, "get_effective_level") and name in _EMITTERS:
        emitter = _EMITTERS[name]
        return lambda line: emitter(logger, line)
    return log


def safe_log(log, line: str) -> None:
    """Write ``line`` with ``log`` (e.g. ``node.get_logger().error``); never raises."""
    try:
        _resolve(log)(line)
    except Exception as error:  # noqa: BLE001 - logging must not end the caller
        _stderr_line(f"{line} [logging failed: {type(error).__name__}: {error}]")


class ThrottledLog:
    """Rate-limits repeated log lines per kind of problem, counting what it held back.

    Args:
        log: the function to call with the line, e.g. ``node.get_logger().warning`` (a
            bound rclpy logger method is routed to a call site of its own severity), or
            any ``callable(str)``.
        interval: seconds between two lines of the same kind.

    Calling it never raises: a failing ``log`` falls back to one line on stderr.
    """

    def __init__(self, log, interval: float = 1.0):
        self._log = _resolve(log)
        self._interval_ns = int(interval * 1e9)
        self._last_ns: dict[str, int] = {}
        self._held: dict[str, int] = {}

    def __call__(self, kind: str, line: str) -> bool:
        """Log ``line`` unless a line of ``kind`` was logged less than ``interval`` ago.

        Returns:
            True when the line was written, False when it was held back.
        """
        try:
            now = time.monotonic_ns()
            last = self._last_ns.get(kind)
            if last is not None and now - last < self._interval_ns:
                self._held[kind] = self._held.get(kind, 0) + 1
                return False
            held = self._held.pop(kind, 0)
            if last is None and len(self._last_ns) >= MAX_KINDS:
                oldest = min(self._last_ns, key=self._last_ns.__getitem__)
                del self._last_ns[oldest]
                self._held.pop(oldest, None)
            self._last_ns[kind] = now
            text = line + (f" ({held} more like this since the last report)" if held else "")
        except Exception as error:  # noqa: BLE001 - bookkeeping must not end the caller
            _stderr_line(f"{line} [throttling failed: {type(error).__name__}: {error}]")
            return True
        try:
            self._log(text)
        except Exception as error:  # noqa: BLE001 - logging must not end the caller
            _stderr_line(f"{text} [logging failed: {type(error).__name__}: {error}]")
        return True
