"""Run the manip_kin nodes without ``ros2 launch``: a supervisor of node processes.

:class:`Pipeline` starts node executables as subprocesses with their parameters, waits
until each one's control loop runs (its first ``/diagnostics`` status), and stops them
cleanly (SIGINT, then SIGTERM, then SIGKILL after timeouts). Any process can join: a
:class:`~manip_kin.pipeline.node_process.NodeProcess` is an executable name, a node name, a namespace and parameters, so the
recorder is one more entry in the list (see :func:`~manip_kin.pipeline.node_process.pipeline_processes`). A pipeline in a
namespace (``Pipeline(..., namespace="/left")``) runs every node with ``-r __ns:=/left``, so
two arms share one domain without seeing each other's topics.

Example::

    with Pipeline(pipeline_processes("genova7", rate_hz=1000), namespace="/left") as pipeline:
        client = pipeline.client()
        stamp = client.send_goal(goal_pose)
        status = client.wait_converged(stamp, timeout=30)
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

from manip_kin.pipeline.client import PipelineClient
from manip_kin.pipeline.domain import ensure_ros_isolation, node_environment
from manip_kin.pipeline.errors import PipelineError
from manip_kin.pipeline.node_process import NodeProcess, find_executable
from manip_kin.pipeline.status import normalize_namespace

#: Fast DDS's environment variable choosing its built-in transports (shared memory + UDP by default).
FAST_DDS_TRANSPORTS = "FASTDDS_BUILTIN_TRANSPORTS"


class Pipeline:
    """Node processes started together and stopped together.

    Args:
        processes: what to run, in start order.
        executable_dir: where the executables are (e.g. ``install/manip_kin/lib/manip_kin``);
            default: next to this Python, else PATH.
        env: environment of the children (default: this process's, completed by
            :func:`ensure_ros_isolation`).
        log_dir: where each process's output goes (``NAME.log``); default: a temp dir.
        namespace: every process that sets none runs in this namespace (``-r __ns:=NS``),
            and :meth:`client` talks to it.
    """

    def __init__(
        self,
        processes: Iterable[NodeProcess],
        executable_dir: str | os.PathLike | None = None,
        env: Mapping[str, str] | None = None,
        log_dir: str | os.PathLike | None = None,
        namespace: str = "",
    ):
        self.namespace = normalize_namespace(namespace)
        self.processes = {
            spec.name: spec if spec.namespace else replace(spec, namespace=self.namespace) for spec in processes
        }
        self.executable_dir = executable_dir
        self.env = ensure_ros_isolation(dict(env) if env is not None else None)
        if env is None:
            self.env = dict(self.env)
        self.env.setdefault("PYTHONUNBUFFERED", "1")
        self.log_dir = Path(log_dir) if log_dir else Path(tempfile.mkdtemp(prefix="manip_kin_pipeline_"))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self._popen: dict[str, subprocess.Popen] = {}
        self._killed: set[str] = set()  # ended by SIGKILL: restarted on UDP only (start_process)
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
        command = [*spec.prefix, find_executable(spec.executable, self.executable_dir), *spec.arguments()]
        env = node_environment(self.env)
        log = open(self.log_dir / f"{name}.log", "ab")  # noqa: SIM115 - closed in stop
        if name in self._killed and FAST_DDS_TRANSPORTS not in env:
            # Fast DDS 2.14 (Jazzy): the shared-memory port a SIGKILLed process leaves behind can
            # leave its successor matched but receiving nothing (eProsima/Fast-DDS#5053, #2811;
            # seen once here: a restarted controller without joint states for 40 s). UDP does not.
            # rmw_fastrtps honours the variable only where it keeps Fast DDS's built-in
            # transports: with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST it configures shared
            # memory and UDP itself, so the log says so rather than claim a switch.
            env = {**env, FAST_DDS_TRANSPORTS: "UDPv4"}
            note = ""
            if env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") == "LOCALHOST":
                note = (
                    " (no effect with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: rmw_fastrtps adds shared memory itself)"
                )
            log.write(f"# restarted after a SIGKILL: {FAST_DDS_TRANSPORTS}=UDPv4{note}\n".encode())
        log.write(f"$ {' '.join(command)}\n".encode())
        log.flush()
        self._logs[name] = log
        self._popen[name] = subprocess.Popen(
            command, env=env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
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
                    status = client.latest_status(spec.status_name)
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

        Before the SIGKILL it sends SIGUSR1: a manip_kin node then writes its threads' Python
        stacks to its log (``faulthandler``), so a node that would not stop says where it hung.

        ``sig=None`` only waits ``timeout`` before escalating (the caller already signalled).
        """
        popen = self._popen.get(name)
        if popen is None:
            return None
        if popen.poll() is None:
            for signal_number, wait in ((sig, timeout), (signal.SIGTERM, 2.0), (signal.SIGKILL, 5.0)):
                try:
                    if signal_number == signal.SIGKILL and sig != signal.SIGKILL:
                        # Still alive after SIGINT and SIGTERM: ask for its threads' stacks first
                        # (the nodes register SIGUSR1 with faulthandler), so the log says where it hung.
                        popen.send_signal(signal.SIGUSR1)
                        time.sleep(0.5)
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
        if popen.returncode == -signal.SIGKILL:
            self._killed.add(name)
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
            self._client = PipelineClient(env=self.env, namespace=self.namespace)
        return self._client
