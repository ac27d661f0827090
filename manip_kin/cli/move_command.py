"""``manip_kin move``: a joint-space move through ``trajectory_generator``.

The command reads the running arm's model from ``robot_description`` (or ``--robot``) and
its configuration from ``joint_states``, checks the target against the joint limits and
sends one ``trajectory_msgs/JointTrajectory`` point on ``joint_trajectory`` at
``--duration``, or at time 0, which the generator times itself as fast as its joint limits
(velocity, acceleration, jerk) allow. The generator interpolates it with its
``joint_time_scaling`` (``--time-scaling`` sets that parameter first when it differs) and
streams ``joint_reference`` to the controller. The command returns once the generator has
started (or rejected) the move; ``--wait`` follows ``/diagnostics`` until the controller
reports the move converged. Ctrl-C during ``--wait`` stops the move.

Exit codes: 0 started (and converged with ``--wait``); 1 not converged within
``--timeout``; 2 bad input (wrong joint count, a target outside the limits, a duration too
short for the joint limits, no pipeline), one line on stderr; 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from manip_kin.cli.common import (
    add_json_argument,
    add_link_arguments,
    add_namespace_argument,
    namespace_from_args,
    print_json,
)
from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError, JointCountError
from manip_kin.motion.joint_trajectory import JOINT_TIME_SCALINGS, TrajectoryPoint

_GENERATOR = "trajectory_generator"
_CONTROLLER = "cartesian_controller"


def register(subparsers) -> None:
    """Add ``move``."""
    move = subparsers.add_parser(
        "move",
        help="joint-space move of the running arm to --q through trajectory_generator (optionally wait)",
        description="Move every joint from where it is to --q along q0 + s(t)(q - q0): one JointTrajectory "
        "point on joint_trajectory, interpolated by trajectory_generator with its time scaling, followed by "
        "cartesian_controller. Example (scara): manip_kin move --q 0.7854 0.7854 0.2 0 --duration 2 "
        "--time-scaling cubic --wait",
        epilog="exit status: 0 done, 1 not converged within --timeout, 2 bad input (one line on stderr)",
    )
    move.add_argument(
        "--q", nargs="+", type=float, required=True, metavar="V", help="target joint values in model order [rad | m]"
    )
    move.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="duration of the move [s] (default: the shortest within the generator's joint limits)",
    )
    move.add_argument(
        "--time-scaling",
        choices=JOINT_TIME_SCALINGS,
        default=None,
        help="s(t): cubic 3τ²-2τ³, quintic 10τ³-15τ⁴+6τ⁵ or trapezoidal; sets the generator's "
        "joint_time_scaling parameter (default: the generator's, cubic unless configured)",
    )
    move.add_argument(
        "--robot",
        default=None,
        metavar="NAME|FILE",
        help="the arm's model (default: the URDF on robot_description from robot_state)",
    )
    add_link_arguments(move)
    move.add_argument("--wait", action="store_true", help="block until the controller reports converged")
    move.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="seconds to wait for the pipeline, and for the move with --wait (default 30)",
    )
    add_namespace_argument(move)
    add_json_argument(move)
    move.set_defaults(run=run_move)


def _model(args, client) -> RobotModel:
    links = {"base_link": args.base_link, "tip_link": args.tip_link, "tool_link": args.tool_link}
    if args.robot is not None:
        from manip_kin.core.robots import load_robot

        return load_robot(args.robot, **links)
    from manip_kin.core.urdf import load_urdf_string

    text = client.robot_description(args.timeout)
    return load_urdf_string(text, source=client.topic("robot_description"), **links)


def _check_target(model: RobotModel, values) -> np.ndarray:
    if len(values) != model.dof:
        raise JointCountError("--q", len(values), model.dof)
    q = model.check_q(values, "--q")
    for j, value in enumerate(q):
        if not model.lower[j] <= value <= model.upper[j]:
            unit = "rad" if model.joints[j].is_revolute else "m"
            raise InvalidArgumentError(
                f"--q: joint '{model.joint_names[j]}' = {value:g} {unit} is outside its limits; "
                f"valid: [{model.lower[j]:.6g}, {model.upper[j]:.6g}] {unit}"
            )
    return q


def _set_time_scaling(client, scaling: str, timeout: float) -> str:
    """The generator's joint_time_scaling after asking for ``scaling`` (set only when it differs)."""
    current = client.wait_status(_GENERATOR, timeout).values.get("joint_time_scaling", "")
    if current == scaling:
        return current
    client.set_parameter(_GENERATOR, "joint_time_scaling", scaling, timeout)
    return scaling


def run_move(args: argparse.Namespace) -> int:
    """``manip_kin move``."""
    from manip_kin.pipeline import PipelineClient

    if args.duration is not None and not args.duration > 0:
        raise InvalidArgumentError(f"--duration {args.duration!r}; valid: seconds > 0")
    if not args.timeout > 0:
        raise InvalidArgumentError(f"--timeout {args.timeout!r}; valid: seconds > 0")
    namespace = namespace_from_args(args)
    with PipelineClient(namespace=namespace) as client:
        try:
            return _move(args, client)
        except KeyboardInterrupt:
            from manip_kin.cli.ros_commands import stop_on_interrupt

            return stop_on_interrupt("move", client, (_GENERATOR, _CONTROLLER))


def _move(args: argparse.Namespace, client) -> int:
    from manip_kin.pipeline import PipelineError
    from manip_kin.ros.wire.joint_messages import make_joint_trajectory
    from manip_kin.ros.wire.validation import JointStateMapper

    try:
        model = _model(args, client)
        q_goal = _check_target(model, args.q)
        client.current_positions(args.timeout)
        q_start = JointStateMapper(model.joint_names).positions(client.joint_state)
        scaling = client.wait_status(_GENERATOR, args.timeout).values.get("joint_time_scaling") or "cubic"
        if args.time_scaling is not None:
            scaling = _set_time_scaling(client, args.time_scaling, args.timeout)
        # 0: as fast as the generator's joint limits allow; it times the move itself, so a
        # duration computed here from a stale snapshot cannot be refused.
        point = TrajectoryPoint(args.duration or 0.0, q_goal)
        for node in (_GENERATOR, _CONTROLLER) if args.wait else (_GENERATOR,):
            client.wait_status(node, args.timeout)  # /diagnostics matched before the move goes out
        start = time.monotonic()
        stamp = client.send_joint_trajectory(make_joint_trajectory(model.joint_names, [point]), args.timeout)
        generator = client.wait_target_taken(stamp, args.timeout, _GENERATOR)
    except PipelineError as error:
        print(f"manip_kin move: error: {error}", file=sys.stderr)
        return 2
    if generator.values.get("rejected_stamp") == stamp:
        reason = generator.values.get("last_rejection", "")
        print(f"manip_kin move: error: trajectory rejected: {reason}", file=sys.stderr)
        return 2
    duration = generator.number("duration")
    payload = {
        "topic": client.topic("joint_trajectory"),
        "stamp": stamp,
        "joint_names": model.joint_names,
        "q_start": q_start.tolist(),
        "q_goal": q_goal.tolist(),
        "duration": duration,
        "time_scaling": scaling,
    }
    summary = (
        f"move of {model.name} from {np.round(q_start, 4).tolist()} to {np.round(q_goal, 4).tolist()} "
        f"in {duration:.3f} s ({scaling})"
    )
    if not args.wait:
        _report(args, payload, f"{summary} started on {payload['topic']} (stamp {stamp})")
        return 0
    return _await(args, client, stamp, start, payload, summary)


def _await(args, client, stamp: str, start: float, payload: dict, summary: str) -> int:
    from manip_kin.pipeline import PipelineError
    from manip_kin.pipeline.outcome import motion_timing

    try:
        generator = client.wait_line_done(stamp, args.timeout, _GENERATOR)
    except PipelineError as error:
        print(f"manip_kin move: error: {error}", file=sys.stderr)
        return 1
    remaining = max(args.timeout - (time.monotonic() - start), 0.1)
    converged, status = client.wait_converged(generator.values["final_goal_stamp"], remaining, _CONTROLLER)
    elapsed = client.time_to_converge(generator.values["final_goal_stamp"], start, _CONTROLLER, stamp)
    errors = {key: _number(status, f"{key}_error") for key in ("joint", "position", "orientation")}
    timing = motion_timing(stamp, status.values if status else {}, generator.values)
    payload.update(
        converged=converged,
        time=elapsed,
        **timing.fields(converged),
        final_error=errors,
        state=status.message if status else None,
    )
    if converged:
        verdict = timing.converged_verdict("move", elapsed)
    else:
        verdict = f"NOT converged after {elapsed:.2f} s"
    if errors["joint"] is None:
        detail = "errors unknown (no controller status for this move)"
    else:
        detail = (
            f"joint error {errors['joint']:.3g}, position error {errors['position']:.3g} m, "
            f"orientation error {errors['orientation']:.3g} rad"
        )
    _report(args, payload, f"{summary} {verdict}: {detail}")
    return 0 if converged else 1


def _number(status, key: str) -> float | None:
    value = status.number(key) if status is not None else float("nan")
    return None if value != value else value


def _report(args, payload: dict, line: str) -> None:
    if args.json:
        print_json(payload)
    else:
        print(line)
