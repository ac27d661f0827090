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
from collections.abc import Callable, Sequence

from rclpy.node import Node

from manip_kin.errors import EXIT_INPUT_ERROR, EXIT_INTERRUPTED, ManipKinError, exit_code_for
from manip_kin.ros.runtime.stop_signals import (
    SIGNAL_POLL_PERIOD_S,
    SignalWakeup,
    StopSignals,
    halt_then_shut_down,
    ignore_signals,
    wake_the_executor_once_stopped,
)


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
            each signal (:class:`SignalWakeup`).

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
    stop_signals = StopSignals()
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
    signal_wakeup = SignalWakeup()
    if halt is not None:
        halt_then_shut_down(stop_signals, started, halt)
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
                    wake_the_executor_once_stopped(stop_signals, node, executor)
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
            # A forced Ctrl-C (see StopSignals) can come at any bytecode,
            # possibly inside the handler above.
            pass
        teardown_code = exit_code
    finally:
        if node is not None:
            # From here on a signal must not interrupt the cleanup (a recorder finishing its
            # file, the loop thread's join): Python-level handlers off; a pending one is dropped.
            ignore_signals()
            signal_wakeup.stop()
            if on_shutdown is not None:
                on_shutdown(node)
            _exit_if_teardown_hangs(teardown_code)
            node.destroy_node()
        rclpy.try_shutdown()
    return exit_code
