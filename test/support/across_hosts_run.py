"""A line across two hosts while the link between them drops: the driver of test_across_hosts.py
(and of bench/bench_across_hosts.py's link rows).

Run inside namespace ``b`` of a :class:`net_namespaces.HostPair` (the workstation), with the
environment of :func:`net_namespaces.host_env`::

    ip netns exec <tag>b python test/support/across_hosts_run.py --pair <tag> --out DIR

robot_state (the kinematic plant, irb120) runs on the robot's host, namespace ``a`` (started
there with ``ip netns exec``); cartesian_controller, trajectory_generator and the recorder run
here, as does this process's client. The arm first goes to the line's start, then a line
starts; ``--down-after`` seconds into it the veth link goes down for ``--down`` seconds and
comes back. Written to ``DIR/result.json``: every ``/diagnostics`` status this process heard
(monotonic ns, name, level, message), the link's down and up instants (monotonic and system
clock, ns; both inside the outage), when the link was back (``link_restored_ns``), how long
the pipeline took to start across the link, the recorder's summary line and the recording's
path (``DIR/run.mcap``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # net_namespaces

from net_namespaces import HostPair
from pipeline_checks import recorder_reads

ROBOT = "irb120"
#: The soak's line (scenario (b) of robots.md, 0.4 m/s): 0.9 m, about 3 s.
LINE_START = [0.4, 0.1, 0.6]
LINE_END = [-0.4, 0.3, 0.5]


#: The topics the test reads from the recording.
RECORDED = ("/joint_velocity_commands", "/joint_states", "/diagnostics")


def run_fault(pair: HostPair, out_dir: Path, rate_hz: float, down_after_s: float, down_s: float) -> dict:
    from diagnostic_msgs.msg import DiagnosticArray

    from manip_kin.core.rotations import make_transform, rpy_to_matrix
    from manip_kin.pipeline import IRB120_LINE_GENERATOR, NodeProcess, Pipeline, PipelineError, pipeline_processes

    recording = out_dir / "run.mcap"
    nodes = pipeline_processes(
        ROBOT,
        rate_hz=rate_hz,
        initial_positions=[0.0] * 6,
        controller={"gain_linear": 6.0, "gain_angular": 6.0},
        generator=IRB120_LINE_GENERATOR,
    )
    robot_state = replace(nodes[0], prefix=pair.prefix("a"))  # on the robot's host
    # The robot host first: its node is up before the workstation's participants start.
    processes = [robot_state, NodeProcess("recorder", "recorder", {"output": str(recording)}), *nodes[1:]]
    down = rpy_to_matrix(0.0, math.pi / 2, 0.0)
    start_pose, end_pose = make_transform(down, LINE_START), make_transform(down, LINE_END)
    statuses: list[tuple[int, str, int, str]] = []
    result: dict = {"rate_hz": rate_hz, "recording": str(recording), "robot": ROBOT}
    started = time.monotonic()
    pipeline = Pipeline(processes, log_dir=out_dir / "logs")
    try:
        pipeline.start(timeout=60)
        result["start_s"] = time.monotonic() - started
        client = pipeline.client()
        client.node.create_subscription(
            DiagnosticArray,
            "/diagnostics",
            lambda msg: statuses.extend((time.monotonic_ns(), s.name, s.level[0], s.message) for s in msg.status),
            100,
        )
        # The recorder's readers matched before anything moves: under load its reader of the
        # commands once matched after the link went down (no command recorded before it).
        result["recorder_matched"] = bool(client.spin_until(lambda: recorder_reads(client, RECORDED), 30))
        converged, _ = client.wait_converged(client.send_goal(start_pose), 30)
        result["reached_line_start"] = bool(converged)
        line_stamp = client.send_line(end_pose)
        # Timed from the generator's start (the acknowledgement send_line waits for can come
        # seconds late on a loaded machine, the line by then well under way).
        client.wait_line_done(line_stamp, 10, finished=False)
        streaming = [t for t, n, _, m in statuses if n == "trajectory_generator" and m == "streaming"]
        result["line_started_ns"] = streaming[0] if streaming else time.monotonic_ns()
        client.spin_for(max(0.0, down_after_s - (time.monotonic_ns() - result["line_started_ns"]) * 1e-9))
        # The outage's instants bracket it from inside: "down" once both ends are down, "up" just
        # before they come up. (Read after `ip link set up` returned, "up" was late by however long
        # that command took, and commands on the returning states could count as the outage's.)
        pair.set_link(False)
        result["link_down_ns"], result["link_down_wall_ns"] = time.monotonic_ns(), time.time_ns()
        client.spin_for(down_s)
        result["link_up_ns"], result["link_up_wall_ns"] = time.monotonic_ns(), time.time_ns()
        pair.set_link(True)
        result["link_restored_ns"] = time.monotonic_ns()
        try:
            generator = client.wait_line_done(line_stamp, 20)
            result["line_done"] = generator.message
            final_goal = generator.values.get("final_goal_stamp", "")
            converged, status = client.wait_converged(final_goal, 20) if final_goal else (False, None)
            result["converged_at_end"] = bool(converged)
            result["controller_at_end"] = None if status is None else status.message
        except PipelineError as error:  # said in the result; the test asserts on it
            result["line_done"] = f"not done: {error}"
        # A few statuses after the return, here and in the recording.
        client.spin_for(max(0.3, 2.0 - (time.monotonic_ns() - result["link_up_ns"]) * 1e-9))
        result["alive"] = {name: pipeline.running(name) for name in pipeline.processes}
        result["recorder_code"] = pipeline.stop_process("recorder", timeout=30)
        result["recorder_summary"] = pipeline.log_text("recorder").strip().splitlines()[-1]
    finally:
        pipeline.stop()
        pair.set_link(True)
        result["statuses"] = statuses
        result["logs"] = {name: pipeline.log_tail(name, 15) for name in pipeline.processes}
        (out_dir / "result.json").write_text(json.dumps(result))
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pair", required=True, help="the HostPair's tag (its namespaces are TAGa and TAGb)")
    parser.add_argument("--out", required=True, type=Path, help="directory for result.json and run.mcap")
    parser.add_argument("--rate-hz", type=float, default=250.0, help="loop rate of the nodes [Hz]")
    parser.add_argument("--down-after", type=float, default=0.8, help="link down this long after the line starts [s]")
    parser.add_argument("--down", type=float, default=2.0, help="how long the link stays down [s]")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    run_fault(HostPair(args.pair), args.out, args.rate_hz, args.down_after, args.down)
    return 0


if __name__ == "__main__":
    sys.exit(main())
