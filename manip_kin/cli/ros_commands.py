"""``manip_kin goal`` and ``manip_kin line``: send one pose to the running pipeline.

Both are real rclpy nodes: they wait until a subscriber is matched on the topic, publish
the pose once (reliable) and wait until the subscriber acknowledged it, so the message is
delivered when the command returns. ``--wait`` then follows ``/diagnostics`` until the
controller reports the goal converged (for ``line``: until the generator finished the line
and the controller converged on its final pose) and prints the final errors.

Exit codes: 0 delivered (and converged with ``--wait``); 1 ``--wait`` timed out before
convergence (the final errors are printed); 2 bad input, no subscriber within
``--timeout``, or a line the generator rejected.
"""

from __future__ import annotations

import argparse
import sys
import time

from manip_kin.cli.common import add_json_argument, add_pose_arguments, pose_from_args, print_json
from manip_kin.errors import InvalidArgumentError


def register(subparsers) -> None:
    """Add ``goal`` and ``line``."""
    goal = subparsers.add_parser(
        "goal",
        help="publish one goal pose on /goal_pose for cartesian_controller (optionally wait until reached)",
        description="Publish one goal pose of the controlled frame (tool if any, else end effector) in the "
        "base frame on /goal_pose, and exit once the controller has it. Example: "
        "manip_kin goal --xyz 0.2 -0.7 0.3 --rpy 0 1.57 0 --wait",
    )
    _add_common(goal)
    goal.set_defaults(run=run_goal)
    line = subparsers.add_parser(
        "line",
        help="publish one line target on /line_target for trajectory_generator (optionally wait until done)",
        description="Publish the end pose of a straight line on /line_target; trajectory_generator plans the "
        "line from the current tool pose and streams it to the controller. Example: "
        "manip_kin line --xyz -0.4 0.3 0.5 --rpy 0 1.5708 0 --wait",
    )
    _add_common(line)
    line.set_defaults(run=run_line)


def _add_common(parser: argparse.ArgumentParser) -> None:
    add_pose_arguments(parser)
    parser.add_argument("--frame", default="base_link", help="frame_id of the pose: the base frame of the robot (default base_link)")
    parser.add_argument("--wait", action="store_true", help="block until the controller reports converged (or --timeout), print the final error")
    parser.add_argument("--timeout", type=float, default=30.0, metavar="S", help="seconds to wait for a subscriber, and for convergence with --wait (default 30)")
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


def run_goal(args: argparse.Namespace) -> int:
    """``manip_kin goal``."""
    from manip_kin.pipeline import PipelineClient, PipelineError

    _check_timeout(args)
    pose = pose_from_args(args)
    with PipelineClient(watch_state=False, base_frame=args.frame) as client:
        try:
            if args.wait:
                # A status from the controller proves /diagnostics is matched before the goal goes out.
                client.wait_status("cartesian_controller", args.timeout)
            start = time.monotonic()
            stamp = client.send_goal(pose, timeout=args.timeout)
        except PipelineError as error:
            print(f"manip_kin goal: error: {error}", file=sys.stderr)
            return 2
        payload = {"topic": "/goal_pose", "stamp": stamp, "xyz": pose[:3, 3].tolist(), "frame": args.frame}
        if not args.wait:
            _report(args, payload, f"goal {pose[:3, 3].round(4).tolist()} delivered on /goal_pose (stamp {stamp})")
            return 0
        converged, status = client.wait_converged(stamp, args.timeout)
        elapsed = time.monotonic() - start
        errors = _errors(status)
        payload.update(converged=converged, time=elapsed, final_error=errors, state=status.message if status else None)
        verdict = f"converged in {elapsed:.2f} s" if converged else f"NOT converged after {elapsed:.2f} s (state {payload['state']})"
        _report(args, payload, f"goal {verdict}: {_format_errors(errors)}")
        return 0 if converged else 1


def run_line(args: argparse.Namespace) -> int:
    """``manip_kin line``."""
    from manip_kin.pipeline import PipelineClient, PipelineError

    _check_timeout(args)
    pose = pose_from_args(args)
    with PipelineClient(watch_state=False, base_frame=args.frame) as client:
        try:
            if args.wait:
                client.wait_status("trajectory_generator", args.timeout)
                client.wait_status("cartesian_controller", args.timeout)
            start = time.monotonic()
            stamp = client.send_line(pose, timeout=args.timeout)
        except PipelineError as error:
            print(f"manip_kin line: error: {error}", file=sys.stderr)
            return 2
        payload = {"topic": "/line_target", "stamp": stamp, "xyz": pose[:3, 3].tolist(), "frame": args.frame}
        if not args.wait:
            _report(args, payload, f"line target {pose[:3, 3].round(4).tolist()} delivered on /line_target (stamp {stamp})")
            return 0
        try:
            generator = client.wait_line_done(stamp, args.timeout)
        except PipelineError as error:
            print(f"manip_kin line: error: {error}", file=sys.stderr)
            return 1
        if generator.values.get("rejected_stamp") == stamp:
            print(f"manip_kin line: error: target rejected: {generator.values.get('last_rejection', '')}", file=sys.stderr)
            return 2
        line_time = time.monotonic() - start
        remaining = max(args.timeout - line_time, 0.1)
        converged, status = client.wait_converged(generator.values["final_goal_stamp"], remaining)
        elapsed = time.monotonic() - start
        errors = _errors(status)
        payload.update(
            converged=converged,
            time=elapsed,
            line_duration=generator.number("duration"),
            final_error=errors,
            state=status.message if status else None,
        )
        verdict = f"converged in {elapsed:.2f} s" if converged else f"NOT converged after {elapsed:.2f} s (state {payload['state']})"
        _report(args, payload, f"line {verdict} (line {payload['line_duration']:.2f} s): {_format_errors(errors)}")
        return 0 if converged else 1
