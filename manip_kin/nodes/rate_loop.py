"""The fixed-rate loop every manip_kin node runs, and subscriptions that loop polls.

Why not an rclpy timer: measured here, an *empty* rclpy timer callback at 1 kHz costs
about 42 % of a core (the Python executor rebuilds its wait set on every wake-up), and
each subscription callback costs another wake-up; a node with one timer and two
subscriptions used ~80 % of a core at 1 kHz. A plain thread sleeping to absolute
deadlines costs ~4 % at 1 kHz with the same period jitter, so each node runs its
cycle in one :class:`RateLoop` thread, and the topics the cycle consumes are
:class:`PolledSubscription` s that the loop drains at the start of each cycle instead
of executor callbacks. The executor in the main thread (``run_node``) still serves
everything else: parameter services, other subscriptions, shutdown.

Design notes:
    * deadlines are absolute (``start + k · period``) so the average rate is exact; a
      cycle that starts more than half a period late re-anchors the schedule instead of
      running the missed cycles back to back (like an rclpy timer, it skips them);
    * timing statistics (periods, compute times) go into preallocated ring buffers and
      are summarised on demand (:meth:`RateLoop.stats`) for ``/diagnostics``.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile


class _NeverExecutedGroup(CallbackGroup):
    """A callback group the executor never waits on: its entities are polled by hand."""

    def can_execute(self, entity) -> bool:  # noqa: D102 - rclpy API
        return False

    def beginning_execution(self, entity) -> bool:  # noqa: D102 - rclpy API
        return False

    def ending_execution(self, entity) -> None:  # noqa: D102 - rclpy API
        return None


class PolledSubscription:
    """A subscription read with :meth:`take` from the loop thread, not by the executor.

    Args:
        node: the node that owns it.
        msg_type: message class.
        topic: topic name (remappable like any other).
        qos: QoS profile or depth.
    """

    def __init__(self, node: Node, msg_type, topic: str, qos: QoSProfile | int = 10):
        self._subscription = node.create_subscription(
            msg_type, topic, _ignore, qos, callback_group=_NeverExecutedGroup()
        )
        self._msg_type = msg_type

    @property
    def subscription(self):
        """The underlying rclpy subscription (topic name, publisher count)."""
        return self._subscription

    def take(self, raw: bool = False):
        """The oldest unread message (its CDR ``bytes`` with ``raw``), or None. Never blocks."""
        handle = self._subscription.handle
        with handle:
            taken = handle.take_message(self._msg_type, raw)
        return None if taken is None else taken[0]


def _ignore(_msg) -> None:
    return None


@dataclass(frozen=True)
class LoopStats:
    """Timing of the recent cycles of a :class:`RateLoop` (window of ``samples`` cycles).

    Attributes:
        target_rate_hz: configured rate [Hz].
        rate_hz: achieved rate over the window [Hz].
        period_error_p99_ms: 99th percentile of ``|period - nominal|`` [ms].
        period_error_max_ms: largest ``|period - nominal|`` [ms].
        compute_mean_ms: mean time spent in the cycle function [ms].
        compute_p99_ms: 99th percentile of that time [ms].
        cycles: cycles run since start.
        overruns: cycles whose schedule had to be re-anchored (started > half a period late).
        errors: cycles whose function raised.
        samples: number of periods in the window.
    """

    target_rate_hz: float
    rate_hz: float
    period_error_p99_ms: float
    period_error_max_ms: float
    compute_mean_ms: float
    compute_p99_ms: float
    cycles: int
    overruns: int
    errors: int
    samples: int


class RateLoop:
    """Calls ``cycle(now_ns)`` every ``1 / rate_hz`` seconds in a dedicated thread.

    Args:
        rate_hz: cycle rate [Hz], > 0.
        cycle: the work of one cycle; receives ``time.monotonic_ns()`` at its start.
        on_error: called with the exception when ``cycle`` raises (the loop goes on).
        name: thread name.
        window: number of cycles kept for :meth:`stats`.
        realtime_priority: SCHED_FIFO priority (1..99) of the loop thread, or 0 for normal
            scheduling. Needs CAP_SYS_NICE (root); without it the loop runs normally and
            :attr:`realtime_error` says why.
    """

    def __init__(
        self,
        rate_hz: float,
        cycle: Callable[[int], None],
        on_error: Callable[[BaseException], None] | None = None,
        name: str = "rate_loop",
        window: int = 4096,
        realtime_priority: int = 0,
    ):
        if not rate_hz > 0:
            raise ValueError(f"rate_hz = {rate_hz}; valid: > 0")
        self.rate_hz = float(rate_hz)
        self.period_ns = int(round(1e9 / rate_hz))
        self._cycle = cycle
        self._on_error = on_error
        self._name = name
        self._periods_ns = np.zeros(window, dtype=np.int64)
        self._compute_ns = np.zeros(window, dtype=np.int64)
        self._count = 0
        self._overruns = 0
        self._errors = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.realtime_priority = int(realtime_priority)
        self.realtime_error = ""

    def start(self) -> None:
        """Start the loop thread (idempotent)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 1.0) -> None:
        """Ask the loop to stop and wait for the current cycle to finish."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    @property
    def running(self) -> bool:
        """True while the loop thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def _set_priority(self) -> None:
        if self.realtime_priority <= 0:
            return
        try:
            # Applies to the calling thread only (Linux): the executor thread keeps its priority.
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.realtime_priority))
        except (OSError, AttributeError) as error:
            self.realtime_error = f"SCHED_FIFO priority {self.realtime_priority} not set: {error}"

    def _run(self) -> None:
        self._set_priority()
        period = self.period_ns
        window = self._periods_ns.shape[0]
        stop = self._stop
        sleep = time.sleep
        clock = time.monotonic_ns
        deadline = clock() + period
        last_start = 0
        while not stop.is_set():
            remaining = deadline - clock()
            if remaining > 0:
                sleep(remaining * 1e-9)
            start = clock()
            if start - deadline > period // 2:
                deadline = start  # late by more than half a period: skip, do not catch up
                self._overruns += 1
            deadline += period
            try:
                self._cycle(start)
            except Exception as error:  # noqa: BLE001 - a node must keep running
                self._errors += 1
                if self._on_error is not None:
                    self._on_error(error)
            end = clock()
            if last_start:
                slot = self._count % window
                self._periods_ns[slot] = start - last_start
                self._compute_ns[slot] = end - start
                self._count += 1
            last_start = start

    def stats(self) -> LoopStats:
        """Summary of the last ``window`` cycles."""
        count = min(self._count, self._periods_ns.shape[0])
        if count == 0:
            return LoopStats(self.rate_hz, 0.0, 0.0, 0.0, 0.0, 0.0, 0, self._overruns, self._errors, 0)
        periods = self._periods_ns[:count].astype(float)
        compute = self._compute_ns[:count].astype(float)
        error = np.abs(periods - self.period_ns)
        p99 = int(0.99 * (count - 1))
        return LoopStats(
            target_rate_hz=self.rate_hz,
            rate_hz=float(1e9 / periods.mean()),
            # np.partition: the order statistic without a full sort (called at the diagnostics rate).
            period_error_p99_ms=float(np.partition(error, p99)[p99] * 1e-6),
            period_error_max_ms=float(error.max() * 1e-6),
            compute_mean_ms=float(compute.mean() * 1e-6),
            compute_p99_ms=float(np.partition(compute, p99)[p99] * 1e-6),
            cycles=self._count,
            overruns=self._overruns,
            errors=self._errors,
            samples=count,
        )


class LoopingNode(Node):
    """A node whose periodic work runs in one :class:`RateLoop` thread.

    Subclasses set ``self._warn`` (a :class:`ThrottledLog`) and call :meth:`start_loop` at
    the end of their constructor; ``main()`` calls :meth:`stop` before the node is destroyed.
    """

    loop: RateLoop

    def start_loop(self, rate_hz: float, cycle: Callable[[int], None], realtime_priority: int = 0) -> None:
        """Start ``cycle(now_ns)`` at ``rate_hz`` [Hz] in the loop thread."""
        self.loop = RateLoop(
            rate_hz, cycle, self._on_loop_error, name=self.get_name(), realtime_priority=realtime_priority
        )
        if self.loop.realtime_priority:
            self.get_logger().info(f"loop thread at SCHED_FIFO priority {self.loop.realtime_priority}")
        self.loop.start()

    def _on_loop_error(self, error: BaseException) -> None:
        if not self.context.ok():  # shutting down: publishers are gone, end the loop quietly
            self.loop.stop(timeout=0.0)
            return
        self._warn("loop", f"cycle failed: {type(error).__name__}: {error}")

    @property
    def status_name(self) -> str:
        """Name of this node's ``/diagnostics`` status: its namespace and name without the leading
        slash (``cartesian_controller``, ``left/cartesian_controller``), so that two pipelines in
        two namespaces report apart on the one global ``/diagnostics``."""
        return self.get_fully_qualified_name().lstrip("/")

    def stop(self) -> None:
        """Stop the loop thread (before the node is destroyed)."""
        self.loop.stop()


def stats_key_values(stats: LoopStats) -> list[tuple[str, str]]:
    """Loop statistics as ``(key, value)`` text pairs for a ``DiagnosticStatus``."""
    return [
        ("loop_target_rate_hz", f"{stats.target_rate_hz:.1f}"),
        ("loop_rate_hz", f"{stats.rate_hz:.2f}"),
        ("loop_period_error_p99_ms", f"{stats.period_error_p99_ms:.4f}"),
        ("loop_period_error_max_ms", f"{stats.period_error_max_ms:.4f}"),
        ("loop_compute_mean_ms", f"{stats.compute_mean_ms:.4f}"),
        ("loop_compute_p99_ms", f"{stats.compute_p99_ms:.4f}"),
        ("loop_cycles", str(stats.cycles)),
        ("loop_overruns", str(stats.overruns)),
        ("loop_errors", str(stats.errors)),
    ]


class ThrottledLog:
    """Rate-limits repeated log lines per kind of problem, counting what it held back.

    rclpy's ``throttle_duration_sec`` throttles per call site, which would hide a
    second kind of problem raised from the same place; this keys on ``kind``.

    Args:
        log: the function to call with the line, e.g. ``node.get_logger().warning``.
        interval: seconds between two lines of the same kind.
    """

    def __init__(self, log: Callable[[str], None], interval: float = 1.0):
        self._log = log
        self._interval_ns = int(interval * 1e9)
        self._last_ns: dict[str, int] = {}
        self._held: dict[str, int] = {}

    def __call__(self, kind: str, line: str) -> None:
        """Log ``line`` unless a line of ``kind`` was logged less than ``interval`` ago."""
        now = time.monotonic_ns()
        last = self._last_ns.get(kind)
        if last is not None and now - last < self._interval_ns:
            self._held[kind] = self._held.get(kind, 0) + 1
            return
        held = self._held.pop(kind, 0)
        self._last_ns[kind] = now
        self._log(line + (f" ({held} more like this since the last report)" if held else ""))
