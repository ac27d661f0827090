"""When a node's status is due, and the checks its supervisors' settings share."""

from __future__ import annotations

import math

from manip_kin.errors import InvalidArgumentError

#: A state change is reported at once, but at most this often [ns]: near a limit the state
#: can flicker cycle to cycle, and a status costs ~0.2 ms to build.
MIN_CHANGE_REPORT_INTERVAL_NS = 20_000_000


class StatusThrottle:
    """When a status is due: every ``period_ns``, and on a state change at most every 20 ms.

    A change is compared with the last *reported* state, so a change that came too soon
    after the previous report goes out as soon as the 20 ms have passed, not at the next
    periodic report.

    Args:
        period_ns: period of the regular report [ns], > 0.
        min_change_interval_ns: shortest time between two reports caused by changes [ns].
    """

    def __init__(self, period_ns: int, min_change_interval_ns: int = MIN_CHANGE_REPORT_INTERVAL_NS):
        if not period_ns > 0:
            raise InvalidArgumentError(f"status period {period_ns} ns; valid: > 0")
        self.period_ns = int(period_ns)
        self.min_change_interval_ns = int(min_change_interval_ns)
        self._last_ns: int | None = None
        self._reported: str | None = None

    def due(self, now_ns: int, state: str) -> bool:
        """True when a status should be published now (and then counts it as published)."""
        if self._last_ns is not None:
            since = now_ns - self._last_ns
            if since < self.period_ns and (state == self._reported or since < self.min_change_interval_ns):
                return False
        self._last_ns = now_ns
        self._reported = state
        return True


def check_seconds(name: str, value: float, allow_zero: bool = False) -> None:
    """Refuse ``value`` [s] for setting ``name`` unless finite and > 0 (>= 0 with ``allow_zero``)."""
    if not (math.isfinite(value) and (value >= 0.0 if allow_zero else value > 0.0)):
        raise InvalidArgumentError(f"{name} = {value!r}; valid: a finite number {'>= 0' if allow_zero else '> 0'} [s]")
