"""``make bench`` rows of the live view: its CPU beside the 1 kHz pipeline, with and without clients.

The genova7 pipeline runs at 1 kHz with ``live_view`` at its default rates (streams and
``/tf`` at 50 Hz). Per round, over the same window: live_view's CPU [% of one core] with no
client, with one client (test/foxglove_client/client.mjs subscribed to every channel), and
with that client beside one that subscribed to everything and never reads (a socket with a
4 KiB receive buffer); the reading client's ``/joint_states`` rate and the node's resident
memory at the end of each window are reported too (the stalled client's queue is bounded by
``message_backlog``, so the memory must not grow with it). Rounds alternate the three cases,
so that the machine's drift falls on all of them.
"""

from __future__ import annotations

import json
import tempfile
import time

import numpy as np
from bench_nodes import _cpu_seconds

LIVE_VIEW_PORT = 18765


def _rss_mib(pid: int) -> float:
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _window(pipeline, client, seconds: float, reader: bool, stalled: bool) -> dict:
    from live_view_client import stalled_client, start_client

    pid = pipeline.pid("live_view")
    silent = stalled_client(LIVE_VIEW_PORT) if stalled else None
    process = start_client(LIVE_VIEW_PORT, seconds + 1.0) if reader else None
    try:
        client.spin_for(1.0)  # connected and subscribed before the window opens
        start_cpu, start = _cpu_seconds(pid), time.monotonic()
        client.spin_for(seconds)
        cpu = 100.0 * (_cpu_seconds(pid) - start_cpu) / (time.monotonic() - start)
        rss = _rss_mib(pid)
        rate = float("nan")
        if process is not None:
            out, _ = process.communicate(timeout=seconds + 30)
            result = json.loads(out)
            times = result["times"].get("/joint_states", [])
            rate = (len(times) - 1) / ((times[-1] - times[0]) / 1000.0) if len(times) > 1 else float("nan")
        return {"cpu": cpu, "rate": rate, "rss": rss}
    finally:
        if silent is not None:
            silent.close()
        if process is not None and process.poll() is None:
            process.kill()
            process.wait()


def run_live_view_benchmarks(rounds: int = 3, window: float = 4.0) -> list[dict]:
    from manip_kin.pipeline import NodeProcess, Pipeline, pipeline_processes

    processes = pipeline_processes("genova7", rate_hz=1000.0) + [
        NodeProcess("live_view", parameters={"port": LIVE_VIEW_PORT}, ready_status="live_view")
    ]
    cases = {
        "no client": (False, False),
        "one client": (True, False),
        "one client + one that never reads": (True, True),
    }
    measured: dict[str, list[dict]] = {case: [] for case in cases}
    with Pipeline(processes, log_dir=tempfile.mkdtemp(prefix="bench_live_view_")) as pipeline:
        client = pipeline.client()
        client.spin_for(1.0)
        for _ in range(rounds):
            for case, (reader, stalled) in cases.items():
                measured[case].append(_window(pipeline, client, window, reader, stalled))
    rows = []
    for case, samples in measured.items():
        cpu = np.array([s["cpu"] for s in samples])
        rate = np.array([s["rate"] for s in samples])
        row = {
            "metric": f"live_view CPU, 1 kHz genova7 pipeline, default rates (50 Hz), {case}",
            "cpu_percent_median": float(np.median(cpu)),
            "cpu_percent_min": float(cpu.min()),
            "cpu_percent_max": float(cpu.max()),
            "rss_mib_max": float(max(s["rss"] for s in samples)),
            "rounds": len(samples),
        }
        if not np.all(np.isnan(rate)):
            row["client_joint_states_hz_median"] = float(np.nanmedian(rate))
        row["target"] = "a slow client costs the node nothing; ≤ 20 % of one core"
        row["reference"] = "four 1 kHz streams in, 50 Hz each out"
        rows.append(row)
    return rows
