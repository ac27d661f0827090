"""The base class of the looping nodes: a :class:`~manip_kin.ros.runtime.rate_loop.RateLoop` and its error path.

No node dies silently: whatever a cycle raises is logged (throttled per exception type
and message, through :class:`~manip_kin.ros.runtime.throttled_log.ThrottledLog`, which cannot
raise), the node publishes its safe output and an ERROR status on ``/diagnostics``, and
the next cycle runs. A loop that gives up (every cycle failing, or the rate far below
target, for seconds on end) makes ``run_node`` exit with code 1 so a supervisor restarts
the node.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.node import Node

from manip_kin.errors import OperationError
from manip_kin.ros.runtime.polling import LoopWaiter, PolledSubscription, fast_path_problem
from manip_kin.ros.runtime.rate_loop import RateLoop, stats_key_values
from manip_kin.ros.runtime.throttled_log import ThrottledLog, safe_log
from manip_kin.ros.wire.diagnostics import diagnostic_array_cdr
from manip_kin.ros.wire.messages import ns_to_stamp, stamp_key


class LoopGaveUpError(OperationError):
    """Raised in the executor thread when a node's loop gave up; ``run_node`` exits with 1.

    A valid node that could not go on: an :class:`~manip_kin.errors.OperationError` (still a
    ``RuntimeError``)."""


class LoopingNode(Node):
    """A node whose periodic work runs in one :class:`RateLoop` thread.

    Subclasses call :meth:`start_loop` at the end of their constructor, publish their
    status on ``self._diagnostics_pub`` (a ``DiagnosticArray`` publisher) and override
    :meth:`publish_safe_output`; ``main()`` calls :meth:`stop` before the node is destroyed.

    When a cycle raises, the node logs it (throttled per exception type and message),
    publishes its safe output and an ERROR status naming the exception, and the next cycle
    runs; for :attr:`ERROR_HOLD_S` after an error :meth:`diagnostic_level` reports ERROR
    in the node's regular status too. When the loop gives up (see :class:`RateLoop`), the
    node logs why and ``run_node`` exits with code 1.
    """

    loop: RateLoop
    #: Seconds after a cycle error during which the regular status stays at ERROR.
    ERROR_HOLD_S = 1.0
    #: Seconds of failing cycles or of a rate below a quarter of the target before the loop gives up.
    GIVE_UP_AFTER_S = 10.0
    #: Shortest interval between two ERROR statuses sent from the error path [s].
    ERROR_STATUS_INTERVAL_S = 0.05

    def start_loop(
        self,
        rate_hz: float,
        cycle: Callable[[int], None],
        realtime_priority: int = 0,
        scheduler_slice: float = 0.0,
        wake_on: tuple[PolledSubscription, ...] = (),
    ) -> None:
        """Start ``cycle(now_ns)`` at ``rate_hz`` [Hz] in the loop thread.

        Args:
            rate_hz: cycle rate [Hz].
            cycle: the work of one cycle.
            realtime_priority: SCHED_FIFO priority of the loop thread (0: normal).
            scheduler_slice: under normal scheduling, the loop thread's time slice [s] (0: the
                kernel's default; see :func:`manip_kin.ros.runtime.scheduling.set_scheduler_slice`).
            wake_on: subscriptions whose messages run a cycle at once (a new goal) instead of
                waiting for the next tick.
        """
        self.fatal_reason = ""
        # Stamps are on the ROS clock: the wall clock, read directly (rclpy's clock object costs
        # microseconds a call at 1 kHz), unless use_sim_time.
        self._wall_clock = not self.get_parameter("use_sim_time").value
        self._cycle_error_log = ThrottledLog(self.get_logger().error, 1.0)
        self._stall_log = ThrottledLog(self.get_logger().warning, 5.0)
        self._last_error_status_ns = 0
        self._fatal_guard = self.create_guard_condition(self._raise_gave_up)
        self.waiter = LoopWaiter(self, list(wake_on)) if wake_on else None
        self.loop = RateLoop(
            rate_hz,
            cycle,
            self._on_loop_error,
            name=self.get_name(),
            realtime_priority=realtime_priority,
            scheduler_slice_ns=int(round(scheduler_slice * 1e9)),
            wait=self.waiter.wait if self.waiter is not None else None,
            on_fatal=self._on_loop_gave_up,
            give_up_after=self.GIVE_UP_AFTER_S,
            on_stall=self._on_loop_stall,
        )
        problem = fast_path_problem()
        if problem:
            self.get_logger().info(f"inputs read through the public rclpy API (more CPU): {problem}")
        self.loop.start()
        # The thread sets its own scheduling: say what it got (or why not) once it has. A refused
        # SCHED_FIFO was asked for explicitly; the slice is asked for by default, and kernels
        # before 6.12 have none: no warning on every start there.
        self.loop.configured.wait(1.0)
        if self.loop.realtime_error:
            self.get_logger().warning(f"loop thread: {self.loop.realtime_error}")
        if self.loop.scheduler_slice_error:
            self.get_logger().info(f"loop thread: {self.loop.scheduler_slice_error}")
        scheduling = self.loop.scheduling or "unknown"
        if self.loop.shared_priority.priority:
            scheduling += f", also given to {self.loop.shared_priority.describe()}"
        self.get_logger().info(f"loop at {rate_hz:g} Hz, thread scheduling: {scheduling}")

    # --- what subclasses provide ---------------------------------------------------------------

    def publish_safe_output(self) -> None:
        """Publish what keeps the robot safe after a failed cycle (subclasses override)."""

    # --- the error path ------------------------------------------------------------------------

    def loop_error(self) -> str:
        """The last cycle error if it is less than :attr:`ERROR_HOLD_S` old, else ""."""
        loop = getattr(self, "loop", None)
        if loop is None or not loop.last_error_ns:
            return ""
        if time.monotonic_ns() - loop.last_error_ns > self.ERROR_HOLD_S * 1e9:
            return ""
        return loop.last_error

    def diagnostic_level(self, level: str) -> str:
        """``level``, raised to ``error`` while a cycle error is recent."""
        return "error" if self.loop_error() else level

    def _on_loop_stall(self, duration_ns: int) -> None:
        """A cycle blocked for many periods: say so (throttled), the loop goes on."""
        period_ms = self.loop.period_ns * 1e-6
        self._stall_log(
            "stall",
            f"a cycle took {duration_ns * 1e-6:.1f} ms of a {period_ms:g} ms period: something in it blocked "
            "(Fast DDS's shared-memory transport can hold a publish up to 1/3 s the first time it sends "
            "to a new participant); the loop goes on, loop_stalls in /diagnostics counts these",
        )

    def _on_loop_error(self, error: BaseException) -> None:
        if not self.context.ok():  # shutting down: publishers are gone, end the loop quietly
            self.loop.stop(timeout=0.0)
            return
        reason = f"{type(error).__name__}: {error}"
        self._cycle_error_log(reason[:300], f"cycle failed: {reason}; publishing the safe output, the next cycle runs")
        try:
            self.publish_safe_output()
        except Exception as safe_error:  # noqa: BLE001 - report and go on
            self._cycle_error_log(
                "safe output", f"publishing the safe output failed too: {type(safe_error).__name__}: {safe_error}"
            )
        now = time.monotonic_ns()
        if now - self._last_error_status_ns >= self.ERROR_STATUS_INTERVAL_S * 1e9:
            self._last_error_status_ns = now
            try:
                self._publish_error_status(reason)
            except Exception as status_error:  # noqa: BLE001 - report and go on
                self._cycle_error_log(
                    "error status", f"publishing the ERROR status failed: {type(status_error).__name__}: {status_error}"
                )

    def _publish_error_status(self, reason: str) -> None:
        if getattr(self, "_diagnostics_pub", None) is None:
            return
        values = [("state", "error"), ("loop_error", reason)] + stats_key_values(self.loop.stats())
        self.publish_status("error", f"cycle failed: {reason}", values)

    def publish_status(self, level: str, message: str, values, stamp_ns: int | None = None) -> None:
        """This node's status on ``_diagnostics_pub`` (``/diagnostics``): named :attr:`status_name`,
        with the robot's name as hardware id, stamped ``stamp_ns`` [ns, ROS clock] or now; as
        CDR bytes (:func:`~manip_kin.ros.wire.diagnostics.diagnostic_array_cdr`: the loop
        publishes it in a cycle)."""
        if stamp_ns is None:
            stamp_ns = self.get_clock().now().nanoseconds
        model = getattr(self, "model", None)
        self._diagnostics_pub.publish(
            diagnostic_array_cdr(stamp_ns, self.status_name, level, message, getattr(model, "name", ""), values)
        )

    def _on_loop_gave_up(self, reason: str) -> None:
        self.fatal_reason = reason
        safe_log(
            self.get_logger().fatal,
            f"loop gave up: {reason}; exiting with code 1 so that a supervisor restarts the node",
        )
        try:
            self.publish_safe_output()
        except Exception:  # noqa: BLE001 - the exit goes on regardless
            pass
        self._fatal_guard.trigger()

    def _raise_gave_up(self) -> None:
        raise LoopGaveUpError(self.fatal_reason)

    def ros_time_ns(self) -> int:
        """Now on the ROS clock (what stamps carry) [ns]."""
        return time.time_ns() if self._wall_clock else self.get_clock().now().nanoseconds

    def ros_time_at(self, monotonic_ns: int) -> int:
        """A loop time (``time.monotonic_ns()``) on the ROS clock [ns]: what a sample taken at
        the cycle's start is stamped with, however late in the cycle it is published."""
        return monotonic_ns + self.ros_time_ns() - time.monotonic_ns()

    def stamp_key_of(self, monotonic_ns: int) -> str:
        """The :func:`~manip_kin.ros.wire.messages.stamp_key` of a loop time moved to the ROS
        clock: how a node reports when something happened in its loop."""
        return stamp_key(ns_to_stamp(self.ros_time_at(monotonic_ns)))

    @property
    def status_name(self) -> str:
        """Name of this node's ``/diagnostics`` status: its namespace and name without the leading
        slash (``cartesian_controller``, ``left/cartesian_controller``), so that two pipelines in
        two namespaces report apart on the one global ``/diagnostics``."""
        return self.get_fully_qualified_name().lstrip("/")

    def stop(self) -> None:
        """Stop the loop thread (before the node is destroyed)."""
        self.loop.stop()
