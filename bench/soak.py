#!/usr/bin/env python3
"""``make soak``: the full pipeline, the recorder and the live view at 1 kHz for minutes, lines alternating.

The Panda pipeline (robot_state, cartesian_controller, trajectory_generator) runs with what
a cell runs: the joint limits on (the defaults, from the URDF), ``collision_avoidance`` with
the Panda's collision geometry and SRDF and three obstacles on ``collision_objects`` (those
of bench_collision), the recorder (every manip_kin topic) and ``live_view`` with a Foxglove
client connected and subscribed to every channel for the whole run
(test/foxglove_client). Every process is separate, at ``--rate-hz``; every ``--switch-s``
seconds a line target alternates between two poses either side of the ready pose, clear of
the obstacles. The nodes' loop threads run at SCHED_FIFO 20 where this process may use it (a
cell's 1 kHz controller runs real-time, as ros2_control's controller manager does), else at
normal scheduling; ``--realtime-priority P`` sets the priority (0 = normal scheduling).
Reported, as JSON (``--out``) and a table:

* per process (the live view client too): RSS at minute 1 and at the end (growth in %), CPU
  share of one core over the run, alive at the end;
* per ``--window-s`` window: ``/joint_states`` messages received here per second, the p99
  of ``|Δstamp - period|`` of those messages, and per node the worst
  ``loop_period_error_p99_ms`` its ``/diagnostics`` reported in the window;
* the recorder: its own summary line (dropped = sequence gaps and middleware losses), the
  count of each topic in the file, and the ``/joint_states`` messages this process saw
  while the recorder ran that are missing from the file;
* every ERROR status on ``/diagnostics``; the controller's states (how often each was
  reported), so a line blocked by an obstacle shows;
* the live view client: messages per topic and its ``/joint_states`` rate.

Targets (issues 8 and 29), each checked in ``checks`` (value, target, pass): RSS growth ≤ 5 %
for every node (the client keeps every receive time it reports, so its growth is shown, not
checked), every window ≥ 990 Hz, zero messages lost (the recorder's dropped count
plus what this process saw that the file lacks), every process alive at the end, no ERROR.
The machine is shared: load from other jobs shows in the windows, so the table carries the
load average too.

Run: ``make soak`` (10 minutes) or ``.venv/bin/python bench/soak.py --minutes 1``.
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(
    0, str(Path(__file__).resolve().parent.parent / "test" / "support")
)  # collision_robots, live_view_client

#: The lines' ends: offsets [m] from the Panda's ready hand position, 0.3 m apart in y, away
#: from bench_collision's sphere (which sits 0.16 m in front of the hand).
LINE_OFFSETS = ([-0.05, -0.15, 0.05], [-0.05, 0.15, 0.05])
#: The line's speed and acceleration (trapezoidal; 0.3 m at 0.2 m/s takes ~1.9 s of each 4 s).
LINE_GENERATOR = {
    "time_scaling": "trapezoidal",
    "max_linear_velocity": 0.2,
    "max_linear_acceleration": 0.5,
    "max_angular_velocity": 1.0,
}
LIVE_VIEW_PORT = 18766
TARGETS = {"rss_growth_percent": 5.0, "min_window_hz": 990.0, "lost": 0, "errors": 0, "all_alive": True}


def _rss_kib(pid: int) -> int:
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def _cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class JointStateCounter:
    """Drains ``/joint_states`` (raw CDR) in its own thread; keeps arrival times and stamps.

    Best effort: a reliable reader would cost robot_state a middleware wake-up per message
    (see ``nodes/topics.py``), which this observer should not add to what it measures. What
    it sees is a sample; each message it sees must be in the recording.
    """

    def __init__(self, node):
        from sensor_msgs.msg import JointState

        from manip_kin.ros.runtime.polling import PolledSubscription
        from manip_kin.ros.wire.topics import latest_state_qos

        self._sub = PolledSubscription(node, JointState, "/joint_states", latest_state_qos(2000))
        self.arrivals: list[int] = []
        self.stamps: list[int] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="joint_state_counter", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _run(self) -> None:
        take = self._sub.take
        while not self._stop.is_set():
            now = time.monotonic_ns()
            while (data := take(raw=True)) is not None:
                sec, nanosec = struct.unpack_from("<iI", data, 4)
                self.arrivals.append(now)
                self.stamps.append(sec * 1_000_000_000 + nanosec)
            time.sleep(0.005)


def _recorder_dropped(summary: str) -> int | None:
    """The recorder's dropped count from its summary line (``...; N dropped ...``); None if absent."""
    for part in summary.split(";"):
        words = part.split()
        if len(words) >= 2 and words[1] == "dropped" and words[0].isdigit():
            return int(words[0])
    return None


def _add_obstacles(env: dict, base_frame: str, hand_xyz: np.ndarray) -> None:
    """bench_collision's three obstacles on ``collision_objects``, through ``manip_kin obstacle add``."""
    import sysconfig

    from bench_collision import _obstacle_arguments

    manip_kin = str(Path(sysconfig.get_path("scripts")) / "manip_kin")
    for k, arguments in enumerate(_obstacle_arguments(hand_xyz)):
        # A fresh CLI process discovers the controller in up to 10 s; beside 1 kHz loops (at
        # SCHED_FIFO above all) that once took longer: it tries again before giving up.
        for _attempt in range(3):
            done = subprocess.run(
                [manip_kin, "obstacle", "add", "--id", str(k + 1), *arguments, "--frame", base_frame],
                env=env,
                capture_output=True,
                text=True,
                timeout=60,
            )
            if done.returncode == 0:
                break
        else:
            raise RuntimeError(f"manip_kin obstacle add failed 3 times: {done.stderr.strip()}")


def run_soak(
    minutes: float, rate_hz: float, window_s: float, switch_s: float, out_dir: Path, realtime_priority: int = 0
) -> dict:
    from collision_robots import PANDA_READY, panda_files
    from diagnostic_msgs.msg import DiagnosticArray
    from live_view_client import start_client

    from manip_kin.core.kinematics import frame_pose
    from manip_kin.core.urdf import load_urdf
    from manip_kin.pipeline import NodeProcess, Pipeline, PipelineError, ensure_ros_isolation, pipeline_processes

    env = ensure_ros_isolation()
    urdf, srdf, share = panda_files()
    model = load_urdf(urdf)
    hand = frame_pose(model, PANDA_READY, "ee")
    poses = []
    for offset in LINE_OFFSETS:
        pose = hand.copy()
        pose[:3, 3] += offset
        poses.append(pose)
    recording = out_dir / "soak.mcap"
    processes = [
        NodeProcess("recorder", "recorder", {"output": str(recording)}),
        *pipeline_processes(
            str(urdf),
            rate_hz=rate_hz,
            initial_positions=PANDA_READY.tolist(),
            controller={
                "gain_linear": 6.0,
                "gain_angular": 6.0,
                "collision_avoidance": True,
                "srdf": str(srdf),
                "mesh_search_path": share,
            },
            generator=LINE_GENERATOR,
            realtime_priority=realtime_priority,
        ),
        NodeProcess("live_view", parameters={"port": LIVE_VIEW_PORT}, ready_status="live_view"),
    ]
    duration_s = minutes * 60.0
    statuses: list[tuple[int, str, int, str, dict]] = []
    with Pipeline(processes, env=env, log_dir=out_dir / "logs") as pipeline:
        client = pipeline.client()
        client.node.create_subscription(
            DiagnosticArray,
            "/diagnostics",
            lambda msg: statuses.extend(
                (time.monotonic_ns(), s.name, s.level[0], s.message, {kv.key: kv.value for kv in s.values})
                for s in msg.status
            ),
            100,
        )
        _add_obstacles(env, model.base_frame, hand[:3, 3])
        converged, _ = client.wait_converged(client.send_goal(poses[0], model.base_frame), 60)
        # Connected for the whole run (and the summary after it): a live view with a reader.
        viewer = start_client(LIVE_VIEW_PORT, duration_s + 5.0)
        client.spin_for(2.0)
        counter = JointStateCounter(client.node)
        counter.start()
        pids = {name: pipeline.pid(name) for name in pipeline.processes}
        pids["live_view_client"] = viewer.pid
        names = list(pids)
        cpu_start = {name: _cpu_seconds(pid) for name, pid in pids.items()}
        start_ns, start_wall_ns = time.monotonic_ns(), time.time_ns()
        rss_minute1: dict[str, int] = {}
        next_switch = time.monotonic()
        target = 1
        lines_sent = lines_unacknowledged = 0
        load = []
        while (time.monotonic_ns() - start_ns) * 1e-9 < duration_s:
            if time.monotonic() >= next_switch:
                try:
                    client.send_line(poses[target], model.base_frame)
                    lines_sent += 1
                except PipelineError:  # not acknowledged in 10 s: counted, and the soak goes on
                    lines_unacknowledged += 1
                target = 1 - target
                next_switch += switch_s
            client.spin_for(0.1)
            elapsed = (time.monotonic_ns() - start_ns) * 1e-9
            if not rss_minute1 and elapsed >= min(60.0, duration_s / 2):
                rss_minute1 = {name: _rss_kib(pid) for name, pid in pids.items()}
            if not load or elapsed - load[-1][0] >= window_s:
                load.append((elapsed, os.getloadavg()[0]))
        end_ns = time.monotonic_ns()
        rss_end = {name: _rss_kib(pid) for name, pid in pids.items()}
        cpu = {
            name: 100.0 * (_cpu_seconds(pid) - cpu_start[name]) / ((end_ns - start_ns) * 1e-9)
            for name, pid in pids.items()
        }
        counter.stop()
        alive = {name: pipeline.running(name) for name in pipeline.processes}
        alive["live_view_client"] = viewer.poll() is None
        try:
            viewer_out, _ = viewer.communicate(timeout=30)
            viewer_result = json.loads(viewer_out)
        except (ValueError, OSError, subprocess.TimeoutExpired) as error:
            viewer.kill()
            viewer_result = {"problems": [f"no result from the client: {error}"]}
        recorder_code = pipeline.stop_process("recorder", timeout=60)
        recorder_line = pipeline.log_text("recorder").strip().splitlines()[-1]
    run = SoakRun(
        minutes=minutes,
        rate_hz=rate_hz,
        window_s=window_s,
        switch_s=switch_s,
        realtime_priority=realtime_priority,
        recording=recording,
        start_ns=start_ns,
        start_wall_ns=start_wall_ns,
        end_ns=end_ns,
        reached_line_start=bool(converged),
        names=names,
        arrivals=counter.arrivals,
        stamps=counter.stamps,
        statuses=statuses,
        rss_minute1=rss_minute1,
        rss_end=rss_end,
        cpu=cpu,
        alive=alive,
        recorder_code=recorder_code,
        recorder_line=recorder_line,
        lines_sent=lines_sent,
        lines_unacknowledged=lines_unacknowledged,
        load=load,
        viewer=viewer_result,
    )
    return _summarise(run)


@dataclass
class SoakRun:
    """What one soak collected, before it is summarised (times from ``time.monotonic_ns``)."""

    minutes: float
    rate_hz: float
    window_s: float
    switch_s: float
    realtime_priority: int
    recording: Path
    start_ns: int
    start_wall_ns: int  # the same instant on the system clock (robot_state stamps its messages with it)
    end_ns: int
    reached_line_start: bool
    names: list
    arrivals: list  # /joint_states arrival times here [ns]
    stamps: list  # their header stamps [ns]
    statuses: list  # (time, name, level, message, values) of every /diagnostics status
    rss_minute1: dict  # [KiB]
    rss_end: dict  # [KiB]
    cpu: dict  # [% of one core]
    alive: dict
    recorder_code: int | None
    recorder_line: str
    lines_sent: int
    lines_unacknowledged: int  # line targets the generator did not acknowledge within 10 s
    load: list  # (elapsed s, 1-min load average)
    viewer: dict  # the live view client's result (test/foxglove_client/client.mjs)


def _summarise(run: SoakRun) -> dict:
    from manip_kin.recording import read_info, read_messages

    start_ns, end_ns, window_s = run.start_ns, run.end_ns, run.window_s
    period_ns = 1e9 / run.rate_hz
    arrivals = np.array(run.arrivals, dtype=np.int64)
    # /joint_states as recorded: the complete sequence robot_state published (stamps on the
    # system clock); what this process received is reported too, but it is itself a busy
    # subscriber on a loaded machine.
    recorded_stamps = np.array(
        sorted(
            record[1].header.stamp.sec * 1_000_000_000 + record[1].header.stamp.nanosec
            for record in read_messages(run.recording, ["/joint_states"])
        ),
        dtype=np.int64,
    )
    wall_offset = run.start_wall_ns - start_ns
    windows = []
    edges = np.arange(start_ns, end_ns + 1, int(window_s * 1e9))
    for lo, hi in zip(edges[:-1], edges[1:]):
        stamps = recorded_stamps[(recorded_stamps >= lo + wall_offset) & (recorded_stamps < hi + wall_offset)]
        window = {
            "start_s": round((lo - start_ns) * 1e-9, 1),
            "joint_states_hz": float(stamps.size / window_s),
            "received_here_hz": float(((arrivals >= lo) & (arrivals < hi)).sum() / window_s),
        }
        if stamps.size > 2:
            window["stamp_period_error_p99_ms"] = float(np.percentile(np.abs(np.diff(stamps) - period_ns), 99) * 1e-6)
        for name in ("robot_state", "cartesian_controller", "trajectory_generator"):
            values = [
                float(v["loop_period_error_p99_ms"])
                for t, n, _, _, v in run.statuses
                if n == name and lo <= t < hi and v.get("loop_period_error_p99_ms")
            ]
            window[f"{name}_p99_ms"] = max(values) if values else None
        windows.append(window)
    errors = [
        {"t_s": round((t - start_ns) * 1e-9, 2), "node": n, "message": m}
        for t, n, level, m, _ in run.statuses
        if level == 2 and start_ns <= t <= end_ns
    ]
    nodes = {}
    for name in run.names:
        before, after = run.rss_minute1.get(name, 0), run.rss_end[name]
        nodes[name] = {
            "rss_minute1_mib": before / 1024,
            "rss_end_mib": after / 1024,
            "rss_growth_percent": 100.0 * (after - before) / before if before else None,
            "cpu_percent_of_core": run.cpu[name],
            "alive_at_end": run.alive[name],
        }
    recording = run.recording
    info = read_info(recording)
    file_counts = {topic.name: topic.message_count for topic in info.topics} if hasattr(info, "topics") else {}
    recorded = {(int(v // 1_000_000_000), int(v % 1_000_000_000)) for v in recorded_stamps}
    seen = {(int(v // 1_000_000_000), int(v % 1_000_000_000)) for v in run.stamps}
    missing = sorted(seen - recorded)
    states: dict[str, int] = {}
    for t, n, _, m, _ in run.statuses:
        if n == "cartesian_controller" and start_ns <= t <= end_ns:
            state = m.split(":")[0]
            states[state] = states.get(state, 0) + 1
    viewer_times = run.viewer.get("times", {}).get("/joint_states", [])
    viewer = {
        "counts": run.viewer.get("counts", {}),
        "joint_states_hz": (len(viewer_times) - 1) / ((viewer_times[-1] - viewer_times[0]) * 1e-3)
        if len(viewer_times) > 1
        else None,
        "problems": run.viewer.get("problems", []),
    }
    recorder_dropped = _recorder_dropped(run.recorder_line)
    lost = (recorder_dropped if recorder_dropped is not None else 0) + len(missing)
    # The client keeps every receive time it saw (its report): its memory grows by design.
    growths = [n["rss_growth_percent"] for name, n in nodes.items() if name != "live_view_client"]
    worst_growth = max((g for g in growths if g is not None), default=None)
    min_hz = min((w["joint_states_hz"] for w in windows), default=0.0)
    error_count = len(errors)
    checks = {
        "lost_messages": {
            "value": lost if recorder_dropped is not None else None,
            "target": "0",
            "pass": recorder_dropped is not None and lost == 0,
        },
        "min_window_hz": {"value": min_hz, "target": f">= {TARGETS['min_window_hz']:g}", "pass": min_hz >= 990.0},
        "worst_rss_growth_percent": {
            "value": worst_growth,
            "target": f"<= {TARGETS['rss_growth_percent']:g} (nodes)",
            "pass": None not in growths and worst_growth <= TARGETS["rss_growth_percent"],
        },
        "all_alive": {"value": all(run.alive.values()), "target": "every process", "pass": all(run.alive.values())},
        "error_statuses": {"value": error_count, "target": "0", "pass": error_count == 0},
    }
    return {
        "config": {
            "minutes": run.minutes,
            "rate_hz": run.rate_hz,
            "window_s": window_s,
            "switch_s": run.switch_s,
            "lines_sent": run.lines_sent,
            "lines_unacknowledged": run.lines_unacknowledged,
            "realtime_priority": run.realtime_priority,
            "robot": "panda (URDF limits, collision_avoidance, SRDF, 3 obstacles), recorder on every manip_kin "
            "topic, live_view with one client",
            "machine": f"{os.cpu_count()} cores, shared; load average per window below",
        },
        "reached_line_start": run.reached_line_start,
        "nodes": nodes,
        "windows": windows,
        "load_average": [{"t_s": round(t, 1), "load1": la} for t, la in run.load],
        "recorder": {
            "exit_code": run.recorder_code,
            "summary": run.recorder_line,
            "file_topic_counts": file_counts,
            "joint_states_seen_here": len(seen),
            "joint_states_in_file": len(recorded),
            "joint_states_seen_but_not_recorded": len(missing),
            "dropped": recorder_dropped,
        },
        "controller_states": states,
        "live_view_client": viewer,
        "errors": errors[:50],
        "error_count": error_count,
        "targets": TARGETS,
        "checks": checks,
    }


def table(result: dict) -> str:
    lines = [
        f"soak: {result['config']}",
        "",
        f"{'node':24} {'RSS@1min MiB':>13} {'RSS end MiB':>12} {'growth %':>9} {'CPU %':>7} alive",
    ]
    for name, node in result["nodes"].items():
        growth = node["rss_growth_percent"]
        lines.append(
            f"{name:24} {node['rss_minute1_mib']:13.1f} {node['rss_end_mib']:12.1f} "
            f"{growth if growth is not None else float('nan'):9.2f} {node['cpu_percent_of_core']:7.1f} {node['alive_at_end']}"
        )
    lines += [
        "",
        "/joint_states Hz: recorded per window (received here in brackets); p99 columns: period error [ms]",
        f"{'window s':>9} {'/joint_states Hz':>22} {'stamp p99':>10} {'rs loop':>8} {'ctl loop':>9} {'gen loop':>9}",
    ]

    def f(value):
        return f"{value:.3f}" if isinstance(value, float) else "-"

    for w in result["windows"]:
        lines.append(
            f"{w['start_s']:9.0f} {w['joint_states_hz']:12.1f} ({w['received_here_hz']:7.1f}) "
            f"{f(w.get('stamp_period_error_p99_ms')):>10} {f(w['robot_state_p99_ms']):>8} "
            f"{f(w['cartesian_controller_p99_ms']):>9} {f(w['trajectory_generator_p99_ms']):>9}"
        )
    hz = [w["joint_states_hz"] for w in result["windows"]]
    rec = result["recorder"]
    lines += [
        "",
        f"min window rate {min(hz) if hz else float('nan'):.1f} Hz (target >= {TARGETS['min_window_hz']:g})",
        f"recorder: {rec['summary']}",
        f"/joint_states seen here {rec['joint_states_seen_here']}, in the file {rec['joint_states_in_file']}, "
        f"seen but not recorded {rec['joint_states_seen_but_not_recorded']} (target 0)",
        f"ERROR statuses: {result['error_count']} (target 0)",
        f"controller states reported: {result['controller_states']}",
        f"live view client: {result['live_view_client']['counts']}, /joint_states "
        f"{f(result['live_view_client']['joint_states_hz'])} Hz, problems {result['live_view_client']['problems']}",
        f"load average (1 min) per window: {[round(x['load1'], 1) for x in result['load_average']]}",
        "",
        f"{'check':26} {'value':>12} {'target':>14} pass",
    ]
    for name, check in result["checks"].items():
        value = check["value"]
        text = f"{value:.2f}" if isinstance(value, float) else str(value)
        lines.append(f"{name:26} {text:>12} {check['target']:>14} {check['pass']}")
    return "\n".join(lines)


#: The loops' SCHED_FIFO priority where permitted: what ``make bench`` measures with.
DEFAULT_PRIORITY = 20


def fifo_permitted() -> bool:
    """True when this process may put a thread at SCHED_FIFO (root, CAP_SYS_NICE or an
    RLIMIT_RTPRIO), tried on a thread of its own that ends at once."""
    import threading

    permitted = []

    def attempt() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            permitted.append(True)
        except (OSError, AttributeError):  # AttributeError: no SCHED_FIFO on this platform
            pass

    thread = threading.Thread(target=attempt)
    thread.start()
    thread.join()
    return bool(permitted)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--minutes", type=float, default=10.0, help="soak duration [min] (default 10)")
    parser.add_argument("--rate-hz", type=float, default=1000.0, help="loop rate of every node [Hz] (default 1000)")
    parser.add_argument("--window-s", type=float, default=30.0, help="statistics window [s] (default 30)")
    parser.add_argument("--switch-s", type=float, default=4.0, help="a new line target every this many seconds")
    parser.add_argument(
        "--realtime-priority",
        type=int,
        default=None,
        help=f"SCHED_FIFO priority of the nodes' loop threads (0 = normal scheduling; default "
        f"{DEFAULT_PRIORITY} where this process may use SCHED_FIFO, as a cell's controller runs, else 0)",
    )
    parser.add_argument("--out", default="bench/results/soak.json", help="JSON result file")
    args = parser.parse_args(argv)
    if not (args.minutes > 0 and args.rate_hz > 0 and args.window_s > 0 and args.switch_s > 0):
        parser.error("--minutes, --rate-hz, --window-s and --switch-s must be > 0")
    if args.realtime_priority is None:
        args.realtime_priority = DEFAULT_PRIORITY if fifo_permitted() else 0
    if not 0 <= args.realtime_priority <= 99:
        parser.error(f"--realtime-priority {args.realtime_priority}: valid 0 (normal scheduling) to 99")
    out_dir = Path(tempfile.mkdtemp(prefix="manip_kin_soak_"))
    scheduling = f"SCHED_FIFO {args.realtime_priority}" if args.realtime_priority else "normal scheduling"
    print(
        f"soak: {args.minutes:g} min at {args.rate_hz:g} Hz, {scheduling}; logs and recording in {out_dir}",
        file=sys.stderr,
    )
    result = run_soak(args.minutes, args.rate_hz, args.window_s, args.switch_s, out_dir, args.realtime_priority)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    print(f"\nJSON: {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
