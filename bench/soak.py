#!/usr/bin/env python3
"""``make soak``: the full pipeline and the recorder at 1 kHz for minutes, lines alternating.

The irb120 pipeline (robot_state, cartesian_controller, trajectory_generator) and the
recorder (every manip_kin topic) run as separate processes at ``--rate-hz``; every
``--switch-s`` seconds a line target alternates between two poses of scenario (b) (0.4 m/s).
Reported, as JSON (``--out``) and a table:

* per node: RSS at minute 1 and at the end (growth in %), CPU share of one core over the
  run;
* per ``--window-s`` window: ``/joint_states`` messages received here per second, the p99
  of ``|Δstamp - period|`` of those messages, and per node the worst
  ``loop_period_error_p99_ms`` its ``/diagnostics`` reported in the window;
* the recorder: its own summary line (dropped = sequence gaps and middleware losses), the
  count of each topic in the file, and the ``/joint_states`` messages this process saw
  while the recorder ran that are missing from the file;
* every ERROR status on ``/diagnostics``.

Targets (issue 8): RSS growth ≤ 5 %, every window ≥ 990 Hz, zero messages lost, no ERROR.
The machine is shared: load from other jobs shows in the windows, so the table carries the
load average too.

Run: ``make soak`` (10 minutes) or ``.venv/bin/python bench/soak.py --minutes 1``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

LINE_START = [0.4, 0.1, 0.6]
LINE_END = [-0.4, 0.3, 0.5]
TARGETS = {"rss_growth_percent": 5.0, "min_window_hz": 990.0, "lost": 0, "errors": 0}


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

        from manip_kin.nodes.polling import PolledSubscription
        from manip_kin.nodes.topics import latest_state_qos

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


def run_soak(minutes: float, rate_hz: float, window_s: float, switch_s: float, out_dir: Path) -> dict:
    from diagnostic_msgs.msg import DiagnosticArray

    from manip_kin.pipeline import (
        IRB120_LINE_GENERATOR,
        NodeProcess,
        Pipeline,
        ensure_ros_isolation,
        pipeline_processes,
    )
    from manip_kin.rotations import make_transform, rpy_to_matrix

    env = ensure_ros_isolation()
    recording = out_dir / "soak.mcap"
    processes = [NodeProcess("recorder", "recorder", {"output": str(recording)})] + pipeline_processes(
        "irb120",
        rate_hz=rate_hz,
        initial_positions=[0.0] * 6,
        controller={"gain_linear": 6.0, "gain_angular": 6.0},
        generator=IRB120_LINE_GENERATOR,
    )
    down = rpy_to_matrix(0.0, math.pi / 2, 0.0)
    poses = [make_transform(down, LINE_START), make_transform(down, LINE_END)]
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
        converged, _ = client.wait_converged(client.send_goal(poses[0]), 60)
        counter = JointStateCounter(client.node)
        counter.start()
        names = list(pipeline.processes)
        pids = {name: pipeline.pid(name) for name in names}
        cpu_start = {name: _cpu_seconds(pid) for name, pid in pids.items()}
        start_ns, start_wall_ns = time.monotonic_ns(), time.time_ns()
        rss_minute1: dict[str, int] = {}
        next_switch = time.monotonic()
        target = 1
        lines_sent = 0
        load = []
        while (time.monotonic_ns() - start_ns) * 1e-9 < duration_s:
            if time.monotonic() >= next_switch:
                client.send_line(poses[target])
                target = 1 - target
                lines_sent += 1
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
        alive = {name: pipeline.running(name) for name in names}
        recorder_code = pipeline.stop_process("recorder", timeout=60)
        recorder_line = pipeline.log_text("recorder").strip().splitlines()[-1]
    run = SoakRun(
        minutes=minutes,
        rate_hz=rate_hz,
        window_s=window_s,
        switch_s=switch_s,
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
        load=load,
    )
    return _summarise(run)


@dataclass
class SoakRun:
    """What one soak collected, before it is summarised (times from ``time.monotonic_ns``)."""

    minutes: float
    rate_hz: float
    window_s: float
    switch_s: float
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
    load: list  # (elapsed s, 1-min load average)


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
    return {
        "config": {
            "minutes": run.minutes,
            "rate_hz": run.rate_hz,
            "window_s": window_s,
            "switch_s": run.switch_s,
            "lines_sent": run.lines_sent,
            "robot": "irb120, recorder on every manip_kin topic",
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
        },
        "errors": errors[:50],
        "error_count": len(errors),
        "targets": TARGETS,
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
        f"load average (1 min) per window: {[round(x['load1'], 1) for x in result['load_average']]}",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--minutes", type=float, default=10.0, help="soak duration [min] (default 10)")
    parser.add_argument("--rate-hz", type=float, default=1000.0, help="loop rate of every node [Hz] (default 1000)")
    parser.add_argument("--window-s", type=float, default=30.0, help="statistics window [s] (default 30)")
    parser.add_argument("--switch-s", type=float, default=4.0, help="a new line target every this many seconds")
    parser.add_argument("--out", default="bench/results/soak.json", help="JSON result file")
    args = parser.parse_args(argv)
    if not (args.minutes > 0 and args.rate_hz > 0 and args.window_s > 0 and args.switch_s > 0):
        parser.error("--minutes, --rate-hz, --window-s and --switch-s must be > 0")
    out_dir = Path(tempfile.mkdtemp(prefix="manip_kin_soak_"))
    print(f"soak: {args.minutes:g} min at {args.rate_hz:g} Hz; logs and recording in {out_dir}", file=sys.stderr)
    result = run_soak(args.minutes, args.rate_hz, args.window_s, args.switch_s, out_dir)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    print(f"\nJSON: {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
