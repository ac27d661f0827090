"""``manip_kin goal`` and ``manip_kin line``: send one pose to the running pipeline.

Both are real rclpy nodes: they wait until a subscriber is matched on the topic, publish
the pose once (reliable) and wait until the subscriber acknowledged it, so the message is
delivered when the command returns. ``--wait`` then follows ``/diagnostics`` until the
controller reports the goal converged (for ``line``: until the generator finished the line
and the controller converged on its final pose) and prints the final errors.

With ``--xyz`` alone (no ``--rpy``/``--quat``) the target is position-only: the message
carries the current tool orientation (from ``tool_pose``), which a controller and generator
with ``task:=position`` leave free.

Without ``--wait`` the command returns once the controller reports the goal's stamp as its
goal (a goal it missed is sent again), so goals sent one after another are each followed.
``--frame`` defaults to the base frame the controller reports. Ctrl-C during ``--wait`` stops
the motion it started (the controller's ``~/stop``, and the generator's for a line).

Exit codes: 0 delivered (and converged with ``--wait``); 1 ``--wait`` ended without
convergence (unreachable, stopped or timed out; the reason and the final errors are printed),
or a line that leaves the arm's reach; 2 bad input, no subscriber within ``--timeout``, or a
goal or line target rejected as invalid (with the node's reason); 130 interrupted.
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
from manip_kin.errors import EXIT_INTERRUPTED, InvalidArgumentError


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
        "--frame",
        default=None,
        help="frame_id of the pose: the robot's base frame (default: the one the controller reports)",
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
    closest = status.values.get("unreachable_errors", "").split()
    if position != position and len(closest) == 2:  # halted at an unreachable goal: the closest pose's
        position, orientation = float(closest[0]), float(closest[1])
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
    """Publish the pose with ``send`` once each node's /diagnostics is heard (so the outcome is
    too); without ``--wait``, return once the controller has taken it.

    Returns:
        ``(start time, stamp, payload)`` once delivered, or an exit code when done.
    """
    from manip_kin.pipeline import PipelineError

    pose = pose_from_args(args)
    position_only = args.rpy is None and args.quat is None
    try:
        from geometry_msgs.msg import PoseStamped

        client.wait_subscribers(PoseStamped, topic, args.timeout, latched=True)  # "nobody listens" first
        statuses = [client.wait_status(node, args.timeout) for node in ready_nodes]
        client.base_frame = args.frame or statuses[-1].values.get("base_frame") or "base_link"
        if position_only:
            pose[:3, :3] = client.current_tool_pose(args.timeout)[:3, :3]
        start = time.monotonic()
        stamp = send(pose, timeout=args.timeout)
        taken = client.wait_taken(stamp, args.timeout) if topic == "goal_pose" and not args.wait else None
    except PipelineError as error:
        print(f"manip_kin {args.command}: error: {error}", file=sys.stderr)
        return 2
    topic = client.topic(topic)
    payload = {
        "topic": topic,
        "stamp": stamp,
        "xyz": pose[:3, 3].tolist(),
        "frame": client.base_frame,
        "position_only": position_only,
    }
    if taken is not None and client.outcome(taken, stamp).word == "rejected":
        print(
            f"manip_kin {args.command}: error: goal rejected: {taken.values.get('last_rejection', '')}", file=sys.stderr
        )
        return 2
    if not args.wait:
        what = "taken by the controller" if taken is not None else "delivered"
        _report(args, payload, f"{label} {pose[:3, 3].round(4).tolist()} {what} on {topic} (stamp {stamp})")
        return 0
    return start, stamp, payload


def _await_convergence(
    args, client, goal_stamp: str, start: float, payload: dict, label: str, timeout: float, generator=None
) -> int:
    """Wait for the controller to say how ``goal_stamp`` ended; report; its exit code.

    ``generator``: the generator's status of the line that ends with ``goal_stamp`` (the
    times are then measured from the line's start, else from the goal's stamp).
    """
    from manip_kin.pipeline.outcome import motion_timing

    converged, status = client.wait_converged(goal_stamp, timeout)
    elapsed = client.time_to_converge(goal_stamp, start, sent_stamp=payload["stamp"])
    outcome = client.outcome(status, goal_stamp)
    if outcome.word == "rejected":
        print(f"manip_kin {args.command}: error: goal rejected: {outcome.reason}", file=sys.stderr)
        return 2
    errors = _errors(status)
    timing = motion_timing(
        payload["stamp"], status.values if status else {}, generator.values if generator is not None else None
    )
    payload.update(
        converged=converged,
        outcome=outcome.word or "timeout",
        reason=outcome.reason,
        time=elapsed,
        **timing.fields(converged),
        final_error=errors,
        state=status.message if status else None,
    )
    if converged:
        verdict = timing.converged_verdict(label, elapsed)
    elif outcome.word:
        verdict = f"{outcome.word} after {elapsed:.2f} s ({outcome.reason})"
    else:
        verdict = f"NOT converged after {elapsed:.2f} s (state {payload['state']})"
    if not converged and timing.motion_s is not None:
        verdict += f" ({label} ended after {timing.motion_s:.2f} s)"
    _report(args, payload, f"{label} {verdict}: {_format_errors(errors)}")
    return outcome.exit_code


def stop_on_interrupt(command: str, client, nodes: tuple[str, ...]) -> int:
    """After Ctrl-C of a waiting command: halt what it started (``~/stop`` of each node, the
    streaming one first); exit code 130."""
    from manip_kin.pipeline import PipelineError

    for node in nodes:
        try:
            client.call_trigger(node, "stop", timeout=2.0)
        except PipelineError as error:
            print(f"manip_kin {command}: could not stop {node}: {error}", file=sys.stderr)
    print(f"manip_kin {command}: interrupted: stopped the motion ({', '.join(nodes)})", file=sys.stderr)
    return EXIT_INTERRUPTED


def run_goal(args: argparse.Namespace) -> int:
    """``manip_kin goal``."""
    from manip_kin.pipeline import PipelineClient

    _check_timeout(args)
    namespace = namespace_from_args(args)
    with PipelineClient(watch_state=False, namespace=namespace) as client:
        try:
            delivered = _deliver(args, client, client.send_goal, "goal_pose", "goal", ("cartesian_controller",))
            if isinstance(delivered, int):
                return delivered
            start, stamp, payload = delivered
            return _await_convergence(args, client, stamp, start, payload, "goal", args.timeout)
        except KeyboardInterrupt:
            # Also while the goal is being delivered: the controller may have it already.
            return stop_on_interrupt("goal", client, ("cartesian_controller",))


def run_line(args: argparse.Namespace) -> int:
    """``manip_kin line``."""
    from manip_kin.pipeline import PipelineClient

    _check_timeout(args)
    namespace = namespace_from_args(args)
    with PipelineClient(watch_state=False, namespace=namespace) as client:
        try:
            return _run_line(args, client)
        except KeyboardInterrupt:
            return stop_on_interrupt("line", client, ("trajectory_generator", "cartesian_controller"))


def _run_line(args: argparse.Namespace, client) -> int:
    from manip_kin.pipeline import PipelineError

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
        print(f"manip_kin line: error: target rejected: {generator.values.get('last_rejection', '')}", file=sys.stderr)
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
        generator=generator,
    )
