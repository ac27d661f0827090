"""``manip_kin robots``, ``fk``, ``jacobian`` and ``sweep``: what the model knows at given configurations."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from manip_kin.cli.common import (
    add_joint_argument,
    add_json_argument,
    add_robot_argument,
    format_matrix,
    joints_from_args,
    pose_summary,
    print_json,
    robot_from_args,
)
from manip_kin.kinematics import JACOBIAN_KINDS, jacobian, transform_between
from manip_kin.robots import bundled_robot_files, load_robot
from manip_kin.sweep import joint_sweep, plot_sweep


def register(subparsers) -> None:
    """Add the model sub-commands."""
    robots = subparsers.add_parser("robots", help="list the bundled robots with their joints and limits")
    add_json_argument(robots)
    robots.set_defaults(run=run_robots)

    frame_help = "tool | ee | N (joint frame 1..n) | base | a link name; default: tool if the robot has one, else ee"
    fk = subparsers.add_parser(
        "fk",
        help="forward kinematics: pose of a frame in the base frame (or in another frame)",
        description="Pose of --frame expressed in --in at --q: T_in^-1 T_frame. Lengths in metres, angles in radians.",
    )
    add_robot_argument(fk)
    add_joint_argument(fk)
    fk.add_argument("--frame", default=None, help=frame_help)
    fk.add_argument(
        "--in",
        dest="in_frame",
        default="base",
        metavar="FRAME",
        help="frame the pose is expressed in: base (default) | N | ee | tool | a link name",
    )
    add_json_argument(fk)
    fk.set_defaults(run=run_fk)

    jac = subparsers.add_parser("jacobian", help="Jacobian of a frame (angular and linear blocks)")
    add_robot_argument(jac)
    add_joint_argument(jac)
    jac.add_argument("--frame", default=None, help=frame_help)
    jac.add_argument(
        "--kind",
        choices=JACOBIAN_KINDS,
        default="geometric",
        help="geometric: frame velocity w.r.t. base, in base; space/body: screw-theory twists; "
        "analytical: roll-pitch-yaw rates and linear velocity (default geometric)",
    )
    add_json_argument(jac)
    jac.set_defaults(run=run_jacobian)

    sweep = subparsers.add_parser(
        "sweep",
        help="joint frames 1..n at N+1 evenly spaced configurations between two, with a 3D picture",
        description="q_k = q_start + k/N (q_goal - q_start), k = 0..N; prints the configurations and the "
        "position of every joint frame in base [m], and writes sweep_<robot>.png (the arm at every step).",
    )
    add_robot_argument(sweep)
    add_joint_argument(sweep, "--q-start", required=True, help_text="first configuration [rad | m]")
    add_joint_argument(sweep, "--q-goal", required=True, help_text="last configuration [rad | m]")
    sweep.add_argument(
        "--steps", type=int, required=True, metavar="N", help="number of steps N >= 1 (N + 1 configurations)"
    )
    sweep.add_argument("--out", default=".", metavar="DIR", help="directory of the PNG (default: the current one)")
    add_json_argument(sweep)
    sweep.set_defaults(run=run_sweep)


def _joint_summary(model) -> list[dict]:
    rows = []
    for joint in model.joints:
        rows.append(
            {
                "name": joint.name,
                "type": joint.type.value,
                "lower": joint.lower,
                "upper": joint.upper,
                "velocity": joint.velocity_limit,
                "unit": "rad" if joint.is_revolute else "m",
            }
        )
    return rows


def run_robots(args: argparse.Namespace) -> int:
    robots = {}
    for name, path in bundled_robot_files().items():
        model = load_robot(name)
        robots[name] = {
            "file": str(path),
            "dof": model.dof,
            "tool": model.has_tool,
            "base_frame": model.base_frame,
            "joints": _joint_summary(model),
        }
    if args.json:
        print_json({"robots": robots})
        return 0
    for name, info in robots.items():
        print(f"{name}: {info['dof']} joints{', with tool' if info['tool'] else ''}  ({info['file']})")
        for joint in info["joints"]:
            scale = 180.0 / math.pi if joint["unit"] == "rad" else 1.0
            unit = "deg" if joint["unit"] == "rad" else "m"
            print(
                f"  {joint['name']:<10} {joint['type']:<9} [{joint['lower'] * scale:8.2f}, {joint['upper'] * scale:8.2f}] {unit:<3}"
                f"  max {joint['velocity'] * scale:7.2f} {unit}/s"
            )
    return 0


def run_fk(args: argparse.Namespace) -> int:
    model = robot_from_args(args)
    q = joints_from_args(model, args.q)
    frame = args.frame or model.default_frame
    index = model.frame_index(frame)
    reference = model.frame_index(args.in_frame)
    pose = transform_between(model, q, reference, index)
    summary = {"frame": model.frame_name(index), **pose_summary(pose)}
    if args.json:
        print_json(summary)
        return 0
    where = model.base_frame if reference == 0 else f"frame '{model.frame_name(reference)}'"
    print(f"{model.name}: pose of frame '{summary['frame']}' in {where} at q = {q.round(6).tolist()}")
    print(format_matrix(pose))
    print(f"  xyz [m]        {[round(v, 6) for v in summary['xyz']]}")
    print(f"  rpy [rad]      {[round(v, 6) for v in summary['rpy']]}")
    print(f"  quat (x y z w) {[round(v, 6) for v in summary['quat_xyzw']]}")
    return 0


def run_jacobian(args: argparse.Namespace) -> int:
    model = robot_from_args(args)
    q = joints_from_args(model, args.q)
    frame = args.frame or model.default_frame
    result = jacobian(model, q, frame, args.kind)
    if args.json:
        print_json(
            {
                "kind": result.kind,
                "frame": result.frame,
                "angular": result.angular.tolist(),
                "linear": result.linear.tolist(),
            }
        )
        return 0
    print(f"{model.name}: {result.kind} Jacobian of frame '{result.frame}' at q = {q.round(6).tolist()}")
    print("  angular rows" + (" (roll/pitch/yaw rates)" if result.kind == "analytical" else " [rad/s per unit q̇]"))
    print(format_matrix(result.angular, "    "))
    print("  linear rows [m/s per unit q̇]")
    print(format_matrix(result.linear, "    "))
    return 0


def run_sweep(args: argparse.Namespace) -> int:
    model = robot_from_args(args)
    q_start = joints_from_args(model, args.q_start, "--q-start")
    q_goal = joints_from_args(model, args.q_goal, "--q-goal")
    sweep = joint_sweep(model, q_start, q_goal, args.steps)
    png = plot_sweep(model, sweep, Path(args.out) / f"sweep_{model.name}.png")
    if args.json:
        print_json({"q": sweep.q.tolist(), "positions": sweep.positions.tolist(), "png": str(png)})
        return 0
    frames = ", ".join(str(i) for i in range(1, model.dof + 1))
    print(f"{model.name}: {args.steps + 1} configurations; joint frames {frames} in {model.base_frame} [m]")
    for k, (q, positions) in enumerate(zip(sweep.q, sweep.positions)):
        print(f"  step {k:3d}  q = [{' '.join(f'{v:.4f}' for v in q)}]")
        print("            " + "  ".join(f"({p[0]:.3f} {p[1]:.3f} {p[2]:.3f})" for p in positions))
    print(f"figure: {png}")
    return 0
