"""``manip_kin ik`` and ``manip_kin simulate``: joint values for a pose, and the control law run offline.

Exit codes: 0 when IK converged / the simulation converged, 1 when it did not (the output
still says how close it got and why), 2 for unusable input.
"""

from __future__ import annotations

import argparse
import sys

from manip_kin.cli.common import (
    add_joint_argument,
    add_json_argument,
    add_pose_arguments,
    add_robot_argument,
    joints_from_args,
    pose_from_args,
    print_json,
    robot_from_args,
)
from manip_kin.cli.ik_all_command import run_ik_all
from manip_kin.control.resolved_rate import ControllerConfig
from manip_kin.control.simulation import simulate
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import COMPONENTS, default_task, parse_task
from manip_kin.errors import InvalidArgumentError
from manip_kin.ik.all_solutions import require_closed_form
from manip_kin.ik.iterative import DEFAULT_DAMPING, IK_METHODS, solve_ik

_FRAME_HELP = (
    "controlled frame: tool | ee | N (joint frame 1..n) | a link name; default: tool if the robot has one, else ee"
)
_TASK_HELP = (
    "pose components to achieve: full | position | position_yaw | orientation | a comma list of "
    f"{','.join(COMPONENTS)}; default: full with 6+ joints, else what the arm can do "
    "(rpp: position, scara: position_yaw)"
)
_EXIT_CODES = "exit status: 0 converged, 1 not converged (the output says why), 2 bad input"


def register(subparsers) -> None:
    """Add the ``ik`` and ``simulate`` sub-commands."""
    ik = subparsers.add_parser(
        "ik",
        help="inverse kinematics: joint values putting the tool (or a frame) at a pose",
        description="Iterative IK (Levenberg-Marquardt by default) within the joint limits, with "
        "seeded random restarts. Lengths in metres, angles in radians.",
        epilog=_EXIT_CODES,
    )
    add_robot_argument(ik)
    add_pose_arguments(ik)
    add_joint_argument(
        ik, "--q0", help_text="initial guess in model joint order [rad | m] (default: the robot's start configuration)"
    )
    ik.add_argument(
        "--seed", type=int, default=None, metavar="S", help="seed of the random restarts (default: unseeded)"
    )
    ik.add_argument("--method", choices=IK_METHODS, default="lm", help="lm (default), nr (Newton-Raphson) or dls")
    ik.add_argument("--frame", default=None, help=_FRAME_HELP)
    ik.add_argument("--task", default=None, help=_TASK_HELP)
    ik.add_argument(
        "--tolerance-position", type=float, default=1e-6, metavar="M", help="success threshold [m] (default 1e-6)"
    )
    ik.add_argument(
        "--tolerance-orientation",
        type=float,
        default=1e-6,
        metavar="RAD",
        help="success threshold [rad] (default 1e-6)",
    )
    ik.add_argument("--max-iterations", type=int, default=60, metavar="N", help="iterations per attempt (default 60)")
    ik.add_argument("--step", type=float, default=1.0, metavar="A", help="step size in (0, 1] (default 1)")
    ik.add_argument(
        "--damping",
        type=float,
        default=None,
        metavar="L",
        help="lm: added damping λ̄; dls: λ; nr: σ_min below which it damps "
        f"(defaults {', '.join(f'{k} {v:g}' for k, v in DEFAULT_DAMPING.items())})",
    )
    ik.add_argument(
        "--restarts", type=int, default=100, metavar="N", help="random restarts after a failed attempt (default 100)"
    )
    ik.add_argument(
        "--time-budget",
        type=float,
        default=0.5,
        metavar="S",
        help="wall-time limit over all attempts [s] (default 0.5)",
    )
    ik.add_argument(
        "--all",
        action="store_true",
        help="list every distinct solution within the joint limits, from the closed form when the arm has "
        "one, else from seeded restarts within --time-budget; solutions that differ only by whole turns "
        "(±2π) of revolute joints are one solution with a count of wraps (--wraps lists them)",
    )
    ik.add_argument(
        "--wraps",
        action="store_true",
        help="with --all: also list every in-limit ±2π wrap of each solution (JSON: wrap_q)",
    )
    ik.add_argument(
        "--solver",
        choices=("auto", "closed_form", "numeric"),
        default="auto",
        help="auto (default): the closed form for RPP, SCARA and 6R ortho-parallel arms with a spherical "
        "wrist, else the iteration; numeric: always iterate (as --method, --step, --damping ask)",
    )
    add_json_argument(ik)
    ik.set_defaults(run=run_ik)

    sim = subparsers.add_parser(
        "simulate",
        help="run the resolved-rate control law offline from --q0 to a goal pose",
        description="Kinematic simulation of the cartesian controller: q <- q + qdot*dt with the "
        "joint limits, until the tool is within --tolerance of the goal or --duration elapses.",
        epilog=_EXIT_CODES,
    )
    add_robot_argument(sim)
    add_joint_argument(
        sim,
        "--q0",
        help_text="start configuration in model joint order [rad | m] (default: the robot's start configuration)",
    )
    add_pose_arguments(sim)
    sim.add_argument("--gain-linear", type=float, default=0.8, metavar="K", help="position gain [1/s] (default 0.8)")
    sim.add_argument(
        "--gain-angular", type=float, default=0.8, metavar="K", help="orientation gain [1/s] (default 0.8)"
    )
    sim.add_argument(
        "--dt", type=float, default=0.001, metavar="S", help="control period and integration step [s] (default 0.001)"
    )
    sim.add_argument("--duration", type=float, default=20.0, metavar="S", help="simulated time limit [s] (default 20)")
    sim.add_argument(
        "--tolerance", type=float, default=1e-6, metavar="E", help="convergence threshold [m] and [rad] (default 1e-6)"
    )
    sim.add_argument("--frame", default=None, help=_FRAME_HELP)
    sim.add_argument("--task", default=None, help=_TASK_HELP)
    sim.add_argument(
        "--ignore-position-limits",
        action="store_true",
        help="let the controller ignore the position limits (the simulation still clamps q): shows why they matter",
    )
    add_json_argument(sim)
    sim.set_defaults(run=run_simulate)


def _announce_task(command: str, model: RobotModel, requested: str | None, frame: str | None) -> str | None:
    """The task to pass on; says on stderr when an under-actuated arm gets a partial default."""
    if requested is not None:
        return requested
    if model.dof >= 6:
        return None
    task = default_task(model, frame)
    components = ", ".join(COMPONENTS[r] for r in task.rows)
    print(
        f"manip_kin {command}: {model.name} has {model.dof} joints and cannot reach an arbitrary pose; "
        f"solving the '{task.name}' task ({components}); choose another with --task",
        file=sys.stderr,
    )
    return task.name


def _check_task(model: RobotModel, task: str | None) -> None:
    if task is not None:
        parse_task(task, model)  # a bad --task is a one-line error before any work


def run_ik(args: argparse.Namespace) -> int:
    model = robot_from_args(args)
    target = pose_from_args(args)
    q0 = joints_from_args(model, args.q0, "--q0")
    _check_task(model, args.task)
    task = _announce_task("ik", model, args.task, args.frame)
    if args.all:
        return run_ik_all(args, model, target, q0, task)
    if args.solver == "closed_form":
        require_closed_form(model, args.frame, task)
    result = solve_ik(
        model,
        target,
        q0,
        method=args.method,
        frame=args.frame,
        task=task,
        tolerance_position=args.tolerance_position,
        tolerance_orientation=args.tolerance_orientation,
        max_iterations=args.max_iterations,
        step=args.step,
        damping=args.damping,
        restarts=args.restarts,
        time_budget=args.time_budget,
        seed=args.seed,
        closed_form=args.solver != "numeric",
    )
    frame = model.frame_name(model.frame_index(args.frame or model.default_frame))
    if args.json:
        print_json(
            {
                "q": result.q.tolist(),
                "success": result.success,
                "iterations": result.iterations,
                "position_error": result.position_error,
                "orientation_error": result.orientation_error,
                "reason": result.reason,
                "attempts": result.attempts,
                "task": result.task,
                "method": args.method,
                "frame": frame,
                "elapsed_s": result.elapsed,
                "solver": result.solver,
            }
        )
    else:
        status = "converged" if result.success else "did NOT converge"
        method = args.method if result.solver == "numeric" else result.solver
        print(f"{model.name}: IK for frame '{frame}' ({method}, task {result.task}) {status}")
        if not result.success:
            print(f"  reason: {result.reason}")
        print(f"  q = {[round(v, 6) for v in result.q.tolist()]}")
        print(f"  position error {result.position_error:.3g} m, orientation error {result.orientation_error:.3g} rad")
        print(f"  {result.iterations} iterations, {result.attempts} attempt(s), {result.elapsed * 1e3:.2f} ms")
    return 0 if result.success else 1


def run_simulate(args: argparse.Namespace) -> int:
    model = robot_from_args(args)
    goal = pose_from_args(args)
    q0 = joints_from_args(model, args.q0, "--q0")
    _check_task(model, args.task)
    task = _announce_task("simulate", model, args.task, args.frame)
    for name in ("dt", "duration", "tolerance"):
        value = getattr(args, name)
        if not value > 0:  # also rejects NaN
            raise InvalidArgumentError(f"--{name} {value!r}; valid: a number > 0")
    config = ControllerConfig(
        gain_angular=args.gain_angular,
        gain_linear=args.gain_linear,
        frame=args.frame,
        task=task,
        respect_position_limits=not args.ignore_position_limits,
    )
    # Samples are not printed; one in a hundred keeps memory small on long runs.
    result = simulate(
        model, q0, goal, config, dt=args.dt, duration=args.duration, tolerance=args.tolerance, record_every=100
    )
    hit_limits = sorted({model.joints[j].name for j in range(model.dof) if result.limited[:, j].any()})
    if args.json:
        print_json(
            {
                "converged": result.converged,
                "time_to_converge": result.time_to_converge,
                "final_error": {"position": result.final_position_error, "orientation": result.final_orientation_error},
                "q_final": result.q_final.tolist(),
                "steps": result.steps,
                "reason": result.reason,
                "task": result.task,
                "frame": model.frame_name(model.frame_index(args.frame or model.default_frame)),
                "joints_held_at_limits": hit_limits,
                "max_velocity_ratio": result.max_velocity_ratio,
            }
        )
    else:
        if result.converged:
            print(
                f"{model.name}: converged in {result.time_to_converge:.3f} s of simulated time ({result.steps} steps of {args.dt:g} s)"
            )
        else:
            print(f"{model.name}: did NOT converge in {args.duration:g} s ({result.steps} steps of {args.dt:g} s)")
            print(f"  reason: {result.reason}")
        print(
            f"  final error: position {result.final_position_error:.3g} m, orientation {result.final_orientation_error:.3g} rad"
            f" (task {result.task}, tolerance {args.tolerance:g})"
        )
        print(f"  q_final = {[round(v, 6) for v in result.q_final.tolist()]}")
        if hit_limits:
            print(f"  joints held at a position limit on the way: {', '.join(hit_limits)}")
        print(f"  highest joint speed: {100 * result.max_velocity_ratio:.1f}% of its limit")
    return 0 if result.converged else 1
