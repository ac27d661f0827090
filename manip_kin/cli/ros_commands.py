"""``manip_kin goal`` and ``manip_kin line``: send one pose to the running pipeline.

Both are real rclpy nodes: they wait until a subscriber is matched on the topic, publish
the pose once (reliable) and wait until the subscriber acknowledged it, so the message is
delivered when the command returns. ``--wait`` then follows ``/diagnostics`` until the
controller reports the goal converged (for ``line``: until the generator finished the line
and the controller converged on its final pose) and prints the final errors.

With ``--xyz`` alone (no ``--rpy``/``--quat``) the target is position-only: the message
carries the current tool orientation (from ``tool_pose``), which a controller and generator
with ``task:=position`` leave free.

Exit codes: 0 delivered (and converged with ``--wait``); 1 ``--wait`` timed out before
convergence (the final errors are printed), or a line that leaves the arm's reach; 2 bad
input, no subscriber within ``--timeout``, or a line target the generator rejected as invalid.
"""

from __future__ import annotations

import argparse
import sys
import time

from manip_kin.cli.common import (
    add_json_argument,
    add_namespace_argument,
    add_pose_arguments,
    namespace_from_args,
    pose_from_args,
    print_json,
)
from manip_kin.errors import InvalidArgumentError


def register(subparsers) -> None:
    """Add ``goal`` and ``line``."""
    goal = subparsers.add_parser(
        "goal",
        help="publish one goal pose on goal_pose for cartesian_controller (optionally wait until reached)",
        description="Publish one goal pose of the controlled frame (tool if any, else end effector) in the "
        "base frame on goal_pose (in --namespace), and exit once the controller has it. With --xyz alone the "
        "goal is position-only (it carries the current tool orientation). Example: "
        "manip_kin goal --xyz 0.2 -0.7 0.3 --rpy 0 1.57 0 --wait --namespace /left",
    )
    _add_common(goal)
    goal.set_defaults(run=run_goal)
    line = subparsers.add_parser(
        "line",
        help="publish one line target on line_target for trajectory_generator (optionally wait until done)",
        description="Publish the end pose of a straight line on line_target (in --namespace); "
        "trajectory_generator plans the "
        "line from the current tool pose and streams it to the controller. With --xyz alone the target is "
        "position-only (it carries the current tool orientation). A line that leaves the arm's reach is refused "
        "with where and why (exit 1). Example: "
        "manip_kin line --xyz -0.4 0.3 0.5 --rpy 0 1.5708 0 --wait",
    )
    _add_common(line)
    line.set_defaults(run=run_line)


def _add_common(parser: argparse.ArgumentParser) -> None:
    add_pose_arguments(parser)
    parser.add_argument(
        "--frame", default="base_link", help="frame_id of the pose: the base frame of the robot (default base_link)"
    )
    parser.add_argument(
        "--wait",
        action="store_true",
        help="block until the controller reports converged (or --timeout), print the final error",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="seconds to wait for a subscriber, and for convergence with --wait (default 30)",
    )
    add_namespace_argument(parser)
    add_json_argument(parser)


def _check_timeout(args) -> None:
    if not (args.timeout > 0):
        raise InvalidArgumentError(f"--timeout {args.timeout}; valid: seconds > 0")


def _errors(status) -> dict:
    if status is None:
        return {"position": None, "orientation": None}
    position, orientation = status.number("position_error"), status.number("orientation_error")
    return {
        "position": None if position != position else position,
        "orientation": None if orientation != orientation else orientation,
    }


def _report(args, payload: dict, line: str) -> None:
    if args.json:
        print_json(payload)
    else:
        print(line)


def _format_errors(errors: dict) -> str:
    if errors["position"] is None:
        return "errors unknown (no controller status for this goal)"
    return f"position error {errors['position']:.3g} m, orientation error {errors['orientation']:.3g} rad"


def _deliver(args, client, send, topic: str, label: str, ready_nodes: tuple[str, ...]):
    """Publish the pose with ``send``; with ``--wait``, first hear each node's /diagnostics.

    Returns:
        ``(start time, stamp, payload)`` once delivered, or an exit code when done.
    """
    from manip_kin.pipeline import PipelineError

    pose = pose_from_args(args)
    position_only = args.rpy is None and args.quat is None
    try:
        if position_only:
            from geometry_msgs.msg import PoseStamped

            client.wait_subscribers(PoseStamped, topic, args.timeout)  # "nobody listens" before "no tool pose"
            pose[:3, :3] = client.current_tool_pose(args.timeout)[:3, :3]
        if args.wait:
            # A status from each node proves /diagnostics is matched before the pose goes out.
            for node in ready_nodes:
                client.wait_status(node, args.timeout)
        start = time.monotonic()
        stamp = send(pose, timeout=args.timeout)
    except PipelineError as error:
        print(f"manip_kin {args.command}: error: {error}", file=sys.stderr)
        return 2
    topic = client.topic(topic)
    payload = {
        "topic": topic,
        "stamp": stamp,
        "xyz": pose[:3, 3].tolist(),
        "frame": args.frame,
        "position_only": position_only,
    }
    if not args.wait:
        _report(args, payload, f"{label} {pose[:3, 3].round(4).tolist()} delivered on {topic} (stamp {stamp})")
        return 0
    return start, stamp, payload


def _await_convergence(
    args, client, goal_stamp: str, start: float, payload: dict, label: str, timeout: float, suffix: str = ""
) -> int:
    """Wait for the controller to report ``goal_stamp`` converged; report; 0 or 1."""
    converged, status = client.wait_converged(goal_stamp, timeout)
    elapsed = client.time_to_converge(goal_stamp, start)
    errors = _errors(status)
    payload.update(converged=converged, time=elapsed, final_error=errors, state=status.message if status else None)
    verdict = (
        f"converged in {elapsed:.2f} s"
        if converged
        else f"NOT converged after {elapsed:.2f} s (state {payload['state']})"
    )
    _report(args, payload, f"{label} {verdict}{suffix}: {_format_errors(errors)}")
    return 0 if converged else 1


def run_goal(args: argparse.Namespace) -> int:
    """``manip_kin goal``."""
    from manip_kin.pipeline import PipelineClient

    _check_timeout(args)
    namespace = namespace_from_args(args)
    with PipelineClient(watch_state=False, base_frame=args.frame, namespace=namespace) as client:
        delivered = _deliver(args, client, client.send_goal, "goal_pose", "goal", ("cartesian_controller",))
        if isinstance(delivered, int):
            return delivered
        start, stamp, payload = delivered
        return _await_convergence(args, client, stamp, start, payload, "goal", args.timeout)


def run_line(args: argparse.Namespace) -> int:
    """``manip_kin line``."""
    from manip_kin.pipeline import PipelineClient, PipelineError

    _check_timeout(args)
    namespace = namespace_from_args(args)
    with PipelineClient(watch_state=False, base_frame=args.frame, namespace=namespace) as client:
        delivered = _deliver(
            args,
            client,
            client.send_line,
            "line_target",
            "line target",
            ("trajectory_generator", "cartesian_controller"),
        )
        if isinstance(delivered, int):
            return delivered
        start, stamp, payload = delivered
        try:
            generator = client.wait_line_done(stamp, args.timeout)
        except PipelineError as error:
            print(f"manip_kin line: error: {error}", file=sys.stderr)
            return 1
        if generator.values.get("rejected_stamp") == stamp:
            print(
                f"manip_kin line: error: target rejected: {generator.values.get('last_rejection', '')}", file=sys.stderr
            )
            # A valid line the arm cannot follow is "not achieved" (1); a malformed one is bad input (2).
            return 1 if generator.values.get("rejection_kind") == "unreachable" else 2
        payload["line_duration"] = generator.number("duration")
        remaining = max(args.timeout - (time.monotonic() - start), 0.1)
        return _await_convergence(
            args,
            client,
            generator.values["final_goal_stamp"],
            start,
            payload,
            "line",
            remaining,
            suffix=f" (line {payload['line_duration']:.2f} s)",
        )
