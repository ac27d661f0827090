"""Live figures of the three manip_kin nodes running as separate processes.

``run_node_benchmarks()`` returns rows for ``bench/run.py`` (``make bench``):

* loop rate and p99 period error of robot_state and cartesian_controller at 500 Hz and
  1 kHz (from the loop statistics the nodes publish on /diagnostics), while the
  controller tracks the genova7 pose goal;
* CPU per node [% of one core] from ``/proc/<pid>/stat`` over the same window;
* goal-to-first-reacting-command latency: goals alternate 1 cm above and below the
  current tool pose; the latency is from just before ``publish`` of a goal to the arrival
  (in this process, polled without an executor) of the first ``/joint_velocity_commands``
  whose tool z velocity has the new sign. With the acceleration and jerk limits (on by
  default since issue 24) that includes reversing the command within them; goals 10 µm
  apart, a change the limits let through in one period, measure the reaction alone;
* the floor under that latency: a round trip to another Python process and back with the
  nodes' transport and wait set and no work in between, on the idle machine and beside the
  1 kHz pipeline;
* maximum distance of the tool from the straight segment during the irb120 line of
  scenario (b) at 0.4 m/s, 1 kHz;
* two full pipelines side by side on one domain (genova7 in ``/left``, irb120 in
  ``/right``), both at 500 Hz and both tracking a goal: loop rate, p99 period error and
  CPU of each of the six nodes.

Each configuration also runs with the nodes at SCHED_FIFO priority (``realtime_priority``:
the loop threads and the threads they wait on) where the machine allows it: on a shared
machine the default scheduler lets other jobs delay a 1 ms loop.

Run alone: ``.venv/bin/python bench/bench_nodes.py`` (``... two``: the two-pipeline rows only).
"""

from __future__ import annotations

import json
import math
import os
import struct
import sys
import tempfile
import time

import numpy as np

#: The line of the line rows: scenario (b)'s 0.4 m/s with its corners rounded at the generator's
#: default jerk (5 m/s³), so that it asks for no jerk step the controller's limits must round
#: off late (against the trapezoid at 1 kHz, normal scheduling, 2026-12-03: 0.06–0.19 mm
#: against 0.07–0.65 mm, docs/performance_limits.md).
LINE_GENERATOR = {"time_scaling": "jerk_limited"}

TARGETS = {
    "rate": "1 kHz held, p99 period error ≤ 0.3 ms",
    "cpu": "≤ 20 % of one core each",
    "latency": "p99 ≤ 1 ms",
    "line": "≤ 0.2 mm at 1 kHz, normal scheduling",
}
REFERENCE = "MoveIt Servo default cycle 10 ms; one rclpy timer ~0.3 ms p99 at 1 kHz; JointState IPC ~0.2 ms p50"


def _samples(values: list) -> np.ndarray:
    """``values`` as an array, or one NaN when there are none (a row then says so, not raises)."""
    return np.array(values) if len(values) else np.array([math.nan])


def _cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _loop_rows(
    rate_hz: float,
    priority: int,
    window: float = 4.0,
    kernel_default_slice: bool = False,
    controller: dict | None = None,
    tag: str = "",
    floor: bool = True,
    latency_steps: tuple[tuple[float, int], ...] = ((0.01, 500), (1e-5, 500)),
) -> list[dict]:
    """Loop, CPU and (at 1 kHz) latency rows of one pipeline. ``kernel_default_slice``: the nodes
    run with ``scheduler_slice`` 0 (what a loop thread gets without asking), loop rows only.
    ``controller``: extra controller parameters, named by ``tag`` in the labels; ``floor``:
    with the round-trip row beside the pipeline (at 1 kHz); ``latency_steps``: one latency row
    per ``(goal step [m], trials)``."""
    from manip_kin.core.rotations import make_transform, rpy_to_matrix
    from manip_kin.pipeline import Pipeline, pipeline_processes

    goal = make_transform(rpy_to_matrix(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])
    label = f"{rate_hz:g} Hz" + (f", SCHED_FIFO {priority}" if priority else "") + (f", {tag}" if tag else "")
    extra = {}
    if kernel_default_slice:
        label += ", the kernel's default slice"
        extra = {"scheduler_slice": 0.0}
    rows = []
    processes = pipeline_processes(
        "genova7",
        rate_hz=rate_hz,
        realtime_priority=priority,
        controller={**extra, **(controller or {})},
        generator=extra,
        robot_state=extra,
    )
    with Pipeline(processes, log_dir=tempfile.mkdtemp(prefix="bench_nodes_")) as pipeline:
        client = pipeline.client()
        client.spin_for(1.0)
        client.send_goal(goal)
        names = list(pipeline.processes)
        start_cpu = {name: _cpu_seconds(pipeline.pid(name)) for name in names}
        start = time.monotonic()
        client.spin_for(window)
        elapsed = time.monotonic() - start
        for name in names:
            cpu = 100.0 * (_cpu_seconds(pipeline.pid(name)) - start_cpu[name]) / elapsed
            status = client.latest_status(name)
            row = {"metric": f"{name} loop, {label}", "cpu_percent": cpu}
            if status is not None:
                row.update(
                    rate_hz=status.number("loop_rate_hz"),
                    p99_period_error_ms=status.number("loop_period_error_p99_ms"),
                    max_period_error_ms=status.number("loop_period_error_max_ms"),
                    compute_mean_ms=status.number("loop_compute_mean_ms"),
                    scheduling=status.values.get("loop_scheduling", ""),
                )
            row["target"] = (
                f"{TARGETS['rate']}; {TARGETS['cpu']}" if name != "trajectory_generator" else "(idle while no line)"
            )
            row["reference"] = REFERENCE
            rows.append(row)
        if rate_hz >= 1000 and not kernel_default_slice:
            if floor:  # the floor under the latency, measured while the same nodes load the machine
                rows.append(_round_trip_row(label=f"beside the pipeline at {label}"))
            rows += [_latency_row(pipeline, label, priority, trials, step) for step, trials in latency_steps]
    return rows


def _latency_row(pipeline, label: str, priority: int, trials: int = 500, step_m: float = 0.01) -> dict:
    """Goals ``step_m`` above and below the tool pose in turn, 10 ms apart; the latency of each
    is until the first command whose tool z velocity has the new sign (beyond ``step_m`` x 0.01
    1/s, 1e-4 m/s at the 1 cm step). With acceleration and jerk limits a 1 cm step reverses
    the command within them (milliseconds); a step the limits let through in one period
    (10 µm on genova7) measures the reaction alone."""
    from std_msgs.msg import Float64MultiArray

    from manip_kin.core.kinematics import pose_and_jacobian_in_base
    from manip_kin.core.robots import load_robot
    from manip_kin.ros.wire.messages import make_pose_stamped

    model = load_robot("genova7")
    client = pipeline.client()
    # Hold still first: the first trials then do not start from the scenario's motion.
    client.send_goal(pose_and_jacobian_in_base(model, client.current_positions(), model.frame_index("tool"))[0])
    client.spin_for(0.5)
    q = client.current_positions()
    client.unwatch_state()  # the measurement reads only the commands
    pose, jac = pose_and_jacobian_in_base(model, q, model.frame_index("tool"))
    z_row = jac[5].tolist()  # the tool's z velocity per joint velocity
    from rclpy.qos import QoSProfile
    from rclpy.serialization import deserialize_message

    from manip_kin.ros.runtime.polling import RawSubscription
    from manip_kin.ros.runtime.scheduling import (
        TIMER_SLACK_NS,
        SharedPriority,
        set_timer_slack,
        share_realtime_priority,
    )

    # Commands are polled in this thread (no executor in the path); with the nodes at SCHED_FIFO
    # this thread and the ones it waits on (as in the nodes) get the same priority, or the
    # measurement would wait behind them.
    shared = SharedPriority(0)
    if priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            shared = share_realtime_priority(priority)
        except OSError:
            pass
    # With their middleware info: when the controller published the command (source
    # timestamp) and when this process's middleware had it (received timestamp).
    commands = RawSubscription(client.node, Float64MultiArray, "joint_velocity_commands", QoSProfile(depth=100))
    # Poll in 20 µs steps, not 20 µs + the default 50 µs timer slack.
    set_timer_slack(TIMER_SLACK_NS)
    client.spin_for(0.5)
    publisher = client.publisher(type(make_pose_stamped(pose, "base_link")), "goal_pose")
    # The command's joint velocities are the last doubles of its CDR bytes (an empty layout):
    # read there, checked once against rclpy. deserialize_message of a command cost ~85 µs
    # (p50) here, run once per goal after a 10 ms sleep: it delayed the polling of the next.
    tail = struct.Struct(f"<{len(q)}d")
    first = client.spin_until(commands.take, 2.0)
    if first is None or list(tail.unpack_from(first[0], len(first[0]) - tail.size)) != list(
        deserialize_message(first[0], Float64MultiArray).data
    ):
        raise RuntimeError("joint_velocity_commands: not a Float64MultiArray with an empty layout")
    latencies, published, received = [], [], []
    threshold = step_m * 0.01
    try:
        for trial in range(trials):
            sign = 1.0 if trial % 2 == 0 else -1.0
            goal = pose.copy()
            goal[2, 3] += sign * step_m
            msg = client.pose_msg(goal)
            while commands.take() is not None:
                pass
            sent = time.monotonic_ns()
            sent_wall = time.time_ns()  # the middleware's timestamps are on this clock
            publisher.publish(msg)
            deadline = sent + 500_000_000
            while time.monotonic_ns() < deadline:
                taken = commands.take()
                if taken is None:
                    time.sleep(20e-6)
                    continue
                arrived = time.monotonic_ns()
                data, info = taken
                velocities = tail.unpack_from(data, len(data) - tail.size)
                if sum(row * velocity for row, velocity in zip(z_row, velocities)) * sign > threshold:
                    latencies.append((arrived - sent) * 1e-6)
                    published.append((info.get("source_timestamp", 0) - sent_wall) * 1e-6)
                    received.append((info.get("received_timestamp", 0) - sent_wall) * 1e-6)
                    break
            time.sleep(0.01)
    finally:
        if priority:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            shared.restore()
    values = _samples(latencies)
    # Where the time goes: goal published -> the command published by the controller (one hop
    # and the reaction) -> in this process's middleware (the second hop) -> seen here (polling).
    published_values = _samples(published)
    received_values = _samples(received)
    return {
        "metric": f"goal-to-first-reacting-command latency, {label}"
        + (f", goals ±{step_m * 1e3:g} mm" if step_m != 0.01 else ""),
        "p50_ms": float(np.percentile(values, 50)),
        "p99_ms": float(np.percentile(values, 99)),
        "max_ms": float(values.max()),
        "trials": len(latencies),
        "command_published_p50_ms": float(np.percentile(published_values, 50)),
        "command_published_p99_ms": float(np.percentile(published_values, 99)),
        "command_received_p50_ms": float(np.percentile(received_values, 50)),
        "command_received_p99_ms": float(np.percentile(received_values, 99)),
        "target": TARGETS["latency"],
        "reference": REFERENCE,
    }


def _echo(seconds: float) -> None:
    """The far end of :func:`_round_trip_row`: returns every ``ping`` on ``pong`` at once."""
    import rclpy
    from std_msgs.msg import Float64MultiArray

    from manip_kin.ros.runtime.polling import LoopWaiter, PolledSubscription
    from manip_kin.ros.runtime.scheduling import TIMER_SLACK_NS, set_timer_slack

    rclpy.init()
    node = rclpy.create_node("bench_echo")
    pings = PolledSubscription(node, Float64MultiArray, "ping", 10)
    pongs = node.create_publisher(Float64MultiArray, "pong", 10)
    waiter = LoopWaiter(node, [pings])  # how a node's loop waits for a goal
    set_timer_slack(TIMER_SLACK_NS)
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end and rclpy.ok():
            waiter.wait(1_000_000)
            while (data := pings.take(raw=True)) is not None:
                pongs.publish(data)
    except Exception:  # noqa: BLE001 - terminated (SIGTERM shuts the context down): just end
        pass


def _round_trip_row(trials: int = 300, label: str = "idle machine") -> dict:
    """The floor under the goal-to-command latency: a message to another Python process and back.

    The same path as a goal and its command (rclpy, the middleware, the node's wait set, the
    polled reply), with no work in between: two hops of inter-process delivery. ``label``
    says what else runs (the latency itself is measured beside a running pipeline).
    """
    import subprocess

    import rclpy
    from std_msgs.msg import Float64MultiArray

    from manip_kin.ros.runtime.polling import PolledSubscription
    from manip_kin.ros.runtime.scheduling import TIMER_SLACK_NS, set_timer_slack

    echo = subprocess.Popen([sys.executable, __file__, "echo", str(trials * 0.02 + 15)])
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("bench_ping", context=context)
    latencies = []
    try:
        pings = node.create_publisher(Float64MultiArray, "ping", 10)
        pongs = PolledSubscription(node, Float64MultiArray, "pong", 10)
        set_timer_slack(TIMER_SLACK_NS)
        deadline = time.monotonic() + 10
        while pings.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        for trial in range(trials):
            sent = time.monotonic_ns()
            pings.publish(Float64MultiArray(data=[float(trial)]))
            while time.monotonic_ns() - sent < 500_000_000:
                if pongs.take(raw=True) is not None:
                    latencies.append((time.monotonic_ns() - sent) * 1e-6)
                    break
                time.sleep(20e-6)
            time.sleep(0.01)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
        echo.terminate()
        try:
            echo.wait(5)
        except subprocess.TimeoutExpired:
            echo.kill()
            echo.wait()
    values = _samples(latencies)
    return {
        "metric": f"inter-process round trip (ping to a Python process and back), no work in between, {label}",
        "p50_ms": float(np.percentile(values, 50)),
        "p99_ms": float(np.percentile(values, 99)),
        "max_ms": float(values.max()),
        "trials": len(latencies),
        "target": "(the floor under the goal-to-command latency: two such hops)",
        "reference": "same transport, wait set and polling as the nodes",
    }


def _wake_up_times(trials: int = 1000) -> dict[str, list[float]]:
    """Round trips [µs] of 8 bytes through two pipes to a forked process, both on one CPU and
    on two CPUs, 2 ms apart (the far end sleeps between them, as a node's thread does).
    Run in a process of its own (``bench_nodes.py wake``): it forks."""
    results: dict[str, list[float]] = {}
    for label, far_cpu in (("same CPU", 0), ("two CPUs", 1)):
        to_far, from_near = os.pipe()
        to_near, from_far = os.pipe()
        pid = os.fork()
        if pid == 0:  # the far end: echo until told to stop
            os.sched_setaffinity(0, {far_cpu})
            while (data := os.read(to_far, 8)) not in (b"", b"stop0000"):  # b"": the near end is gone
                os.write(from_far, data)
            os._exit(0)
        os.sched_setaffinity(0, {0})
        times = []
        for _ in range(trials):
            begin = time.monotonic_ns()
            os.write(from_near, b"ping0000")
            os.read(to_near, 8)
            times.append((time.monotonic_ns() - begin) * 1e-3)
            time.sleep(0.002)
        os.write(from_near, b"stop0000")
        os.waitpid(pid, 0)
        for fd in (to_far, from_near, to_near, from_far):
            os.close(fd)
        results[label] = times
    os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))
    return results


def _wake_up_rows() -> list[dict]:
    """What waking a sleeping thread costs on this machine, on its own CPU and on another:
    every hop of a message wakes one or two threads, most often on the other CPU."""
    import subprocess

    if not {0, 1} <= os.sched_getaffinity(0):  # CPUs 0 and 1 to pin the two ends on
        return []
    done = subprocess.run([sys.executable, __file__, "wake"], capture_output=True, text=True, timeout=120, check=True)
    rows = []
    for label, times in json.loads(done.stdout).items():
        values = np.array(times)
        rows.append(
            {
                "metric": f"pipe round trip to a sleeping process, {label} (two wake-ups, no middleware), idle",
                "p50_us": float(np.percentile(values, 50)),
                "p99_us": float(np.percentile(values, 99)),
                "trials": len(times),
                "target": "(the machine under the round trip: a wake-up across CPUs on this VM)",
                "reference": "one CPU against two: what waking a thread on the other CPU adds",
            }
        )
    return rows


def _line_row(
    rate_hz: float,
    priority: int,
    robot_state: dict | None = None,
    generator: dict | None = None,
    controller: dict | None = None,
    tag: str = "",
) -> dict:
    """The irb120 line, timed ``jerk_limited`` (see :data:`LINE_GENERATOR`); ``generator`` and
    ``controller``: extra parameters, named by ``tag`` in the label."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from manip_kin.core.rotations import make_transform, rpy_to_matrix
    from manip_kin.motion.lines import distance_to_segment
    from manip_kin.pipeline import IRB120_LINE_GENERATOR, Pipeline, pipeline_processes
    from manip_kin.ros.runtime.polling import PolledSubscription
    from manip_kin.ros.wire.messages import pose_stamped_to_matrix

    start, end = [0.4, 0.1, 0.6], [-0.4, 0.3, 0.5]
    down = rpy_to_matrix(0.0, math.pi / 2, 0.0)
    line_generator = {**IRB120_LINE_GENERATOR, **LINE_GENERATOR, **(generator or {})}
    processes = pipeline_processes(
        "irb120",
        rate_hz=rate_hz,
        initial_positions=[0.0] * 6,
        controller={"gain_linear": 6.0, "gain_angular": 6.0, **(controller or {})},
        generator=line_generator,
        realtime_priority=priority,
        robot_state=robot_state,
    )
    label = f"{rate_hz:g} Hz" + (f", SCHED_FIFO {priority}" if priority else "") + (f", {tag}" if tag else "")
    with Pipeline(processes, log_dir=tempfile.mkdtemp(prefix="bench_line_")) as pipeline:
        client = pipeline.client()
        converged, _ = client.wait_converged(client.send_goal(make_transform(down, start)), 30)
        # Polled once the line is over, not taken by the client's executor as it runs: a Python
        # callback for each of the 1000 poses a second cost this client ~48 % of a core, which
        # the pipeline's own loops then lost on this 2-core machine (measured 2026-12-03).
        poses = PolledSubscription(
            client.node, PoseStamped, "tool_pose", QoSProfile(depth=30000, reliability=ReliabilityPolicy.RELIABLE)
        )
        # The segment is the one the generator planned (its path, latched): it starts where the
        # arm was when the line began, which is the start pose only within the convergence
        # tolerance (~0.07 mm here, which the nominal segment would count as deviation).
        paths: list[Path] = []
        latched = QoSProfile(
            depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
        )
        client.node.create_subscription(Path, "planned_path", paths.append, latched)
        client.spin_for(0.3)
        done = client.wait_line_done(client.send_line(make_transform(down, end)), 15)
        final, status = client.wait_converged(done.values.get("final_goal_stamp", ""), 15)
        samples = []
        while (pose := poses.take()) is not None:
            samples.append(pose_stamped_to_matrix(pose)[:3, 3])
        planned = [pose_stamped_to_matrix(p)[:3, 3] for p in paths[-1].poses] if paths else [start, end]
        offset = float(np.linalg.norm(np.asarray(planned[0]) - start))
        deviation = distance_to_segment(np.array(samples), planned[0], planned[-1]) if samples else np.array([math.nan])
        return {
            "metric": f"irb120 line 0.4 m/s, max deviation from the planned segment, {label}",
            "max_deviation_mm": float(deviation.max() * 1e3),
            "p99_deviation_mm": float(np.percentile(deviation, 99) * 1e3),
            "samples": len(samples),
            "planned_start_offset_mm": offset * 1e3,
            "line_s": done.number("duration"),
            "reached_start": converged,
            "converged_end": final,
            "target": TARGETS["line"],
            "reference": f"gains 6/6 1/s, feed-forward twist, {line_generator['time_scaling']} line",
        }


def _two_pipeline_rows(rate_hz: float = 500.0, priority: int = 0, window: float = 6.0) -> list[dict]:
    from manip_kin.core.kinematics import frame_pose
    from manip_kin.core.robots import load_robot
    from manip_kin.pipeline import Pipeline, pipeline_processes

    arms = {
        "/left": ("genova7", None, frame_pose(load_robot("genova7"), [1.8, -0.6, 0.2, -0.9, 0.2, 0.1, 1.0])),
        "/right": (
            "irb120",
            [0.0, 0.3, 0.0, 0.0, 0.5, 0.0],
            frame_pose(load_robot("irb120"), [0.6, 0.1, 0.3, 0.4, 0.9, 0.5]),
        ),
    }
    label = f"two pipelines side by side, {rate_hz:g} Hz" + (f", SCHED_FIFO {priority}" if priority else "")
    pipelines = {}
    rows = []
    try:
        for namespace, (robot, start, _) in arms.items():
            processes = pipeline_processes(robot, rate_hz=rate_hz, initial_positions=start, realtime_priority=priority)
            pipeline = Pipeline(processes, log_dir=tempfile.mkdtemp(prefix="bench_two_"), namespace=namespace)
            pipelines[namespace] = pipeline
            pipeline.start()
        for namespace, (_, _, goal) in arms.items():
            pipelines[namespace].client().send_goal(goal)  # default gains 0.8/s: tracking for seconds
        for pipeline in pipelines.values():
            pipeline.client().spin_for(1.0)
        start_cpu = {(ns, name): _cpu_seconds(p.pid(name)) for ns, p in pipelines.items() for name in p.processes}
        start = time.monotonic()
        while time.monotonic() - start < window:
            for pipeline in pipelines.values():
                pipeline.client().spin_for(0.05)
        elapsed = time.monotonic() - start
        for namespace, pipeline in pipelines.items():
            client = pipeline.client()
            for name in pipeline.processes:
                cpu = 100.0 * (_cpu_seconds(pipeline.pid(name)) - start_cpu[(namespace, name)]) / elapsed
                status = client.latest_status(name)
                row = {"metric": f"{namespace[1:]}/{name} loop, {label}", "cpu_percent": cpu}
                if status is not None:
                    row.update(
                        state=status.message,
                        rate_hz=status.number("loop_rate_hz"),
                        p99_period_error_ms=status.number("loop_period_error_p99_ms"),
                        max_period_error_ms=status.number("loop_period_error_max_ms"),
                    )
                row["target"] = "500 Hz held by all six, p99 period error ≤ 0.5 ms"
                row["reference"] = "one pipeline alone: the rows above"
                rows.append(row)
    finally:
        for pipeline in pipelines.values():
            pipeline.stop()
    return rows


def run_two_pipeline_benchmarks(priorities: tuple[int, ...] = (0, 20)) -> list[dict]:
    """Two pipelines at 500 Hz side by side, per scheduling priority."""
    from manip_kin.pipeline import ensure_ros_isolation

    ensure_ros_isolation()
    return [row for priority in priorities for row in _two_pipeline_rows(500.0, priority)]


def run_node_benchmarks(priorities: tuple[int, ...] = (0, 20)) -> list[dict]:
    """Every figure above, as rows ``{"metric", values..., "target", "reference"}``."""
    from manip_kin.pipeline import ensure_ros_isolation

    ensure_ros_isolation()
    rows: list[dict] = _wake_up_rows() + [_round_trip_row()]
    for priority in priorities:
        for rate_hz in (500.0, 1000.0):
            rows += _loop_rows(rate_hz, priority)
        if not priority:
            # What the slice buys: the same 1 kHz loops on the kernel's default slice.
            rows += _loop_rows(1000.0, 0, kernel_default_slice=True)
        rows.append(_line_row(1000.0, priority))
        if not priority:
            rows.append(_line_row(1000.0, 0, generator={"time_scaling": "trapezoidal"}, tag="trapezoid"))
        rows += _two_pipeline_rows(500.0, priority)
    return rows


if __name__ == "__main__":
    # ``bench_nodes.py two``: only the two-pipeline figures; ``echo SECONDS``: the far end of the
    # round trip; ``wake``: the wake-up times of _wake_up_rows.
    if sys.argv[1:2] == ["echo"]:
        _echo(float(sys.argv[2]))
        sys.exit(0)
    if sys.argv[1:2] == ["wake"]:
        json.dump(_wake_up_times(), sys.stdout)
        sys.exit(0)
    results = run_two_pipeline_benchmarks() if sys.argv[1:] == ["two"] else run_node_benchmarks()
    json.dump(results, sys.stdout, indent=1)
    sys.stdout.write("\n")
