"""Node plumbing without ROS traffic: the rate loop, log throttling, parameter checks, --help."""

import contextlib
import signal
import subprocess
import sys
import sysconfig
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.runtime.params import ParamSpec
from manip_kin.ros.runtime.rate_loop import RateLoop
from manip_kin.ros.runtime.runner import TEARDOWN_TIMEOUT_S
from manip_kin.ros.runtime.scheduling import TIMER_SLACK_NS
from manip_kin.ros.runtime.throttled_log import ThrottledLog


def test_rate_loop_runs_at_rate_survives_errors_and_stops():
    calls = []
    errors = []

    def cycle(now_ns):
        calls.append(now_ns)
        if len(calls) == 5:
            raise RuntimeError("boom")

    loop = RateLoop(200.0, cycle, errors.append, name="test_loop")
    loop.start()
    deadline = time.monotonic() + 30
    while len(calls) < 100 and time.monotonic() < deadline:  # a condition, not a fixed sleep
        time.sleep(0.01)
    loop.stop()
    assert not loop.running  # joined: no cycle can follow
    count = len(calls)
    assert count >= 100
    assert len(errors) == 1 and str(errors[0]) == "boom"  # the loop went on after the error
    periods = np.diff(calls)
    # The rate is the behaviour, as a lower bound a loaded machine cannot break: deadlines are
    # 5 ms apart and a cycle more than a period late re-anchors them instead of running the
    # missed cycles, so any 10 consecutive periods last at least 9 x 5 ms (a cycle starts at or
    # after its deadline, and at most one period after it unless re-anchored). Too slow says
    # nothing about the loop on a shared machine; the unloaded rate is measured by make bench.
    ten_periods = np.array(calls[10:]) - np.array(calls[:-10])
    assert ten_periods.min() >= 45e6, ten_periods.min()
    # The stats are those of the cycles that ran (the cycle's now_ns is its start time).
    stats = loop.stats()
    assert stats.errors == 1 and stats.cycles == count - 1 and stats.samples == count - 1
    assert stats.rate_hz == pytest.approx(1e9 / periods.mean(), rel=1e-12)
    assert stats.period_error_max_ms == pytest.approx(np.abs(periods - 5e6).max() * 1e-6, rel=1e-12)
    rank = int(0.99 * (len(periods) - 1))
    assert stats.period_error_p99_ms == pytest.approx(np.sort(np.abs(periods - 5e6))[rank] * 1e-6, rel=1e-12)
    assert stats.compute_mean_ms >= 0
    with pytest.raises(ValueError, match="rate"):
        RateLoop(0.0, cycle)


def test_a_cycle_that_blocks_for_many_periods_is_reported_and_the_loop_goes_on():
    """A cycle longer than ten periods (at least 20 ms) is a stall: reported once with its
    duration, counted in the stats; a cycle just under the threshold is not; the loop goes on."""
    calls = []
    stalls = []

    def cycle(now_ns):
        calls.append(now_ns)
        if len(calls) == 5:
            time.sleep(0.015)  # under 10 periods of 2 ms = 20 ms: slow, not a stall
        if len(calls) == 10:
            time.sleep(0.06)  # blocked for 30 periods

    loop = RateLoop(500.0, cycle, name="stall_loop", on_stall=stalls.append)
    assert loop.stall_ns == 20_000_000
    loop.start()
    deadline = time.monotonic() + 30
    while len(calls) < 60 and time.monotonic() < deadline:
        time.sleep(0.01)
    loop.stop()
    assert len(calls) >= 60  # it went on
    assert len(stalls) == 1
    assert 60e6 <= stalls[0] < 60e6 + 1e9  # the blocked cycle's own duration
    stats = loop.stats()
    assert stats.stalls == 1
    assert stats.longest_cycle_ms == pytest.approx(stalls[0] * 1e-6)
    # A handler that raises is reported on stderr; the loop survives it too.
    failing = RateLoop(500.0, lambda now_ns: time.sleep(0.03), name="stall_loop_2", on_stall=lambda ns: 1 / 0)
    failing.start()
    deadline = time.monotonic() + 30
    while failing.stats().stalls < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    failing.stop()
    assert failing.stats().stalls >= 2


def test_loop_thread_sleeps_with_a_short_timer_slack():
    # Linux wakes a sleeping thread up to its timer slack late (50 us by default); the loop
    # thread asks for TIMER_SLACK_NS, and only its own thread (the caller keeps its slack).
    slacks = []

    def read_slack(_now_ns):
        slacks.append(int(open(f"/proc/{threading.get_native_id()}/timerslack_ns").read()))

    caller_slack = int(open(f"/proc/{threading.get_native_id()}/timerslack_ns").read())
    loop = RateLoop(200.0, read_slack, name="slack_loop")
    loop.start()
    deadline = time.monotonic() + 10
    while not slacks and time.monotonic() < deadline:
        time.sleep(0.01)
    loop.stop()
    assert slacks and slacks[0] == TIMER_SLACK_NS < caller_slack
    assert int(open(f"/proc/{threading.get_native_id()}/timerslack_ns").read()) == caller_slack


def _thread_slice_ns(native_id: int) -> int:
    from pipeline_checks import thread_slice_ns

    slice_ns = thread_slice_ns(native_id)
    if slice_ns is None:
        pytest.skip("this kernel reports no se.slice")
    return slice_ns


@pytest.mark.parametrize("requested_ns", [0, 100_000, 400_000])
def test_the_loop_thread_gets_the_scheduler_slice_asked_for_and_keeps_its_nice_value(requested_ns):
    """The slice goes to the loop thread only (read back from /proc, not from our syscall), its
    nice value (inherited from the thread that started it) survives the change, and 0 leaves the
    kernel's default."""
    import os

    seen = []

    def read_scheduling(_now_ns):
        native_id = threading.get_native_id()
        seen.append((_thread_slice_ns(native_id), os.getpriority(os.PRIO_PROCESS, native_id)))

    caller_slice = _thread_slice_ns(threading.get_native_id())
    loops = []

    def start_niced():  # a thread at nice 3 starts the loop: the loop thread inherits it
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 3)
        loops.append(RateLoop(200.0, read_scheduling, name="slice_loop", scheduler_slice_ns=requested_ns))
        loops[0].start()

    starter = threading.Thread(target=start_niced)
    starter.start()
    starter.join()
    loop = loops[0]
    deadline = time.monotonic() + 10
    while not seen and time.monotonic() < deadline:
        time.sleep(0.01)
    loop.stop()
    assert seen, "the loop never ran"
    slice_ns, nice = seen[0]
    assert nice == 3
    assert _thread_slice_ns(threading.get_native_id()) == caller_slice  # the caller keeps its own
    if requested_ns == 0:
        assert (slice_ns, loop.scheduling, loop.scheduler_slice_error) == (caller_slice, "default", "")
    elif loop.scheduler_slice_error:  # a kernel before 6.12: the loop runs, saying why
        assert "not set" in loop.scheduler_slice_error and loop.scheduling == "default"
        print(f"this kernel refused the slice: {loop.scheduler_slice_error}")
    else:
        assert slice_ns == requested_ns != caller_slice
        assert loop.scheduling == f"slice {requested_ns * 1e-6:g} ms"
        assert loop.stats().scheduling == loop.scheduling


def test_throttled_log_keys_on_kind():
    lines = []
    log = ThrottledLog(lines.append, interval=0.2)
    for _ in range(3):
        log("length", "bad length")
        log("finite", "bad value")
    assert lines == ["bad length", "bad value"]
    time.sleep(0.25)  # the behaviour is the interval: anything longer than 0.2 s releases the kind
    log("length", "bad length")
    assert lines[-1] == "bad length (2 more like this since the last report)"


def test_param_spec_coercion():
    rate = ParamSpec("rate_hz", "float", 500.0, "rate", "Hz", positive=True)
    assert rate.coerce(1000) == 1000.0 and isinstance(rate.coerce(1000), float)
    with pytest.raises(InvalidArgumentError, match="valid: > 0 Hz"):
        rate.coerce(0)
    with pytest.raises(InvalidArgumentError, match="wrong type"):
        rate.coerce("fast")
    with pytest.raises(InvalidArgumentError, match="wrong type"):
        rate.coerce(True)
    positions = ParamSpec("initial_positions", "float_list", None, "q")
    assert positions.coerce([0, 1, 2]) == [0.0, 1.0, 2.0] and positions.coerce(None) is None
    with pytest.raises(InvalidArgumentError, match=r"= \[nan\]; valid: finite numbers"):
        positions.coerce([float("nan")])
    scaling = ParamSpec("time_scaling", "str", "cubic", "s", choices=("cubic", "quintic"))
    with pytest.raises(InvalidArgumentError, match="valid: cubic, quintic"):
        scaling.coerce("linear")
    assert "rate_hz (default 500.0) [Hz]" in rate.help_line()


@pytest.mark.parametrize("executable", ["robot_state", "cartesian_controller", "trajectory_generator"])
def test_help_lists_parameters_topics_and_example(executable):
    path = Path(sysconfig.get_path("scripts")) / executable
    result = subprocess.run([str(path), "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0
    text = result.stdout
    # robot_state simulates genova7 by default; the others read the URDF on robot_description.
    robot_default = "'genova7'" if executable == "robot_state" else "''"
    assert "rate_hz (default 500.0) [Hz]" in text and f"robot (default {robot_default})" in text
    assert "tip_link (default '')" in text and "Settable at run time" in text
    assert "--ros-args -p robot:=" in text and "Subscribes:" in text and "Publishes:" in text


@pytest.mark.parametrize("executable", ["robot_state", "recorder"])
def test_help_into_a_pipe_whose_reader_left_exits_0_quietly(executable):
    """``robot_state --help | head -1``: the reader is gone before the usage is written."""
    path = Path(sysconfig.get_path("scripts")) / executable
    process = subprocess.Popen([str(path), "--help"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    process.stdout.close()  # before the interpreter has started, let alone printed
    stderr = process.stderr.read()
    assert process.wait(60) == 0, stderr
    assert stderr == ""


def test_bad_parameter_exits_2_with_one_line():
    path = Path(sysconfig.get_path("scripts")) / "robot_state"
    result = subprocess.run(
        [str(path), "--ros-args", "-p", "robot:=nosuchbot"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "nosuchbot" in errors[0]


HANGING_TEARDOWN = """
import ctypes, sys, time
from rclpy.node import Node
from manip_kin.ros.runtime.runner import run_node

HOLD_THE_GIL = sys.argv[1] == "gil"

class HangingTeardown(Node):
    def __init__(self):
        super().__init__("hanging_teardown")
        self.timer = self.create_timer(0.01, self.ready)  # runs once the executor spins

    def ready(self):
        self.timer.cancel()
        print("ready", flush=True)

    def destroy_node(self):
        # Middleware teardown that never ends; with "gil" inside C code that keeps the GIL (a
        # PyDLL call does not release it), as rclpy's destroy_node was seen to.
        if HOLD_THE_GIL:
            ctypes.PyDLL(None).sleep(60)
        time.sleep(60)

sys.exit(run_node(HangingTeardown, "usage", ["hanging_teardown"]))
"""


@contextlib.contextmanager
def _python_process(script: str, argument: str, ready: str):
    """``script`` run by a new Python with one argument; yields the process once it printed
    ``ready``; killed and reaped at the end (its stderr stays readable)."""
    process = subprocess.Popen(
        [sys.executable, "-c", script, argument], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert process.stdout.readline().strip() == ready
        yield process
    finally:
        process.kill()
        process.wait()


@pytest.mark.parametrize("hang", ["sleep", "gil"])
def test_a_node_whose_teardown_hangs_still_exits_with_its_code(hang):
    with _python_process(HANGING_TEARDOWN, hang, ready="ready") as process:
        process.send_signal(signal.SIGINT)
        signalled = time.monotonic()
        # The watchdog fires TEARDOWN_TIMEOUT_S (3 s) after the node stopped; 30 s leaves a loaded
        # machine room and is still half the hang, so a process without the watchdog fails here.
        code = process.wait(30)
        waited = time.monotonic() - signalled
    stderr = process.stderr.read()
    assert code == 0, stderr
    assert waited >= TEARDOWN_TIMEOUT_S
    # The stacks at the timeout, written by faulthandler's own thread (no GIL needed): where it hung.
    assert "Timeout (0:00:03)!" in stderr and "in destroy_node" in stderr and "in run_node" in stderr, stderr
    if hang == "sleep":  # the GIL is free: the Python timer says why it exits
        assert f"shutting down took more than {TEARDOWN_TIMEOUT_S:g} s" in stderr


def test_a_node_dumps_its_stacks_on_sigusr1():
    """What the pipeline supervisor sends before a SIGKILL (to a node that is stuck): every
    thread's stack, to stderr, and the node runs on."""
    with _python_process(HANGING_TEARDOWN, "sleep", ready="ready") as process:
        lines: list[str] = []
        dumped = threading.Event()

        def read_stderr() -> None:
            for line in process.stderr:
                lines.append(line)
                if "in run_node" in line:
                    dumped.set()

        threading.Thread(target=read_stderr, daemon=True).start()
        process.send_signal(signal.SIGUSR1)
        # The stop waits for the whole dump: faulthandler walks every thread's frames without
        # the GIL, and a Ctrl-C right behind it, changing the main thread's frames mid-walk,
        # once left the dump cut off at its first frame and the process gone.
        assert dumped.wait(30), "".join(lines)
        assert process.poll() is None
        process.send_signal(signal.SIGINT)
        try:
            code = process.wait(30)
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGUSR1)  # where it stands now, for the message below
            time.sleep(1.0)
            raise AssertionError("the node did not stop:\n" + "".join(lines)) from None
    assert code == 0, "".join(lines)
    assert "".join(lines).count("most recent call first") >= 1


LATE_CONTEXT_SHUTDOWN = """
import signal, sys, threading, time
from rclpy.node import Node
from manip_kin.ros.runtime.runner import run_node

class NothingToWakeIt(Node):
    \"\"\"After its first callback the executor has nothing that could wake it: no timer, no
    subscription.\"\"\"

    def __init__(self):
        super().__init__("nothing_to_wake_it")
        self.timer = self.create_timer(0.01, self.start)

    def start(self):
        self.timer.cancel()
        threading.Thread(target=self.ctrl_c_with_a_late_shutdown, daemon=True).start()

    def ctrl_c_with_a_late_shutdown(self):
        # What rclpy's signal thread does on SIGINT, in the order it does it, with its context
        # shutdown landing after the executor has woken, found the context valid and gone back to
        # its wait. Python's SIGINT handler runs at the woken main thread's first bytecode.
        time.sleep(0.2)
        signal.getsignal(signal.SIGINT)(signal.SIGINT, None)
        self.executor._sigint_gc.trigger()  # rclpy's signal thread wakes every executor ...
        time.sleep(0.5)
        print("shutting the context down", flush=True)
        with self.context.handle:
            self.context.handle.shutdown()  # ... then shuts the contexts down, waking nothing

sys.exit(run_node(NothingToWakeIt, "usage", ["nothing_to_wake_it"]))
"""


def test_ctrl_c_stops_a_node_whose_context_shutdown_lands_after_its_executor_waits_again():
    """rclpy's signal thread triggers the executors' guard conditions, then shuts the contexts
    down, and that wakes no executor: one that woke in between and went back to its wait slept on
    with a shut-down context (a node with no timer left, 2 of 45 runs under load)."""
    try:
        result = subprocess.run(
            [sys.executable, "-c", LATE_CONTEXT_SHUTDOWN], capture_output=True, text=True, timeout=30
        )
    except subprocess.TimeoutExpired as stuck:
        raise AssertionError(f"the node did not stop: {stuck.stdout!r} {stuck.stderr!r}") from None
    assert result.returncode == 0, result.stderr
    assert result.stdout == "shutting the context down\n"


CTRL_C_IN_A_CALLBACK = """
import os, signal, sys, time
from rclpy.node import Node
from manip_kin.ros.runtime.runner import run_node

STUCK = sys.argv[1] == "stuck"

class CtrlCInACallback(Node):
    def __init__(self):
        super().__init__("ctrl_c_in_a_callback")
        self.timer = self.create_timer(0.01, self.work)

    def work(self):
        self.timer.cancel()
        if STUCK:  # a callback that never returns
            print("stuck", flush=True)
            while True:
                time.sleep(0.01)
        os.kill(os.getpid(), signal.SIGINT)
        # A piece of work the Ctrl-C lands in the middle of (the recorder's chunk write, say):
        # wait until rclpy's handler has shut the context down, then finish the work.
        deadline = time.monotonic() + 20
        while self.context.ok() and time.monotonic() < deadline:
            time.sleep(0.001)
        steps = sum(range(100000))
        print(f"finished {steps}", flush=True)

sys.exit(run_node(CtrlCInACallback, "usage", ["ctrl_c_in_a_callback"]))
"""


def test_ctrl_c_stops_a_node_without_interrupting_the_callback_that_runs():
    """A KeyboardInterrupt at an arbitrary bytecode once cost a recording a chunk of messages:
    the first Ctrl-C only stops the node (rclpy shuts the context down), the callback finishes."""
    result = subprocess.run(
        [sys.executable, "-c", CTRL_C_IN_A_CALLBACK, "work"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == f"finished {sum(range(100000))}", result.stderr


def test_a_second_ctrl_c_interrupts_a_stuck_node_only_after_a_while():
    from manip_kin.ros.runtime.stop_signals import FORCE_INTERRUPT_AFTER_S

    with _python_process(CTRL_C_IN_A_CALLBACK, "stuck", ready="stuck") as process:
        process.send_signal(signal.SIGINT)
        first = time.monotonic()
        time.sleep(0.1)
        process.send_signal(signal.SIGINT)  # a launcher forwarding the terminal's Ctrl-C: dropped
        time.sleep(max(0.0, first + FORCE_INTERRUPT_AFTER_S - 0.5 - time.monotonic()))
        assert process.poll() is None, "a Ctrl-C soon after the first interrupted the callback"
        time.sleep(max(0.0, first + FORCE_INTERRUPT_AFTER_S + 0.2 - time.monotonic()))
        process.send_signal(signal.SIGINT)  # the user insists
        code = process.wait(30)
    assert code == 0, process.stderr.read()


def test_cleanup_drops_the_keyboard_interrupt_of_the_signal_that_stopped_the_node(monkeypatch):
    """CPython's signal.signal() first runs the handlers of signals already received, so a
    pending KeyboardInterrupt (a forced Ctrl-C; before run_node's own SIGINT handler, the SIGINT
    that ended spin(), seen in a loaded run: the node exited -2) can raise inside the call that
    turns SIGINT off. The cleanup drops it and turns the signal off."""
    from manip_kin.ros.runtime import stop_signals

    installed = []
    pending = {signal.SIGINT: True}

    def fake_signal(number, handler):
        if pending.pop(number, False):
            raise KeyboardInterrupt
        installed.append((number, handler))

    monkeypatch.setattr(stop_signals.signal, "signal", fake_signal)
    stop_signals.ignore_signals()
    assert installed == [(signal.SIGINT, signal.SIG_IGN), (signal.SIGTERM, signal.SIG_IGN)]


HALTING_NODE = """
import sys, threading, time
from rclpy.node import Node
from manip_kin.ros.runtime.runner import run_node

class Halting(Node):
    \"\"\"A node with a halt and nothing of its own that could wake its executor.\"\"\"

    def __init__(self):
        super().__init__("halting")
        threading.Thread(target=self.report, daemon=True).start()

    def report(self):
        deadline = time.monotonic() + 20
        while self.executor is None and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.2)  # spinning by now
        print(f"spinning with {len(list(self.timers))} timers", flush=True)

def halt(node):
    print("halted", flush=True)

sys.exit(run_node(Halting, "usage", ["halting"], halt=halt))
"""


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_wakes_a_halting_node_without_a_polling_timer(stop):
    """A node with a halt runs Python's signal handler, which runs only when the main thread
    leaves the executor's wait: the signal itself wakes it, not a no-op timer every 20 ms."""
    with _python_process(HALTING_NODE, "", ready="spinning with 0 timers") as process:
        process.send_signal(stop)
        signalled = time.monotonic()
        try:
            code = process.wait(30)
        except subprocess.TimeoutExpired:
            raise AssertionError("the signal did not stop the node") from None
        stopped_after = time.monotonic() - signalled
        assert code == 0, process.stderr.read()
        assert process.stdout.read() == "halted\n"
    assert stopped_after < 10.0
