"""Shared ``main()`` plumbing for manip_kin nodes.

Every node executable starts the same way: ``--help`` answered without
starting ROS, rclpy initialised with the process arguments (so ``--ros-args``
remapping and parameters work), SIGINT and SIGTERM ending the spin loop so the
node can finish its work (a recorder closes its file), then a clean shutdown.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence

from rclpy.node import Node

from manip_kin.errors import EXIT_INPUT_ERROR, EXIT_INTERRUPTED, ManipKinError, exit_code_for


def wants_help(argv: Sequence[str], usage: str) -> bool:
    """Print ``usage`` and return True when the user asked for ``--help``.

    Only arguments before ``--ros-args`` count, as in ``ros2 run``.
    """
    user_args = list(argv[1:])
    if "--ros-args" in user_args:
        user_args = user_args[: user_args.index("--ros-args")]
    if "-h" in user_args or "--help" in user_args:
        try:
            print(usage, flush=True)
        except BrokenPipeError:
            # `robot_state --help | head`: the reader left, as it may. Later writes (the flush at
            # exit) go nowhere instead of ending in a traceback and exit code 1.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return True
    return False


#: Seconds the middleware teardown (node destruction, rclpy shutdown, interpreter exit) may
#: take once the node has finished its own work; then the process exits anyway.
TEARDOWN_TIMEOUT_S = 3.0


def _exit_if_teardown_hangs(exit_code: int, timeout_s: float = TEARDOWN_TIMEOUT_S) -> None:
    """Exit with ``exit_code`` if the process is still alive ``timeout_s`` from now.

    The node's own work (a recorder closing its file) is done before this starts; what is
    left is middleware teardown (node destruction, rclpy shutdown, interpreter exit), and a
    hang there is not worth a process its supervisor has to SIGKILL. Seen under load:
    ``destroy_node`` blocking inside rclpy's C++ with the GIL held, so no Python thread can
    run. Hence three guards: at ``timeout_s`` faulthandler's own C thread writes every
    thread's stack to stderr; a Python timer then warns and exits (when the GIL is free);
    and a C timer (:func:`_exit_later_without_the_gil`) exits half a second later in any case.
    """

    def give_up() -> None:
        try:
            print(
                f"warning: shutting down took more than {timeout_s:g} s after the node stopped; exiting",
                file=sys.stderr,
                flush=True,
            )
        finally:
            os._exit(exit_code)

    faulthandler.dump_traceback_later(timeout_s, repeat=False, file=sys.stderr, exit=False)
    timer = threading.Timer(timeout_s + 0.05, give_up)
    timer.daemon = True
    timer.start()
    _exit_later_without_the_gil(exit_code, timeout_s + 0.5)


def _exit_later_without_the_gil(exit_code: int, delay_s: float) -> bool:
    """Arm a POSIX timer whose expiry calls libc's ``_exit(exit_code)`` in a thread of its own
    (``SIGEV_THREAD``): no Python, no GIL involved. False where that cannot be set up."""
    import ctypes

    class _Sigevent(ctypes.Structure):  # struct sigevent (Linux): sigval, signo, notify, then the thread's function
        _fields_ = [
            ("sigev_value", ctypes.c_void_p),
            ("sigev_signo", ctypes.c_int),
            ("sigev_notify", ctypes.c_int),
            ("sigev_notify_function", ctypes.c_void_p),
            ("sigev_notify_attributes", ctypes.c_void_p),
            ("_pad", ctypes.c_int * 8),
        ]

    class _Timespec(ctypes.Structure):
        _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]

    class _Itimerspec(ctypes.Structure):
        _fields_ = [("it_interval", _Timespec), ("it_value", _Timespec)]

    sigev_thread, clock_monotonic = 2, 1  # <signal.h>, <time.h>
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        event = _Sigevent()
        event.sigev_value = exit_code & 0xFF  # passed to _exit as its int argument
        event.sigev_notify = sigev_thread
        event.sigev_notify_function = ctypes.cast(libc._exit, ctypes.c_void_p).value
        timer_id = ctypes.c_void_p()
        if libc.timer_create(clock_monotonic, ctypes.byref(event), ctypes.byref(timer_id)) != 0:
            return False
        seconds = int(delay_s)
        expiry = _Itimerspec(_Timespec(0, 0), _Timespec(seconds, int((delay_s - seconds) * 1e9)))
        return libc.timer_settime(timer_id, 0, ctypes.byref(expiry), None) == 0
    except (OSError, AttributeError, ValueError):
        return False


#: Seconds after a first Ctrl-C from which another one interrupts the node's Python code.
FORCE_INTERRUPT_AFTER_S = 2.0


class _StopSignals:
    """Python's SIGINT and SIGTERM handler, under rclpy's: the node stops, nothing is raised.

    rclpy's own handler ends ``spin()`` (its signal thread wakes the executors, then shuts the
    contexts down) and then chains to Python's. Python's default SIGINT handler raises
    KeyboardInterrupt at the next bytecode of whatever callback runs, which can leave a
    half-done piece of work behind: one landed inside the recorder's chunk write (the MCAP
    writer had emptied its chunk buffer and not yet its index), and the file lost the chunk's
    messages. So the first signal raises nothing, as SIGTERM never did; it sets
    :attr:`received`, on which :func:`_wake_the_executor_once_stopped` acts. A Ctrl-C
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


def _wake_the_executor_once_stopped(stop_signals: _StopSignals, node: Node, executor: object) -> None:
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
#: :class:`_SignalWakeup` cannot be set up (run_node outside the main thread) [s].
SIGNAL_POLL_PERIOD_S = 0.02


class _SignalWakeup:
    """Wakes the executor when a signal comes, so that Python's handler runs at once.

    With a halt, rclpy's signal handlers are not installed, and Python runs its own handler in
    the main thread between bytecodes: a main thread blocked in the executor's wait (C code)
    runs it only once something wakes that wait. ``signal.set_wakeup_fd`` has the C-level
    handler write a byte to a pipe; a thread blocked on the pipe wakes the executor. A no-op
    timer every 20 ms did the same for 2.9 % of a core (the controller at 1 kHz, 2026-12-06).
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


def _halt_then_shut_down(stop_signals: _StopSignals, started: dict, halt: Callable) -> None:
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


def _ignore_signals() -> None:
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


def run_node(
    make_node: Callable[[], Node],
    usage: str,
    argv: Sequence[str] | None = None,
    on_shutdown: Callable[[Node], None] | None = None,
    halt: Callable[[Node], None] | None = None,
) -> int:
    """Create a node, spin it until Ctrl-C or SIGTERM, then clean up.

    Args:
        make_node: builds the node after ``rclpy.init``.
        usage: text printed for ``--help``.
        argv: process arguments; defaults to ``sys.argv``.
        on_shutdown: called with the node before it is destroyed, also after
            a signal (used to finish files).
        halt: called with the node on SIGINT or SIGTERM *before* the context shuts down, so
            that it can still publish (a controller brings its commands to rest). With it,
            rclpy's own signal handlers are not installed: Python's run, the executor woken by
            each signal (:class:`_SignalWakeup`).

    Returns:
        The process exit code: 0 after a clean stop, 2 when the node could not
        be configured (bad parameter, robot or file: a ``ValueError``, which every
        :class:`~manip_kin.errors.InputError` is), 1 when it could not start for
        another reason (a :class:`~manip_kin.errors.ManipKinError` such as an
        :class:`~manip_kin.errors.OperationError`); the reason is printed on one line.
        Also 1 when the node's loop gave up (see ``LoopingNode``), so that a supervisor restarts it.
    """
    try:  # a Ctrl-C before the stop handlers below are in place: nothing has started
        import rclpy
        from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

        from manip_kin.ros.runtime.looping_node import LoopGaveUpError
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED

    argv = list(sys.argv if argv is None else argv)
    if wants_help(argv, usage):
        return 0
    # SIGUSR1 writes every thread's Python stack to stderr (the node's log): what a supervisor
    # asks for before it SIGKILLs a node that did not stop (manip_kin.pipeline does).
    faulthandler.register(signal.SIGUSR1, all_threads=True, chain=False)
    # ALL: rclpy turns both SIGINT and SIGTERM into a context shutdown that ends spin(). Python's
    # own handlers, which rclpy chains to, must be in place before rclpy.init.
    stop_signals = _StopSignals()
    for signal_number in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(signal_number, stop_signals)
        except ValueError:  # not the main thread (a test harness): Python's handler does not run there
            break
    try:
        options = rclpy.signals.SignalHandlerOptions.NO if halt else rclpy.signals.SignalHandlerOptions.ALL
        rclpy.init(args=argv, signal_handler_options=options)
    except RuntimeError as error:  # rcl cannot parse the --ros-args (e.g. a list mixing 0 and 0.3)
        reason = str(error).split(", at /")[0]
        if "same type" in reason:
            reason += " (a list of numbers needs one type: write 0.0, not 0, next to 0.3)"
        print(f"error: {reason}", file=sys.stderr)
        return 2
    if stop_signals.first_at is not None:  # a stop signal before rclpy's handler was there
        rclpy.try_shutdown()
        return 0
    node = None
    exit_code = 0
    teardown_code = 1  # the exit code if teardown hangs: 1 unless spin ended as it should
    started: dict = {}
    signal_wakeup = _SignalWakeup()
    if halt is not None:
        _halt_then_shut_down(stop_signals, started, halt)
    try:
        try:
            node = make_node()
        except ValueError as error:  # bad parameter, robot or file (InputError is a ValueError)
            print(f"error: {error}", file=sys.stderr)
            return EXIT_INPUT_ERROR
        except ManipKinError as error:  # a valid configuration that could not be carried out
            print(f"error: {error}", file=sys.stderr)
            return exit_code_for(error)
        except (KeyboardInterrupt, ExternalShutdownException):  # stopped while waiting (robot_description)
            return 0
        except Exception as error:  # noqa: BLE001 - anything else: say why, exit non-zero
            if stop_signals.received.is_set():  # the signal's context shutdown broke the start: a stop
                return 0
            print(f"error: the node could not start: {type(error).__name__}: {error}", file=sys.stderr)
            return 1
        try:
            try:  # a signal may land before spin() starts: the same clean stop
                if stop_signals.received.is_set() and not node.context.ok():
                    # Stopped while it started: an executor made now raises half-built (and
                    # its __del__ then prints an AttributeError).
                    raise ExternalShutdownException()
                executor = SingleThreadedExecutor()
                executor.add_node(node)
                if halt is None:
                    _wake_the_executor_once_stopped(stop_signals, node, executor)
                else:
                    if not signal_wakeup.start(executor):
                        node.create_timer(SIGNAL_POLL_PERIOD_S, lambda: None)
                    started.update(node=node, executor=executor)
                    if stop_signals.received.is_set() and not node.context.ok():
                        return 0
                executor.spin()
            except (KeyboardInterrupt, ExternalShutdownException):
                pass
            except LoopGaveUpError as error:
                print(f"error: {node.get_name()} gave up: {error}", file=sys.stderr)
                exit_code = 1
            except Exception:
                # A signal's context shutdown can land while spin() builds its wait set, which then
                # raises RCLError ("context is not valid") instead of ExternalShutdownException.
                if node.context.ok():
                    raise
        except KeyboardInterrupt:
            # A forced Ctrl-C (see _StopSignals) can come at any bytecode,
            # possibly inside the handler above.
            pass
        teardown_code = exit_code
    finally:
        if node is not None:
            # From here on a signal must not interrupt the cleanup (a recorder finishing its
            # file, the loop thread's join): Python-level handlers off; a pending one is dropped.
            _ignore_signals()
            signal_wakeup.stop()
            if on_shutdown is not None:
                on_shutdown(node)
            _exit_if_teardown_hangs(teardown_code)
            node.destroy_node()
        rclpy.try_shutdown()
    return exit_code
