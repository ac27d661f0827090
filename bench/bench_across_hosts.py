"""Across hosts: two network namespaces joined by a veth pair (test/support/net_namespaces.py), against
one namespace's loopback. Needs root and ``ip``; prints why not otherwise.

Rows (JSON to ``--out`` and a table):

* discovery: robot_state runs on host ``a``; a fresh process subscribes to ``joint_states``
  on host ``b`` (across) or on ``a`` (loopback); the time from its ``rclpy.init`` to its
  first message (discovery, matching, first sample), median/min/max of ``--trials``;
* goal-to-first-reacting-command latency (bench_nodes' measurement, genova7 at 1 kHz): the
  measuring process and robot_state on ``a``; cartesian_controller and trajectory_generator
  on ``b`` (across: the goal crosses the link, the command crosses back) or on ``a``;
* the link down for 2 s during a line (test/support/across_hosts_run.py): how long until the
  controller said ``stale input``, how long after the link's return until it no longer
  did, its state at the end, the widest gap in the recorded ``joint_states`` (receive
  times) and in their stamps.

Run: ``.venv/bin/python bench/bench_across_hosts.py`` (not part of ``make bench``: it needs root).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "test" / "support"))  # net_namespaces, across_hosts_run

from net_namespaces import HostPair, host_env, unavailable_reason  # noqa: E402


def _first_message_s() -> float:
    """Inside a namespace: seconds from rclpy.init to the first joint_states message."""
    start = time.monotonic()
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = rclpy.create_node("discovery_probe")
    got = []
    node.create_subscription(
        JointState, "joint_states", got.append, QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    )
    while not got and time.monotonic() - start < 30:
        rclpy.spin_once(node, timeout_sec=0.01)
    return time.monotonic() - start if got else float("nan")


def _latency_inside(pair: HostPair, across: bool, trials: int) -> dict:
    """Inside namespace a: bench_nodes' latency row, the controller and generator on b when ``across``."""
    from bench_nodes import _latency_row

    from manip_kin.pipeline import Pipeline, pipeline_processes

    nodes = pipeline_processes("genova7", rate_hz=1000.0)
    # robot_state first: the other host's participants start after it (see docs/across_machines.md).
    if across:
        nodes = [nodes[0], *(replace(n, prefix=pair.prefix("b")) for n in nodes[1:])]
    with Pipeline(nodes, log_dir=tempfile.mkdtemp(prefix="bench_across_")) as pipeline:
        label = "controller on the other host (veth)" if across else "all on one host (loopback)"
        return _latency_row(pipeline, label, 0, trials)


def _in_namespace(pair: HostPair, side: str, env: dict, *args: str, timeout: float = 300) -> str:
    done = subprocess.run(
        [*pair.prefix(side), sys.executable, __file__, "--inside", *args, "--pair", pair.tag],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} in {side}: {done.stderr[-2000:]}")
    return done.stdout.strip().splitlines()[-1]


def _discovery_rows(pair: HostPair, env: dict, trials: int) -> list[dict]:
    from manip_kin.pipeline import find_executable

    robot = subprocess.Popen(
        [*pair.prefix("a"), find_executable("robot_state"), "--ros-args", "-p", "robot:=genova7"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(5.0)
        times = {"b": [], "a": []}
        for _ in range(trials):
            for side in times:
                times[side].append(float(_in_namespace(pair, side, env, "discovery", timeout=60)))
    finally:
        robot.terminate()
        robot.wait(10)
    rows = []
    for side, label in (("b", "across the veth"), ("a", "loopback, same namespace")):
        values = np.array(times[side])
        rows.append(
            {
                "metric": f"rclpy.init to the first joint_states message, {label}",
                "median_s": float(np.nanmedian(values)),
                "min_s": float(np.nanmin(values)),
                "max_s": float(np.nanmax(values)),
                "trials": len(values),
            }
        )
    return rows


def _link_row(pair: HostPair, env: dict) -> dict:
    from manip_kin.recording import read_messages

    out = Path(tempfile.mkdtemp(prefix="bench_across_link_"))
    driver = HERE.parent / "test" / "support" / "across_hosts_run.py"
    subprocess.run(
        [*pair.prefix("b"), sys.executable, str(driver), "--pair", pair.tag, "--out", str(out)],
        env=env,
        capture_output=True,
        timeout=120,
        check=True,
    )
    result = json.loads((out / "result.json").read_text())
    down, up = result["link_down_ns"], result["link_restored_ns"]
    controller = [(t, m) for t, n, _, m in result["statuses"] if n == "cartesian_controller"]
    stale = [t for t, m in controller if t >= down and m.startswith("stale input")]
    back = [t for t, m in controller if t >= up and not m.startswith("stale input")]
    states = [r.message for r in read_messages(Path(result["recording"]), ["/joint_states"])]
    logs = np.array([r.log_time_ns for r in read_messages(Path(result["recording"]), ["/joint_states"])])
    stamps = np.array(sorted(s.header.stamp.sec * 10**9 + s.header.stamp.nanosec for s in states))
    return {
        "metric": "link down 2 s during the irb120 line at 250 Hz (robot_state across the veth)",
        "stale_reported_after_down_s": (stale[0] - down) * 1e-9 if stale else None,
        "not_stale_after_up_s": (back[0] - up) * 1e-9 if back else None,
        "controller_at_end": result.get("controller_at_end"),
        "joint_states_widest_receive_gap_s": float(np.diff(logs).max() * 1e-9),
        "joint_states_widest_stamp_gap_s": float(np.diff(stamps).max() * 1e-9),
        "start_across_s": result["start_s"],
        "recorder": result["recorder_summary"],
    }


def run_across_hosts_benchmarks(trials: int = 5, latency_trials: int = 300) -> list[dict]:
    """Every row; an empty list (with the reason on stderr) where namespaces cannot be made."""
    reason = unavailable_reason()
    if reason:
        print(f"across hosts: skipped: {reason}", file=sys.stderr)
        return []
    from manip_kin.pipeline import ensure_ros_isolation

    rows = []
    with HostPair() as pair:
        env = host_env(pair, ensure_ros_isolation(dict(os.environ)), os.environ.get("ROS_DOMAIN_ID", "") or 42)
        rows += _discovery_rows(pair, env, trials)
        for across in (True, False):
            rows.append(json.loads(_in_namespace(pair, "a", env, "latency", str(int(across)), str(latency_trials))))
        rows.append(_link_row(pair, env))
    for row in rows:
        row["load_average"] = os.getloadavg()[0]
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=HERE / "results" / "across_hosts.json", help="JSON output")
    parser.add_argument("--trials", type=int, default=5, help="discovery trials per side")
    parser.add_argument("--inside", nargs="*", help=argparse.SUPPRESS)  # a measurement inside a namespace
    parser.add_argument("--pair", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.inside:
        if args.inside[0] == "discovery":
            print(_first_message_s())
        else:
            print(json.dumps(_latency_inside(HostPair(args.pair), args.inside[1] == "1", int(args.inside[2]))))
        return 0
    rows = run_across_hosts_benchmarks(args.trials)
    payload = {"time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "cpus": os.cpu_count(), "results": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(payload, indent=1) + "\n")
    for row in rows:
        print(row["metric"])
        for key, value in row.items():
            if key != "metric":
                print(f"    {key}: {value:.4g}" if isinstance(value, float) else f"    {key}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
