"""How a node stops on SIGINT and SIGTERM (:func:`~manip_kin.ros.runtime.runner.run_node` uses it):
Python's own handler under rclpy's, the executor woken once the context is down, a node's halt
before the shutdown, and no signal while the node cleans up."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable

from rclpy.node import Node

#: Seconds after a first Ctrl-C from which another one interrupts the node's Python code.
FORCE_INTERRUPT_AFTER_S = 2.0


class StopSignals:
    """Python's SIGINT and SIGTERM handler, under rclpy's: the node stops, nothing is raised.

    rclpy's own handler ends ``spin()`` (its signal thread wakes the executors, then shuts the
    contexts down) and then chains to Python's. Python's default SIGINT handler raises
    KeyboardInterrupt at the next bytecode of whatever callback runs, which can leave a
    half-done piece of work behind: one landed inside the recorder's chunk write (the MCAP
    writer had emptied its chunk buffer and not yet its index), and the file lost the chunk's
    messages. So the first signal raises nothing, as SIGTERM never did; it sets
    :attr:`received`, on which :func:`wake_the_executor_once_stopped` acts. A Ctrl-C
    ``FORCE_INTERRUPT_AFTER_S`` or more after the first (a node stuck in a callback) raises as
    usual; an earlier one (a launcher forwarding the terminal's Ctrl-C to a process that got it
    already) is dropped.
    """

    def __init__(self) -> None:
        self.first_at: float | None = None
        self.received = threading.Event()

    def __call__(self, signal_number: int, frame: object) -> None:
        now = time.monotonic()
        if self.first_at is None:
            self.first_at = now
            self.received.set()
        elif signal_number == signal.SIGINT and now - self.first_at >= FORCE_INTERRUPT_AFTER_S:
            raise KeyboardInterrupt


#: Seconds a stop signal leaves rclpy's signal thread to shut the context down before the
#: executor is woken anyway.
CONTEXT_SHUTDOWN_WAIT_S = 5.0


def wake_the_executor_once_stopped(stop_signals: StopSignals, node: Node, executor: object) -> None:
    """Wake ``executor`` once a stop signal has come and the node's context is shut down.

    rclpy's signal thread wakes the executors *before* it shuts the contexts down, and the
    shutdown itself wakes nothing: an executor that woke in between, found its context still
    valid and went back to its wait slept on with a shut-down context, until a timer or a
    message came (a node with neither did not stop, 2 of 45 runs under load). A daemon thread
    waits for the signal and the shutdown, then wakes the executor, which then sees the
    shut-down context and ends ``spin()``.
    """

    def watch() -> None:
        stop_signals.received.wait()
        deadline = time.monotonic() + CONTEXT_SHUTDOWN_WAIT_S
        try:
            while node.context.ok() and time.monotonic() < deadline:
                time.sleep(0.001)
            executor.wake()
        except Exception:  # noqa: BLE001 - the executor is already gone: nothing left to wake
            pass

    threading.Thread(target=watch, name="wake_executor_on_stop", daemon=True).start()


#: Period of the no-op timer that lets Python's signal handler run in a node with a halt where
#: :class:`SignalWakeup` cannot be set up (run_node outside the main thread) [s].
SIGNAL_POLL_PERIOD_S = 0.02


class SignalWakeup:
    """Wakes the executor when a signal comes, so that Python's handler runs at once.

    With a halt, rclpy's signal handlers are not installed, and Python runs its own handler in
    the main thread between bytecodes: a main thread blocked in the executor's wait (C code)
    runs it only once something wakes that wait. ``signal.set_wakeup_fd`` has the C-level
    handler write a byte to a pipe; a thread blocked on the pipe wakes the executor. A no-op
    timer every 20 ms (:data:`SIGNAL_POLL_PERIOD_S`, now the fallback) woke it 50 times a second
    instead, each wake a pass of rclpy's Python executor (docs/collision.md measures it).
    """

    def __init__(self) -> None:
        self._write_fd = -1
        self._previous_fd = -1

    def start(self, executor: object) -> bool:
        """Wake ``executor`` on every signal from now on; False where that cannot be set up
        (not the main thread)."""
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)  # the C-level handler must never block
        try:
            self._previous_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        except ValueError:  # not the main thread
            os.close(read_fd)
            os.close(write_fd)
            return False
        self._write_fd = write_fd
        threading.Thread(
            target=self._wake_on_signals, args=(read_fd, executor), name="signal_wakeup", daemon=True
        ).start()
        return True

    @staticmethod
    def _wake_on_signals(read_fd: int, executor: object) -> None:
        try:
            while os.read(read_fd, 64):  # b"" once stop() closed the write end
                try:
                    executor.wake()
                except Exception:  # noqa: BLE001 - the executor is already gone: nothing left to wake
                    return
        finally:
            os.close(read_fd)

    def stop(self) -> None:
        """Give the wakeup fd back and end the thread."""
        if self._write_fd < 0:
            return
        try:
            signal.set_wakeup_fd(self._previous_fd)
        except ValueError:  # a fd closed meanwhile by its owner: none then
            signal.set_wakeup_fd(-1)
        os.close(self._write_fd)
        self._write_fd = -1


def halt_then_shut_down(stop_signals: StopSignals, started: dict, halt: Callable) -> None:
    """On a stop signal: ``halt(node)`` while the context is up (its last messages still go
    out), then shut the context down and wake the executor, which ends ``spin()``. Before the
    node exists (``started`` has no ``node`` yet: waiting for robot_description), only the
    shutdown, which ends that wait."""

    def watch() -> None:
        stop_signals.received.wait()
        node = started.get("node")
        if node is not None:
            try:
                halt(node)
            except Exception as error:  # noqa: BLE001 - shut down regardless
                print(f"error: halting {node.get_name()} failed: {type(error).__name__}: {error}", file=sys.stderr)
        try:
            import rclpy

            rclpy.try_shutdown()
            if "executor" in started:
                started["executor"].wake()
        except Exception:  # noqa: BLE001 - the executor is already gone: nothing left to wake
            pass

    threading.Thread(target=watch, name="halt_on_stop", daemon=True).start()


def ignore_signals() -> None:
    """SIGINT and SIGTERM ignored from now on, at the Python level (the node is stopping)."""
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        for _attempt in range(3):
            try:
                signal.signal(signal_number, signal.SIG_IGN)
                break
            except KeyboardInterrupt:
                # signal.signal() first runs the handlers of signals already received: a
                # forced Ctrl-C can raise here (before that handler existed, the SIGINT that
                # stopped spin() did, in a loaded test run). It asked for this cleanup: drop it
                # and try again.
                continue
            except (ValueError, OSError):  # not the main thread (a test harness): nothing to do
                break
