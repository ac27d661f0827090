"""Run the manip_kin nodes without ``ros2 launch``, and talk to them from Python.

:class:`Pipeline` starts node executables as subprocesses with their parameters, waits
until each one's control loop runs (its first ``/diagnostics`` status), and stops them
cleanly (SIGINT, then SIGTERM, then SIGKILL after timeouts). Any process can join: a
:class:`NodeProcess` is an executable name, a node name and parameters, so the recorder is
one more entry in the list (see :func:`pipeline_processes`).

:class:`PipelineClient` is a small rclpy node in its own context: send a goal or a line
target, wait until the controller reports the goal converged (matched by the goal's
stamp in ``/diagnostics``), read ``/joint_states`` and ``/tool_pose``. The ``manip_kin
goal`` and ``manip_kin line`` commands, the demo, the tests and the benchmark use it.

DDS isolation: every process started here runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE``
and ``ROS_DOMAIN_ID`` set; when the caller set neither, :func:`ensure_ros_isolation`
picks LOCALHOST and a free domain for this process and its children (a caller's values
are never overridden).

Example::

    with Pipeline(pipeline_processes("genova7", rate_hz=1000)) as pipeline, PipelineClient() as client:
        stamp = client.send_goal(goal_pose)
        status = client.wait_converged(stamp, timeout=30)
"""

from __future__ import annotations

import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.errors import ManipKinError

#: Node executables of the pipeline, in start order.
PIPELINE_NODES = ("robot_state", "cartesian_controller", "trajectory_generator")


class PipelineError(ManipKinError):
    """A node that did not start, died, or a wait that timed out."""


# --- environment ----------------------------------------------------------------------------


def _domain_is_free(domain_id: int) -> bool:
    # Fast DDS binds the first participant's unicast discovery port to 7410 + 250 * domain.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", 7410 + 250 * domain_id))
        except OSError:
            return False
    return True


def pick_free_domain(exclude: Iterable[str] = ()) -> int:
    """A random ``ROS_DOMAIN_ID`` in 1..100 that no local participant uses.

    Raises:
        PipelineError: every domain is taken (sharing one would mix two runs' topics).
    """
    excluded = {str(d) for d in exclude}
    candidates = [d for d in range(1, 101) if str(d) not in excluded]
    random.SystemRandom().shuffle(candidates)
    for domain_id in candidates:
        if _domain_is_free(domain_id):
            return domain_id
    raise PipelineError("no free ROS_DOMAIN_ID in 1..100 on this machine")


def ensure_ros_isolation(environ: dict | None = None) -> dict:
    """Set ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a free ``ROS_DOMAIN_ID`` where unset.

    Args:
        environ: the environment to complete (default ``os.environ``, so that this
            process's own rclpy and every child inherit it).

    Returns:
        The same mapping.
    """
    environ = os.environ if environ is None else environ
    environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if not environ.get("ROS_DOMAIN_ID"):
        environ["ROS_DOMAIN_ID"] = str(pick_free_domain())
    return environ


def fresh_domain_env(environ: Mapping[str, str] | None = None) -> dict:
    """A copy of ``environ`` (default ``os.environ``) on a free ``ROS_DOMAIN_ID`` of its own.

    For two pipelines alive at once in one test session: on a shared domain their topics
    would mix.
    """
    env = dict(os.environ if environ is None else environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["ROS_DOMAIN_ID"] = str(pick_free_domain(exclude=[env.get("ROS_DOMAIN_ID", "")]))
    return env


def find_executable(name: str, executable_dir: str | os.PathLike | None = None) -> str:
    """Path of a node executable: in ``executable_dir`` if given, else next to this Python, else on PATH."""
    if executable_dir is not None:
        candidate = Path(executable_dir) / name
        if candidate.is_file():
            return str(candidate)
        raise PipelineError(f"executable {name!r} not found in {executable_dir}")
    beside = Path(sys.executable).parent / name
    if beside.is_file():
        return str(beside)
    found = shutil.which(name)
    if found is None:
        raise PipelineError(f"executable {name!r} not found next to {sys.executable} nor on PATH")
    return found


def _parameter_text(value) -> str:
    """A parameter value as ``-p name:=value`` text (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(repr(float(v)) for v in value) + "]"
    if isinstance(value, float):
        return repr(value)
    return str(value)


# --- processes -------------------------------------------------------------------------------


@dataclass(frozen=True)
class NodeProcess:
    """One node executable to run.

    Attributes:
        executable: console script name (``robot_state``...).
        node_name: the node's name in the graph, also its ``/diagnostics`` status name.
        parameters: ``-p name:=value`` pairs.
        params_file: optional ``--params-file``.
        remaps: ``-r from:=to`` pairs.
        ready_status: ``/diagnostics`` status name whose arrival means the node runs
            ("" = wait only for the node name in the graph).
    """

    executable: str
    node_name: str = ""
    parameters: Mapping[str, object] = field(default_factory=dict)
    params_file: str | None = None
    remaps: Mapping[str, str] = field(default_factory=dict)
    ready_status: str = ""

    @property
    def name(self) -> str:
        """The node name (the executable name when not set)."""
        return self.node_name or self.executable

    def arguments(self) -> list[str]:
        """The ``--ros-args`` part of the command line."""
        args = ["--ros-args"]
        if self.node_name:
            args += ["-r", f"__node:={self.node_name}"]
        for source, target in self.remaps.items():
            args += ["-r", f"{source}:={target}"]
        if self.params_file:
            args += ["--params-file", str(self.params_file)]
        for key, value in self.parameters.items():
            args += ["-p", f"{key}:={_parameter_text(value)}"]
        return args


def pipeline_processes(
    robot: str = "genova7",
    rate_hz: float = 500.0,
    initial_positions: Sequence[float] | None = None,
    controller: Mapping[str, object] | None = None,
    generator: Mapping[str, object] | None = None,
    robot_state: Mapping[str, object] | None = None,
    params_file: str | None = None,
    realtime_priority: int = 0,
) -> list[NodeProcess]:
    """The three pipeline nodes for ``robot`` at ``rate_hz``, with extra parameters per node.

    Args:
        robot: bundled robot name or robot file.
        rate_hz: loop rate of the three nodes [Hz].
        initial_positions: start configuration of robot_state (default: the robot's).
        controller: extra cartesian_controller parameters (gains, tolerances...).
        generator: extra trajectory_generator parameters (time_scaling, limits...).
        robot_state: extra robot_state parameters.
        params_file: a ``--params-file`` given to every node. ROS resolves a key found in the
            file's node-name section before ``-p`` values (which act like ``/**`` entries), so
            the file wins for the keys it sets per node.
        realtime_priority: SCHED_FIFO priority of every node's loop thread (0 = normal
            scheduling); keeps the loops on time on a busy machine where permitted.
    """
    common = {"robot": robot, "rate_hz": float(rate_hz)}
    if realtime_priority:
        common["realtime_priority"] = int(realtime_priority)
    state = dict(common, **(robot_state or {}))
    if initial_positions is not None:
        state["initial_positions"] = [float(v) for v in initial_positions]
    return [
        NodeProcess("robot_state", "robot_state", state, params_file, ready_status="robot_state"),
        NodeProcess(
            "cartesian_controller",
            "cartesian_controller",
            dict(common, **(controller or {})),
            params_file,
            ready_status="cartesian_controller",
        ),
        NodeProcess(
            "trajectory_generator",
            "trajectory_generator",
            dict(common, **(generator or {})),
            params_file,
            ready_status="trajectory_generator",
        ),
    ]


class Pipeline:
    """Node processes started together and stopped together.

    Args:
        processes: what to run, in start order.
        executable_dir: where the executables are (e.g. ``install/manip_kin/lib/manip_kin``);
            default: next to this Python, else PATH.
        env: environment of the children (default: this process's, completed by
            :func:`ensure_ros_isolation`).
        log_dir: where each process's output goes (``NAME.log``); default: a temp dir.
    """

    def __init__(
        self,
        processes: Iterable[NodeProcess],
        executable_dir: str | os.PathLike | None = None,
        env: Mapping[str, str] | None = None,
        log_dir: str | os.PathLike | None = None,
    ):
        self.processes = {spec.name: spec for spec in processes}
        self.executable_dir = executable_dir
        self.env = ensure_ros_isolation(dict(env) if env is not None else None)
        if env is None:
            self.env = dict(self.env)
        self.env.setdefault("PYTHONUNBUFFERED", "1")
        self.log_dir = Path(log_dir) if log_dir else Path(tempfile.mkdtemp(prefix="manip_kin_pipeline_"))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self._popen: dict[str, subprocess.Popen] = {}
        self._logs: dict[str, object] = {}
        self._client: PipelineClient | None = None

    # --- lifecycle ---------------------------------------------------------------------------

    def start(self, timeout: float = 30.0) -> Pipeline:
        """Start every process and wait until each runs; stops them all on failure."""
        try:
            for name in self.processes:
                self.start_process(name)
            self.wait_ready(list(self.processes), timeout)
        except BaseException:
            self.stop()
            raise
        return self

    def start_process(self, name: str) -> subprocess.Popen:
        """Start (or restart) one process by node name; does not wait for it."""
        spec = self.processes[name]
        old = self._popen.get(name)
        if old is not None and old.poll() is None:
            raise PipelineError(f"{name} is already running (pid {old.pid})")
        command = [find_executable(spec.executable, self.executable_dir)] + spec.arguments()
        log = open(self.log_dir / f"{name}.log", "ab")  # noqa: SIM115 - closed in stop
        log.write(f"$ {' '.join(command)}\n".encode())
        log.flush()
        self._logs[name] = log
        self._popen[name] = subprocess.Popen(
            command, env=self.env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
        )
        return self._popen[name]

    def wait_ready(self, names: Sequence[str], timeout: float = 30.0) -> None:
        """Wait until each named process publishes its ready status (or appears in the graph).

        Raises:
            PipelineError: a process exited, or the timeout passed; the message has its log tail.
        """
        client = self.client()
        deadline = time.monotonic() + timeout
        started = {name: client.now_ns() for name in names}
        waiting = list(names)
        while waiting:
            for name in list(waiting):
                popen = self._popen.get(name)
                if popen is None or popen.poll() is not None:
                    code = None if popen is None else popen.returncode
                    raise PipelineError(f"{name} exited with code {code} during start:\n{self.log_tail(name)}")
                spec = self.processes[name]
                if spec.ready_status:
                    status = client.latest_status(spec.ready_status)
                    if status is not None and status.received_ns >= started[name]:
                        waiting.remove(name)
                elif name in client.node_names():
                    waiting.remove(name)
            if not waiting:
                break
            if time.monotonic() > deadline:
                tails = "\n".join(f"--- {n} ---\n{self.log_tail(n)}" for n in waiting)
                raise PipelineError(f"not ready after {timeout:g} s: {', '.join(waiting)}\n{tails}")
            client.spin_for(0.05)

    def stop_process(self, name: str, timeout: float = 5.0, sig: int | None = signal.SIGINT) -> int | None:
        """Stop one process: ``sig`` (SIGINT), then SIGTERM, then SIGKILL; returns its exit code.

        ``sig=None`` only waits ``timeout`` before escalating (the caller already signalled).
        """
        popen = self._popen.get(name)
        if popen is None:
            return None
        if popen.poll() is None:
            for signal_number, wait in ((sig, timeout), (signal.SIGTERM, 2.0), (signal.SIGKILL, 5.0)):
                try:
                    if signal_number is not None:
                        popen.send_signal(signal_number)
                except ProcessLookupError:
                    break
                try:
                    popen.wait(wait)
                    break
                except subprocess.TimeoutExpired:
                    continue
        log = self._logs.pop(name, None)
        if log is not None:
            log.close()
        return popen.returncode

    def kill_process(self, name: str) -> int | None:
        """SIGKILL one process at once (a crash) and reap it."""
        return self.stop_process(name, timeout=5.0, sig=signal.SIGKILL)

    def restart_process(self, name: str, timeout: float = 30.0) -> None:
        """Start a stopped process again and wait until it runs."""
        self.start_process(name)
        self.wait_ready([name], timeout)

    def stop(self, timeout: float = 5.0) -> dict[str, int | None]:
        """Stop every process (reverse start order) and the client; returns exit codes by name."""
        codes = {}
        # Signal all first so they stop in parallel, then collect.
        for name in reversed(list(self._popen)):
            popen = self._popen[name]
            if popen.poll() is None:
                try:
                    popen.send_signal(signal.SIGINT)
                except ProcessLookupError:
                    pass
        for name in reversed(list(self._popen)):
            codes[name] = self.stop_process(name, timeout, sig=None)
        if self._client is not None:
            self._client.close()
            self._client = None
        return codes

    def __enter__(self) -> Pipeline:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # --- inspection -----------------------------------------------------------------------------

    def pid(self, name: str) -> int:
        """Process id of a running node."""
        return self._popen[name].pid

    def running(self, name: str) -> bool:
        """True while the process runs."""
        popen = self._popen.get(name)
        return popen is not None and popen.poll() is None

    def log_text(self, name: str) -> str:
        """Everything the process printed so far."""
        path = self.log_dir / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def log_tail(self, name: str, lines: int = 30) -> str:
        """The last ``lines`` lines the process printed."""
        return "\n".join(self.log_text(name).splitlines()[-lines:])

    def client(self) -> PipelineClient:
        """The pipeline's own :class:`PipelineClient` (created on first use, closed by :meth:`stop`)."""
        if self._client is None:
            self._client = PipelineClient(env=self.env)
        return self._client


# --- client ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Status:
    """One ``DiagnosticStatus`` as received.

    Attributes:
        name: status name (the node name).
        message: its message (the node's state).
        values: key/value pairs.
        received_ns: receive time, ``time.monotonic_ns()``.
    """

    name: str
    message: str
    values: dict
    received_ns: int

    def number(self, key: str) -> float:
        """A value as a float (NaN when empty or missing)."""
        text = self.values.get(key, "")
        try:
            return float(text)
        except ValueError:
            return float("nan")


class PipelineClient:
    """A small rclpy node (own context) to drive and observe the pipeline.

    Args:
        env: environment whose ``ROS_DOMAIN_ID`` to use (default: this process's, completed by
            :func:`ensure_ros_isolation`).
        watch_state: subscribe to ``/joint_states`` and ``/tool_pose`` now (otherwise on the
            first :meth:`current_positions` / :meth:`current_tool_pose`: each subscriber costs
            the 1 kHz publisher a little, so the client only listens when asked).
        base_frame: frame id put on goals.
        node_name: this node's name.
    """

    def __init__(
        self,
        env: Mapping[str, str] | None = None,
        watch_state: bool = False,
        base_frame: str = "base_link",
        node_name: str = "",
    ):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState

        self._state_types = (JointState, PoseStamped)
        environ = ensure_ros_isolation() if env is None else env
        domain = int(environ.get("ROS_DOMAIN_ID", os.environ.get("ROS_DOMAIN_ID", "0")))
        # rclpy reads the discovery range from this process's environment.
        os.environ.setdefault(
            "ROS_AUTOMATIC_DISCOVERY_RANGE", environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        )
        self.base_frame = base_frame
        self._context = rclpy.Context()
        # No signal handlers: Ctrl-C stays a KeyboardInterrupt for the program using the client.
        rclpy.init(
            context=self._context, domain_id=domain, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO
        )
        self.node = rclpy.create_node(node_name or f"manip_kin_client_{os.getpid()}", context=self._context)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._publishers: dict[str, object] = {}
        self._statuses: dict[str, Status] = {}
        self.joint_state: JointState | None = None
        self.tool_pose: PoseStamped | None = None
        self._status_listeners: list[Callable[[Status], None]] = []
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)
        self._watching = False
        if watch_state:
            self.watch_state()
        self._closed = False

    def watch_state(self) -> None:
        """Subscribe to ``/joint_states`` and ``/tool_pose`` (once)."""
        if not self._watching:
            joint_state_type, pose_type = self._state_types
            self.node.create_subscription(joint_state_type, "/joint_states", self._on_joint_state, 1)
            self.node.create_subscription(pose_type, "/tool_pose", self._on_tool_pose, 1)
            self._watching = True

    # --- plumbing --------------------------------------------------------------------------------

    def now_ns(self) -> int:
        """``time.monotonic_ns()``: the clock of :attr:`Status.received_ns`."""
        return time.monotonic_ns()

    def spin_for(self, seconds: float) -> None:
        """Process incoming messages for ``seconds``."""
        deadline = time.monotonic() + seconds
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return
            self._executor.spin_once(timeout_sec=min(remaining, 0.05))

    def spin_until(self, predicate: Callable[[], object], timeout: float):
        """Spin until ``predicate()`` is truthy (returned) or ``timeout`` passes (returns None)."""
        deadline = time.monotonic() + timeout
        while True:
            value = predicate()
            if value:
                return value
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            self._executor.spin_once(timeout_sec=min(remaining, 0.02))

    def node_names(self) -> list[str]:
        """Node names currently in the graph."""
        return self.node.get_node_names()

    def _on_diagnostics(self, msg) -> None:
        now = time.monotonic_ns()
        for status in msg.status:
            entry = Status(status.name, status.message, {kv.key: kv.value for kv in status.values}, now)
            self._statuses[status.name] = entry
            for listener in self._status_listeners:
                listener(entry)

    def _on_joint_state(self, msg) -> None:
        self.joint_state = msg

    def _on_tool_pose(self, msg) -> None:
        self.tool_pose = msg

    def latest_status(self, name: str) -> Status | None:
        """Newest ``/diagnostics`` status of node ``name`` received so far."""
        return self._statuses.get(name)

    def add_status_listener(self, listener: Callable[[Status], None]) -> None:
        """Call ``listener(status)`` for every status received from now on."""
        self._status_listeners.append(listener)

    def close(self) -> None:
        """Destroy the node and shut its context down."""
        if self._closed:
            return
        self._closed = True
        self._executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self._context.try_shutdown()

    def __enter__(self) -> PipelineClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- publishing ------------------------------------------------------------------------------

    def publisher(self, msg_type, topic: str):
        """A reliable depth-10 publisher on ``topic`` (created once)."""
        key = f"{topic}:{msg_type.__name__}"
        if key not in self._publishers:
            self._publishers[key] = self.node.create_publisher(msg_type, topic, 10)
        return self._publishers[key]

    def publish_delivered(self, topic: str, msg, timeout: float = 10.0, subscribers: int = 1) -> int:
        """Publish ``msg`` once a subscriber is matched, and wait until they acknowledged it.

        Returns:
            The number of matched subscriptions.

        Raises:
            PipelineError: no subscriber within ``timeout`` or no acknowledgement.
        """
        from rclpy.duration import Duration

        publisher = self.publisher(type(msg), topic)

        def all_matched() -> bool:
            # Every subscription the graph knows must be matched, not just the first one:
            # with a recorder running, it may match before the controller does.
            known = len(self.node.get_subscriptions_info_by_topic(topic))
            return publisher.get_subscription_count() >= max(subscribers, known)

        matched = self.spin_until(all_matched, timeout)
        if not matched:
            raise PipelineError(
                f"no subscriber on {topic} after {timeout:g} s (is the node running, same ROS_DOMAIN_ID?)"
            )
        # Discovery is two-sided: give the subscriber's side a moment to match our writer too,
        # or a reliable sample can be sent before the reader accepts it.
        self.spin_for(0.05)
        publisher.publish(msg)
        if not publisher.wait_for_all_acked(Duration(seconds=timeout)):
            raise PipelineError(f"message on {topic} was not acknowledged within {timeout:g} s")
        return publisher.get_subscription_count()

    def pose_msg(self, pose: np.ndarray, frame_id: str | None = None):
        """A ``PoseStamped`` of a 4x4 pose stamped now (the stamp identifies it in /diagnostics)."""
        from manip_kin.nodes.conversions import make_pose_stamped

        return make_pose_stamped(pose, frame_id or self.base_frame, self.node.get_clock().now().to_msg())

    def send_goal(self, pose: np.ndarray, frame_id: str | None = None, timeout: float = 10.0) -> str:
        """Publish a goal pose on ``/goal_pose``; returns its stamp key (see :meth:`wait_converged`)."""
        from manip_kin.nodes.conversions import stamp_key

        msg = self.pose_msg(pose, frame_id)
        self.publish_delivered("/goal_pose", msg, timeout)
        return stamp_key(msg.header.stamp)

    def send_line(self, pose: np.ndarray, frame_id: str | None = None, timeout: float = 10.0) -> str:
        """Publish a line target on ``/line_target``; returns its stamp key (see :meth:`wait_line_done`)."""
        from manip_kin.nodes.conversions import stamp_key

        msg = self.pose_msg(pose, frame_id)
        self.publish_delivered("/line_target", msg, timeout)
        return stamp_key(msg.header.stamp)

    # --- waiting ---------------------------------------------------------------------------------

    def wait_status(self, name: str, timeout: float = 10.0, after_ns: int = 0) -> Status:
        """Wait for a status of node ``name`` received after ``after_ns``."""
        status = self.spin_until(
            lambda: (s := self._statuses.get(name)) is not None and s.received_ns > after_ns and s, timeout
        )
        if status is None:
            raise PipelineError(f"no /diagnostics from {name} within {timeout:g} s")
        return status

    def wait_converged(
        self, goal_stamp: str, timeout: float = 30.0, controller: str = "cartesian_controller"
    ) -> tuple[bool, Status | None]:
        """Wait until the controller reports ``converged`` on the goal stamped ``goal_stamp``.

        Returns:
            ``(converged, last status about that goal)``; the status has ``position_error``
            [m] and ``orientation_error`` [rad].
        """
        last: list[Status | None] = [None]

        def done():
            status = self._statuses.get(controller)
            if status is None or status.values.get("goal_stamp") != goal_stamp:
                return False
            last[0] = status
            return status.message == "converged"

        converged = bool(self.spin_until(done, timeout))
        return converged, last[0]

    def wait_line_done(
        self, target_stamp: str, timeout: float = 60.0, generator: str = "trajectory_generator"
    ) -> Status:
        """Wait until the generator finished (``holding``) or rejected the target ``target_stamp``.

        Returns:
            The generator's status: ``message`` is ``holding`` (``final_goal_stamp`` set) or
            ``rejected`` (``last_rejection`` says why; ``rejected_stamp`` is the target's).

        Raises:
            PipelineError: neither within ``timeout``.
        """

        def done():
            status = self._statuses.get(generator)
            if status is None:
                return None
            if status.values.get("rejected_stamp") == target_stamp:
                return status
            if status.values.get("target_stamp") == target_stamp and status.message == "holding":
                return status
            return None

        status = self.spin_until(done, timeout)
        if status is None:
            last = self._statuses.get(generator)
            raise PipelineError(
                f"line not finished within {timeout:g} s (generator state: {last.message if last else 'no status'})"
            )
        return status

    def current_positions(self, timeout: float = 5.0) -> np.ndarray:
        """Newest ``/joint_states`` positions (message order), waiting for one if needed."""
        self.watch_state()
        self.joint_state = None
        msg = self.spin_until(lambda: self.joint_state, timeout)
        if msg is None:
            raise PipelineError(f"no /joint_states within {timeout:g} s")
        return np.array(msg.position)

    def current_tool_pose(self, timeout: float = 5.0) -> np.ndarray:
        """Newest ``/tool_pose`` as a 4x4 pose, waiting for one if needed."""
        from manip_kin.nodes.conversions import pose_stamped_to_matrix

        self.watch_state()
        self.tool_pose = None
        msg = self.spin_until(lambda: self.tool_pose, timeout)
        if msg is None:
            raise PipelineError(f"no /tool_pose within {timeout:g} s")
        return pose_stamped_to_matrix(msg)
