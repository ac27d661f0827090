"""``manip_kin robots``, ``fk``, ``jacobian`` and ``sweep``: what the model knows at given configurations."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from manip_kin.cli.common import (
    add_joint_argument,
    add_json_argument,
    add_link_arguments,
    add_robot_argument,
    format_matrix,
    joints_from_args,
    pose_summary,
    print_json,
    robot_from_args,
)
from manip_kin.core.kinematics import JACOBIAN_KINDS, jacobian, transform_between
from manip_kin.core.robots import bundled_robot_files, load_robot
from manip_kin.errors import InvalidArgumentError
from manip_kin.viz.sweep import joint_sweep, plot_sweep


def register(subparsers) -> None:
    """Add the model sub-commands."""
    robots = subparsers.add_parser(
        "robots",
        help="list the bundled robots with their joints and limits, or describe one robot file (--robot)",
        description="Without --robot: every bundled robot. With --robot NAME|FILE: that robot's joints, "
        "limits and chain (for a URDF, the chain --base-link/--tip-link/--tool-link select). "
        "Infinite limits (continuous joints, no velocity limit) are null in --json.",
    )
    robots.add_argument(
        "--robot",
        default=None,
        metavar="NAME|FILE",
        help="describe only this robot: a bundled name or a YAML/URDF file",
    )
    add_link_arguments(robots)
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


def _finite_or_none(value: float) -> float | None:
    """A limit for JSON, which has no infinity: None means "no limit"."""
    return value if math.isfinite(value) else None


def _joint_summary(model) -> list[dict]:
    return [
        {
            "name": joint.name,
            "type": joint.type.value,
            "lower": _finite_or_none(joint.lower),
            "upper": _finite_or_none(joint.upper),
            "velocity": _finite_or_none(joint.velocity_limit),
            "unit": "rad" if joint.is_revolute else "m",
            "link": joint.link_name,
        }
        for joint in model.joints
    ]


def _chain(model) -> list[str]:
    """The frames from the base to the end effector (and tool): base, each joint's link, ee."""
    links = [joint.link_name or f"link{i}" for i, joint in enumerate(model.joints, start=1)]
    return [model.base_frame, *links, "ee", *(["tool"] if model.has_tool else [])]


def _robot_summary(model, file: str) -> dict:
    return {
        "file": file,
        "name": model.name,
        "dof": model.dof,
        "tool": model.has_tool,
        "base_frame": model.base_frame,
        "chain": _chain(model),
        "joints": _joint_summary(model),
    }


def _limit_text(value: float | None, scale: float) -> str:
    return f"{value * scale:8.2f}" if value is not None else "    none"


def run_robots(args: argparse.Namespace) -> int:
    if args.robot is not None:
        model = robot_from_args(args)
        robots = {model.name: _robot_summary(model, model.source or str(args.robot))}
    else:
        if args.base_link or args.tip_link or args.tool_link:
            raise InvalidArgumentError("--base-link/--tip-link/--tool-link need --robot FILE (a URDF)")
        robots = {name: _robot_summary(load_robot(name), str(path)) for name, path in bundled_robot_files().items()}
    if args.json:
        print_json({"robots": robots})
        return 0
    for name, info in robots.items():
        print(f"{name}: {info['dof']} joints{', with tool' if info['tool'] else ''}  ({info['file']})")
        print(f"  chain: {' -> '.join(info['chain'])}")
        for joint in info["joints"]:
            scale = 180.0 / math.pi if joint["unit"] == "rad" else 1.0
            unit = "deg" if joint["unit"] == "rad" else "m"
            lower, upper = _limit_text(joint["lower"], scale), _limit_text(joint["upper"], scale)
            print(
                f"  {joint['name']:<10} {joint['type']:<9} [{lower}, {upper}] {unit:<3}"
                f"  max {_limit_text(joint['velocity'], scale)} {unit}/s"
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
