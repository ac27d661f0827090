"""Argument helpers shared by the ``manip_kin`` sub-commands (interfaces.md conventions)."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.core.robots import bundled_robot_names, load_robot
from manip_kin.core.rotations import make_transform, matrix_to_quat, matrix_to_rpy, quat_to_matrix, rpy_to_matrix
from manip_kin.errors import InvalidArgumentError, JointCountError, OperationError


def add_robot_argument(parser: argparse.ArgumentParser) -> None:
    """``--robot NAME|FILE`` and, for a URDF, ``--base-link``, ``--tip-link``, ``--tool-link``."""
    parser.add_argument(
        "--robot",
        required=True,
        metavar="NAME|FILE",
        help=f"bundled robot ({', '.join(bundled_robot_names())}) or a robot .yaml/.urdf path",
    )
    add_link_arguments(parser)


def add_link_arguments(parser: argparse.ArgumentParser) -> None:
    """``--base-link``, ``--tip-link``, ``--tool-link``: the chain of a URDF robot."""
    parser.add_argument(
        "--base-link", metavar="LINK", default=None, help="URDF only: first link of the chain (default: the root link)"
    )
    parser.add_argument(
        "--tip-link",
        metavar="LINK",
        default=None,
        help="URDF only: last link of the chain, the end effector 'ee' (default: where the unbranched chain "
        "below the base ends; required when the tree branches into several arms)",
    )
    parser.add_argument(
        "--tool-link",
        metavar="LINK",
        default=None,
        help="URDF only: a link below the tip, joined by fixed joints, used as the tool frame (default: none)",
    )


def add_joint_argument(
    parser: argparse.ArgumentParser, flag: str = "--q", required: bool = False, help_text: str = ""
) -> None:
    """``--q v1 v2 …`` joint values in model order [rad | m]."""
    parser.add_argument(
        flag,
        nargs="+",
        type=float,
        metavar="V",
        required=required,
        help=help_text or "joint values in model joint order, [rad] or [m] (default: the robot's start configuration)",
    )


def add_pose_arguments(parser: argparse.ArgumentParser, required: bool = True) -> None:
    """``--xyz x y z`` with ``--rpy roll pitch yaw`` or ``--quat x y z w``."""
    parser.add_argument(
        "--xyz", nargs=3, type=float, metavar=("X", "Y", "Z"), required=required, help="position in the base frame [m]"
    )
    rotation = parser.add_mutually_exclusive_group()
    rotation.add_argument(
        "--rpy",
        nargs=3,
        type=float,
        metavar=("ROLL", "PITCH", "YAW"),
        help="orientation, R = Rz(yaw) Ry(pitch) Rx(roll) [rad]",
    )
    rotation.add_argument(
        "--quat", nargs=4, type=float, metavar=("X", "Y", "Z", "W"), help="orientation as a quaternion (x y z w)"
    )


def add_namespace_argument(parser: argparse.ArgumentParser) -> None:
    """``--namespace NS``: the ROS namespace of the pipeline the command talks to."""
    parser.add_argument(
        "--namespace",
        default="",
        metavar="NS",
        help="ROS namespace of the nodes to talk to, as started with --ros-args -r __ns:=/NS "
        "(default: the root namespace)",
    )


def namespace_from_args(args: argparse.Namespace) -> str:
    """``--namespace`` normalised (``left`` → ``/left``); InvalidArgumentError when not a ROS namespace."""
    from manip_kin.pipeline.status import normalize_namespace

    return normalize_namespace(args.namespace)


def add_json_argument(parser: argparse.ArgumentParser) -> None:
    """``--json``: one JSON object on stdout."""
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout and nothing else there")


def robot_from_args(args: argparse.Namespace) -> RobotModel:
    """The model named by ``--robot`` (the chain of ``--base-link``/``--tip-link``/``--tool-link``).

    A URDF joint without a velocity limit is reported on stderr, once: it is not limited.
    """
    from manip_kin.core.urdf import joints_without_velocity_limit

    model = load_robot(args.robot, base_link=args.base_link, tip_link=args.tip_link, tool_link=args.tool_link)
    unlimited = joints_without_velocity_limit(model)
    if unlimited:
        print(
            f"manip_kin: warning: {model.source or args.robot} gives no velocity limit for {', '.join(unlimited)}; "
            "those joints are not speed-limited",
            file=sys.stderr,
        )
    return model


def joints_from_args(model: RobotModel, values, what: str = "--q") -> np.ndarray:
    """``--q`` as an array of shape (n,), or the start configuration when not given."""
    if values is None:
        return model.start_configuration()
    if len(values) != model.dof:
        raise JointCountError(what, len(values), model.dof)
    return model.check_q(values, what)


def pose_from_args(args: argparse.Namespace) -> np.ndarray:
    """The goal pose of ``--xyz`` and ``--rpy``/``--quat`` as a 4x4 transform (orientation default I)."""
    position = np.asarray(args.xyz, dtype=float)
    if args.quat is not None:
        quat = np.asarray(args.quat, dtype=float)
        norm = float(np.linalg.norm(quat))
        if not np.isfinite(norm) or abs(norm - 1.0) > 1e-3:
            raise InvalidArgumentError(f"--quat has length {norm:.6g}; valid: a unit quaternion (x y z w)")
        rotation = quat_to_matrix(quat)
    elif args.rpy is not None:
        rotation = rpy_to_matrix(*args.rpy)
    else:
        rotation = np.eye(3)
    pose = make_transform(rotation, position)
    if not np.all(np.isfinite(pose)):
        raise InvalidArgumentError("--xyz/--rpy contain NaN or infinity; valid: finite numbers")
    return pose


def pose_summary(pose: np.ndarray) -> dict:
    """A pose as JSON-ready ``matrix`` rows, ``xyz``, ``quat_xyzw`` and ``rpy``."""
    return {
        "matrix": pose.tolist(),
        "xyz": pose[:3, 3].tolist(),
        "quat_xyzw": matrix_to_quat(pose[:3, :3]).tolist(),
        "rpy": matrix_to_rpy(pose[:3, :3]).tolist(),
    }


def print_json(payload: dict) -> None:
    """One JSON object, one line, on stdout.

    Raises:
        OperationError: the payload holds NaN or infinity, which JSON cannot carry; nothing
            is printed (a reader must never get ``NaN``).
    """
    try:
        text = json.dumps(payload, allow_nan=False)
    except ValueError:
        raise OperationError("the result holds NaN or infinity, which JSON cannot carry; nothing printed") from None
    sys.stdout.write(text + "\n")


def format_matrix(matrix: np.ndarray, indent: str = "  ") -> str:
    """Rows of a matrix aligned for a terminal."""
    return "\n".join(indent + " ".join(f"{value:9.4f}" for value in row) for row in np.asarray(matrix))
