"""The fixed-rate loop every manip_kin node runs (the node base class, :class:`~manip_kin.ros.runtime.looping_node.LoopingNode`, runs one).

Why not an rclpy timer: measured here, an *empty* rclpy timer callback at 1 kHz costs
about 42 % of a core (the Python executor rebuilds its wait set on every wake-up), and
each subscription callback costs another wake-up; a node with one timer and two
subscriptions used ~80 % of a core at 1 kHz. A plain thread sleeping to absolute
deadlines costs ~4 % at 1 kHz with the same period jitter, so each node runs its
cycle in one :class:`RateLoop` thread, and the topics the cycle consumes are
:class:`~manip_kin.ros.runtime.polling.PolledSubscription` s that the loop drains at the start
of each cycle instead of executor callbacks. The executor in the main thread
(``run_node``) still serves everything else: parameter services, shutdown.

Design notes:
    * deadlines are absolute (``start + k · period``) so the average rate is exact: a
      cycle that starts late is followed by shorter periods until the schedule is met
      again; a cycle more than a full period late re-anchors the schedule instead of
      running the missed cycles back to back (``rclcpp::Rate``'s rule). Re-anchoring at
      half a period, as before, lost about 2 % of the cycles of a 1 kHz loop on a busy
      2-core machine (measured: 972-984 Hz per 30 s window in a 10-minute soak);
    * a waiter (:class:`~manip_kin.ros.runtime.polling.LoopWaiter`) can end the sleep early when
      a message that needs an immediate reaction arrives (a new goal): the cycle runs at
      once and the schedule re-anchors on it; a second wake within half a period of a woken
      cycle waits for that half period, so a flood of wakes cannot run the loop faster
      than twice its rate;
    * no exception ends the loop: a failing cycle is counted and handed to ``on_error``
      (guarded too), and the next cycle runs. Only a loop that cannot do its job for
      seconds on end (rate far below target, or every cycle failing) calls ``on_fatal``
      and ends, so that the process exits non-zero and a supervisor restarts it;
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

from manip_kin.ros.runtime.polling import sleep_ns
from manip_kin.ros.runtime.scheduling import (
    TIMER_SLACK_NS,
    SharedPriority,
    set_scheduler_slice,
    set_timer_slack,
    share_realtime_priority,
)
from manip_kin.ros.runtime.throttled_log import safe_log

__all__ = ["LoopStats", "RateLoop", "stats_key_values"]

#: How often :meth:`RateLoop.stats` sorts for its 99th percentiles (the costliest part of a status) [ns].
P99_REFRESH_NS = 1_000_000_000


@dataclass(frozen=True)
class LoopStats:
    """Timing of the recent cycles of a :class:`RateLoop` (window of ``samples`` cycles).

    Attributes:
        target_rate_hz: configured rate [Hz].
        rate_hz: achieved rate over the window [Hz].
        period_error_p99_ms: 99th percentile of ``|period - nominal|`` [ms] (and ``compute_p99_ms``:
            sorted again at most every :data:`P99_REFRESH_NS`, otherwise the last ones).
        period_error_max_ms: largest ``|period - nominal|`` [ms].
        compute_mean_ms: mean time spent in the cycle function [ms].
        compute_p99_ms: 99th percentile of that time [ms].
        cycles: cycles run since start.
        overruns: cycles whose schedule had to be re-anchored (started > one period late).
        errors: cycles whose function raised.
        samples: number of periods in the window.
        woken: cycles run early because a message woke the loop (their periods are not in
            the window statistics: they are reactions, not schedule).
        scheduling: how the kernel schedules the loop thread (:attr:`RateLoop.scheduling`).
        stalls: cycles since start that took longer than :attr:`RateLoop.stall_ns` (blocked
            inside: the schedule is lost for that long).
        longest_cycle_ms: the longest cycle since start [ms].
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
    woken: int = 0
    scheduling: str = ""
    stalls: int = 0
    longest_cycle_ms: float = 0.0


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
            :attr:`realtime_error` says why. While the loop runs, the threads it waits on get
            the same priority (:func:`share_realtime_priority`, :attr:`shared_priority`).
        scheduler_slice_ns: under normal scheduling, the EEVDF slice to request for the loop
            thread [ns] (see :func:`set_scheduler_slice`), or 0 for the kernel's default.
        wait: ``wait(timeout_ns) -> bool`` blocks until the next deadline and returns True
            when it returned early because the cycle should run now (default: sleep).
        on_fatal: called with the reason when the loop gives up (see ``give_up_after``).
        give_up_after: [s] the loop ends and calls ``on_fatal`` when, for this long without
            a break, every cycle raised or the achieved rate stayed below
            ``min_rate_fraction`` of ``rate_hz`` (0 = never give up).
        min_rate_fraction: see ``give_up_after``. A quarter by default: a loop slowed by a
            busy machine keeps going (a restart would not give it CPU); one that has stalled
            (a wedged middleware call, a cycle far slower than its period) gives up.
        on_stall: called with the duration [ns] of a cycle longer than :attr:`stall_ns`
            (ten periods, at least 20 ms): one blocked inside, whose loss of schedule should
            be said, not only counted. Called from the loop thread after the cycle.
    """

    def __init__(
        self,
        rate_hz: float,
        cycle: Callable[[int], None],
        on_error: Callable[[BaseException], None] | None = None,
        name: str = "rate_loop",
        window: int = 4096,
        realtime_priority: int = 0,
        wait: Callable[[int], bool] | None = None,
        on_fatal: Callable[[str], None] | None = None,
        give_up_after: float = 10.0,
        min_rate_fraction: float = 0.25,
        scheduler_slice_ns: int = 0,
        on_stall: Callable[[int], None] | None = None,
    ):
        if not 0 < rate_hz < 1e6:
            raise ValueError(f"rate_hz = {rate_hz}; valid: > 0 and < 1e6")
        self.rate_hz = float(rate_hz)
        self.period_ns = int(round(1e9 / rate_hz))
        self._cycle = cycle
        self._on_error = on_error
        self._on_fatal = on_fatal
        self._wait = wait or sleep_ns
        self._name = name
        self._periods_ns = np.zeros(window, dtype=np.int64)
        self._compute_ns = np.zeros(window, dtype=np.int64)
        self._count = 0
        self._p99s, self._p99s_ns = None, 0  # (period error, compute) [ns] and when, see stats()
        self._overruns = 0
        self._errors = 0
        self._woken = 0
        self._on_stall = on_stall
        #: A cycle longer than this [ns] is a stall (see ``on_stall``).
        self.stall_ns = max(10 * self.period_ns, 20_000_000)
        self._stalls = 0
        self._longest_ns = 0
        self._give_up_ns = int(give_up_after * 1e9)
        self._min_rate_fraction = float(min_rate_fraction)
        self.last_error = ""
        self.last_error_ns = 0
        self.fatal_reason = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.realtime_priority = int(realtime_priority)
        self.realtime_error = ""
        #: The process's threads that run at the loop's SCHED_FIFO priority while it runs.
        self.shared_priority = SharedPriority(0)
        self.scheduler_slice_ns = int(scheduler_slice_ns)
        #: Why the requested slice was not applied ("" when it was, or none was asked for).
        self.scheduler_slice_error = ""
        #: How the loop thread is scheduled once it runs: ``SCHED_FIFO 10``, ``slice 0.1 ms``,
        #: ``default`` (set by the thread itself; ``configured`` is set then).
        self.scheduling = ""
        self.configured = threading.Event()

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

    def _configure_thread(self) -> None:
        """Timer slack, SCHED_FIFO priority (shared with the threads the loop waits on) or else
        the EEVDF slice of the loop thread (it calls this)."""
        try:
            set_timer_slack(TIMER_SLACK_NS)
            if self.realtime_priority > 0:
                try:
                    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.realtime_priority))
                    self.scheduling = f"SCHED_FIFO {self.realtime_priority}"
                    self.shared_priority = share_realtime_priority(self.realtime_priority)
                    return
                except (OSError, AttributeError) as error:
                    self.realtime_error = f"SCHED_FIFO priority {self.realtime_priority} not set: {error}"
            self.scheduling = "default"
            if self.scheduler_slice_ns > 0:
                granted, why_not = set_scheduler_slice(self.scheduler_slice_ns)
                if granted:
                    self.scheduling = f"slice {granted * 1e-6:g} ms"
                else:
                    self.scheduler_slice_error = (
                        f"scheduler slice {self.scheduler_slice_ns * 1e-6:g} ms not set: {why_not}"
                    )
        finally:
            self.configured.set()

    def _run(self) -> None:
        self._configure_thread()
        try:
            self._run_cycles()
        finally:
            self.shared_priority.restore()

    def _run_cycles(self) -> None:
        period = self.period_ns
        half = period // 2
        window = self._periods_ns.shape[0]
        stop = self._stop
        wait = self._wait
        clock = time.monotonic_ns
        deadline = clock() + period
        last_start = 0
        last_woken = False
        # Health over one-second windows: the loop gives up after give_up_after seconds of
        # windows that ran too few cycles or in which every cycle failed.
        health_start = clock()
        health_cycles = health_failures = 0
        unhealthy_since = 0
        while not stop.is_set():
            try:
                woken = wait(deadline - clock())
                start = clock()
                if woken and last_woken and start - last_start < half:
                    # Woken again right after a woken cycle (goals in a burst, or a waiter that
                    # keeps returning at once): half a period between such cycles bounds the
                    # rate. The first wake after a regular cycle runs at once: a new goal's
                    # reaction time.
                    sleep_ns(last_start + half - start)
                    start = clock()
                if woken:
                    self._woken += 1
                    deadline = start  # re-anchor the schedule on the reacting cycle
                elif start - deadline > period:
                    # rclcpp::Rate's rule: a cycle less than a full period late keeps the schedule
                    # (the next ones catch up); one later than that re-anchors it, no burst.
                    deadline = start
                    self._overruns += 1
                deadline += period
            except Exception as error:  # noqa: BLE001 - a failing waiter must not end the loop
                self._report(error)
                start = clock()
                deadline = start + period
                woken = True  # no period sample for this cycle
            failed = False
            try:
                self._cycle(start)
            except Exception as error:  # noqa: BLE001 - a node must keep running
                failed = True
                self._report(error)
            end = clock()
            if end - start > self._longest_ns:
                self._longest_ns = end - start
            if end - start > self.stall_ns:
                self._stalled(end - start)
            if last_start and not woken:
                slot = self._count % window
                self._periods_ns[slot] = start - last_start
                self._compute_ns[slot] = end - start
                self._count += 1
            last_start = start
            last_woken = woken
            health_cycles += 1
            health_failures += failed
            if end - health_start >= 1_000_000_000:
                expected = (end - health_start) / period
                healthy = health_failures < health_cycles and health_cycles >= self._min_rate_fraction * expected
                if healthy:
                    unhealthy_since = 0
                elif not unhealthy_since:
                    unhealthy_since = health_start
                if self._give_up_ns and unhealthy_since and end - unhealthy_since >= self._give_up_ns:
                    self._give_up(health_cycles, health_failures, (end - health_start) * 1e-9)
                    return
                health_start = end
                health_cycles = health_failures = 0

    def _report(self, error: BaseException) -> None:
        self._errors += 1
        try:
            self.last_error = f"{type(error).__name__}: {error}"
            self.last_error_ns = time.monotonic_ns()
            if self._on_error is not None:
                self._on_error(error)
        except Exception as handler_error:  # noqa: BLE001 - the error path must not end the loop
            safe_log(print, f"{self._name}: error handler failed: {type(handler_error).__name__}: {handler_error}")

    def _stalled(self, duration_ns: int) -> None:
        self._stalls += 1
        if self._on_stall is not None:
            try:
                self._on_stall(duration_ns)
            except Exception as error:  # noqa: BLE001 - reporting must not end the loop
                safe_log(print, f"{self._name}: stall handler failed: {type(error).__name__}: {error}")

    def _give_up(self, cycles: int, failures: int, seconds: float) -> None:
        give_up_s = self._give_up_ns * 1e-9
        if failures >= cycles:
            reason = f"every cycle failed for {give_up_s:g} s (last: {self.last_error})"
        else:
            reason = (
                f"rate below {100 * self._min_rate_fraction:.0f} % of {self.rate_hz:g} Hz for {give_up_s:g} s "
                f"(last second: {cycles / seconds:.0f} Hz)"
            )
        self.fatal_reason = reason
        self._stop.set()
        if self._on_fatal is not None:
            try:
                self._on_fatal(reason)
            except Exception as error:  # noqa: BLE001 - nothing left to do but say so
                safe_log(print, f"{self._name}: giving up ({reason}); fatal handler failed: {error}")

    def stats(self) -> LoopStats:
        """Summary of the last ``window`` cycles."""
        count = min(self._count, self._periods_ns.shape[0])
        counts = {
            "target_rate_hz": self.rate_hz,
            "cycles": self._count,
            "overruns": self._overruns,
            "errors": self._errors,
            "samples": count,
            "woken": self._woken,
            "scheduling": self.scheduling,
            "stalls": self._stalls,
            "longest_cycle_ms": self._longest_ns * 1e-6,
        }
        if count == 0:
            timing = ("rate_hz", "period_error_p99_ms", "period_error_max_ms", "compute_mean_ms", "compute_p99_ms")
            return LoopStats(**dict.fromkeys(timing, 0.0), **counts)
        periods = self._periods_ns[:count]
        compute = self._compute_ns[:count]
        error = np.abs(periods - self.period_ns)
        now_ns = time.monotonic_ns()
        if self._p99s is None or now_ns - self._p99s_ns >= P99_REFRESH_NS:
            p99 = int(0.99 * (count - 1))
            self._p99s = (float(np.partition(error, p99)[p99]), float(np.partition(compute, p99)[p99]))
            self._p99s_ns = now_ns
        return LoopStats(
            rate_hz=float(1e9 / periods.mean()),
            period_error_p99_ms=self._p99s[0] * 1e-6,
            period_error_max_ms=float(error.max() * 1e-6),
            compute_mean_ms=float(compute.mean() * 1e-6),
            compute_p99_ms=self._p99s[1] * 1e-6,
            **counts,
        )


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
        ("loop_woken", str(stats.woken)),
        ("loop_scheduling", stats.scheduling),
        ("loop_stalls", str(stats.stalls)),
        ("loop_longest_cycle_ms", f"{stats.longest_cycle_ms:.3f}"),
    ]
