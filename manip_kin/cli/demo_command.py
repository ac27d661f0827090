"""``manip_kin demo``: the main job, end to end, on the genova7 "pose goal" scenario.

1. core: the tool pose and Jacobian at the start configuration;
2. control law, offline: the resolved-rate simulation of the pose goal;
3. live pipeline: robot_state, cartesian_controller, trajectory_generator and the recorder as
   separate processes on loopback DDS; the pose goal, then a straight line back to a second
   target (the start tool pose);
4. the recording: ``manip_kin info`` of it, its plots and an animation of the arm from its /tf.

With ``--live`` the ``live_view`` node runs beside them: connect Foxglove to
ws://127.0.0.1:8765 (``--live-port``) and import config/foxglove_layout.json to watch the arm
move; at a terminal the demo then waits for Enter before it stops the nodes.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from manip_kin.cli.common import add_namespace_argument, format_matrix, namespace_from_args
from manip_kin.core.kinematics import frame_pose, jacobian
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform, matrix_to_rpy, rpy_to_matrix
from manip_kin.errors import InvalidArgumentError
from manip_kin.pipeline.outcome import motion_timing
from manip_kin.plant import PLANT_NAMES

# The genova7 "pose goal" scenario of shared/robots.md.
GOAL_POSITION = (0.2, -0.7, 0.3)
GOAL_RPY = (0.0, 1.57, 0.0)
GAIN = 0.8  # [1/s], angular and linear
TOLERANCE = 1e-6  # [m] and [rad]


def register(subparsers) -> None:
    """Add the ``demo`` sub-command."""
    parser = subparsers.add_parser(
        "demo",
        help="run the genova7 pose-goal scenario: core, offline control law, live ROS pipeline, recording",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--out", default="runs/demo.mcap", metavar="FILE", help="recording of the live run (default runs/demo.mcap)"
    )
    parser.add_argument(
        "--rate", type=float, default=500.0, metavar="HZ", help="loop rate of the nodes [Hz] (default 500)"
    )
    parser.add_argument(
        "--line-speed",
        type=float,
        default=0.2,
        metavar="M/S",
        help="top speed of the straight line [m/s] (default 0.2)",
    )
    parser.add_argument(
        "--offline-only", action="store_true", help="stop after the offline simulation (no ROS processes)"
    )
    parser.add_argument("--timeout", type=float, default=60.0, metavar="S", help="limit for each live leg [s]")
    parser.add_argument(
        "--live",
        action="store_true",
        help="also run live_view: watch the arm in Foxglove on ws://127.0.0.1:PORT (with "
        "config/foxglove_layout.json); at a terminal, wait for Enter before stopping",
    )
    parser.add_argument(
        "--live-port", type=int, default=8765, metavar="PORT", help="port of the live view (default 8765)"
    )
    parser.add_argument(
        "--plant",
        choices=PLANT_NAMES,
        default="kinematic",
        help="what robot_state simulates: a perfect integrator (default) or MuJoCo physics (docs/physics.md)",
    )
    add_namespace_argument(parser)
    parser.set_defaults(run=run_demo)


def _heading(text: str) -> None:
    print(f"\n=== {text}", flush=True)


def _pose_line(pose: np.ndarray) -> str:
    xyz = ", ".join(f"{v:+.4f}" for v in pose[:3, 3])
    rpy = ", ".join(f"{v:+.4f}" for v in matrix_to_rpy(pose[:3, :3]))
    return f"xyz [{xyz}] m, rpy [{rpy}] rad"


def run_demo(args: argparse.Namespace) -> int:
    if not 0 < args.live_port < 65536:
        raise InvalidArgumentError(f"--live-port {args.live_port}; valid: a TCP port 1-65535")
    model = load_robot("genova7")
    q0 = model.start_configuration()
    goal_pose = make_transform(rpy_to_matrix(*GOAL_RPY), GOAL_POSITION)

    _heading("1/4 core: genova7 at the scenario start q0")
    print(f"q0 = {np.round(q0, 4).tolist()} [rad | m]")
    start_pose = frame_pose(model, q0, "tool")
    print("tool pose in base_link:")
    print(format_matrix(start_pose))
    tool_jacobian = jacobian(model, q0, "tool")
    print("geometric Jacobian of the tool, angular rows [rad/s per unit q̇]:")
    print(format_matrix(tool_jacobian.angular))
    print("linear rows [m/s per unit q̇]:")
    print(format_matrix(tool_jacobian.linear))

    _heading("2/4 control law, offline: resolved-rate simulation of the pose goal")
    from manip_kin.control.resolved_rate import ControllerConfig
    from manip_kin.control.simulation import simulate

    print(f"goal: {_pose_line(goal_pose)}; gains {GAIN} 1/s; dt 1 ms")
    started = time.perf_counter()
    result = simulate(
        model,
        q0,
        goal_pose,
        ControllerConfig(gain_angular=GAIN, gain_linear=GAIN),
        dt=0.001,
        duration=20.0,
        tolerance=TOLERANCE,
    )
    elapsed = time.perf_counter() - started
    prismatic = int(np.flatnonzero(model.is_prismatic)[0])
    lowest = float(result.q[:, prismatic].min())
    ideal = (
        math.log(max(np.linalg.norm(result.position_error[0]), np.linalg.norm(result.orientation_error[0])) / TOLERANCE)
        / GAIN
    )
    print(
        f"converged: {result.converged} at t = {result.time_to_converge} s "
        f"(pure exponential convergence: {ideal:.2f} s); {result.steps} steps in {elapsed:.2f} s of computing"
    )
    print(
        f"final error: position {result.final_position_error:.2e} m, orientation {result.final_orientation_error:.2e} rad"
    )
    print(
        f"prismatic {model.joints[prismatic].name}: lowest {lowest:.6f} m (limit {model.lower[prismatic]:.3f} m); "
        f"largest limit violation {result.max_limit_violation:.1e}"
    )
    if args.offline_only:
        return 0 if result.converged else 1
    return _run_live(args, model, q0, goal_pose, start_pose)


def demo_processes(args: argparse.Namespace, out: Path, controller: dict, generator: dict) -> list:
    """The demo's node processes: the recorder, the pipeline and, with ``--live``, ``live_view``."""
    from manip_kin.pipeline import NodeProcess, pipeline_processes

    processes = [NodeProcess("recorder", "recorder", {"output": str(out)})]
    processes += pipeline_processes(
        "genova7", rate_hz=args.rate, controller=controller, generator=generator, robot_state={"plant": args.plant}
    )
    if args.live:
        processes.append(NodeProcess("live_view", "live_view", {"port": args.live_port}, ready_status="live_view"))
    return processes


def _run_live(args, model, q0, goal_pose, start_pose) -> int:
    from manip_kin.pipeline import Pipeline, ensure_ros_isolation

    env = ensure_ros_isolation()
    namespace = namespace_from_args(args)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.exists():
        out.unlink()
    _heading(
        f"3/4 live pipeline at {args.rate:g} Hz, plant {args.plant} (ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}, discovery {env['ROS_AUTOMATIC_DISCOVERY_RANGE']})"
    )
    controller = {
        "position_tolerance": TOLERANCE,
        "orientation_tolerance": TOLERANCE,
        "gain_linear": GAIN,
        "gain_angular": GAIN,
    }
    generator = {"time_scaling": "trapezoidal", "max_linear_velocity": args.line_speed}
    processes = demo_processes(args, out, controller, generator)
    exit_code = 0
    with Pipeline(processes, namespace=namespace) as pipeline:
        print(f"started {', '.join(pipeline.processes)} (logs in {pipeline.log_dir})", flush=True)
        if args.live:
            print(
                f"live view: in Foxglove, Open connection -> Foxglove WebSocket -> ws://127.0.0.1:{args.live_port}, "
                "then Layouts -> Import from file -> config/foxglove_layout.json",
                flush=True,
            )
        client = pipeline.client()
        legs = (
            ("leg 1: pose goal", client.send_goal, goal_pose),
            ("leg 2: straight line back to the start tool pose", client.send_line, start_pose),
        )
        for title, send, target in legs:
            print(f"{title}: {_pose_line(target)}", flush=True)
            started = time.monotonic()
            sent_stamp = stamp = send(target)
            generator = None
            if send == client.send_line:
                generator = client.wait_line_done(stamp, timeout=args.timeout)
                if generator.message != "holding":
                    print(f"  line rejected: {generator.values.get('last_rejection')}")
                    exit_code = 1
                    continue
                stamp = generator.values.get("final_goal_stamp", stamp)
            converged, status = client.wait_converged(stamp, timeout=args.timeout)
            took = client.time_to_converge(stamp, started, sent_stamp=sent_stamp)
            timing = motion_timing(
                sent_stamp, status.values if status else {}, generator.values if generator is not None else None
            )
            errors = (
                f"position {status.number('position_error'):.2e} m, orientation {status.number('orientation_error'):.2e} rad"
                if status is not None
                else "no status"
            )
            verdict = timing.converged_verdict("line", took) if converged else f"NOT converged in {took:.2f} s"
            print(f"  {verdict}; final error {errors}", flush=True)
            exit_code = exit_code or (0 if converged else 1)
        tool_now = client.current_tool_pose()
        print(f"  tool now: {_pose_line(tool_now)}")
        if args.live and sys.stdin.isatty():
            input("live view still up: press Enter to stop the nodes and read the recording ")
        summary_code = pipeline.stop_process("recorder", timeout=10.0)
        recorder_lines = [line for line in pipeline.log_text("recorder").splitlines() if line.strip()]
        if recorder_lines:
            print(recorder_lines[-1])  # the recorder's own summary line, "recorder: recorded ..."
        if summary_code not in (0, None):
            print(f"recorder exited with {summary_code}", file=sys.stderr)
    _heading(f"4/4 the recording: {out}")
    from manip_kin.recording import read_info
    from manip_kin.viz.plotting import plot_run
    from manip_kin.viz.run_data import load_run

    print(read_info(out).to_text())
    run = load_run(out, namespace=namespace)
    plots_dir = out.parent / f"{out.stem}_plots"
    figures = plot_run(run, plots_dir, title="genova7 demo")
    print(f"plots: {', '.join(str(p) for p in figures)}")
    if run.arm is not None:
        from manip_kin.viz.arm_animation import write_animation

        print(f"animation of the arm from /tf: {write_animation(run.arm, plots_dir / 'arm.gif', title='genova7 demo')}")
    else:
        print("no /tf in the recording: no animation", file=sys.stderr)
        exit_code = exit_code or 1
    return exit_code
