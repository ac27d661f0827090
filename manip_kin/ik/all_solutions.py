"""Every IK solution of a pose within the joint limits (``manip_kin ik --all``).

Arms with a closed form (:mod:`manip_kin.ik.closed_form`) list all its branches, each revolute
joint wrapped into its limits with every in-limit wrap listed, each verified by forward
kinematics; a branch that misses the tolerances (a model only nearly of the structure) is
refined by the iteration and kept when that converges. :func:`group_wraps` folds the wraps
(solutions differing only by whole turns of revolute joints) into one solution each. Other arms run the iterative solver
from ``q0`` and then from seeded random starts until ``restarts`` or ``time_budget`` is used
up, and list the distinct solutions found (a redundant arm has infinitely many: the list is a
sample, not the set).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import Task, parse_task
from manip_kin.core.rotations import check_rotation
from manip_kin.errors import InvalidArgumentError, NonFiniteError
from manip_kin.ik.closed_form import (
    Solution,
    closed_form_solutions,
    distinct,
    in_limit_variants,
    solver_for_task,
    task_error_function,
)
from manip_kin.ik.closed_form.geometry import wrap_to_pi
from manip_kin.ik.iterative import solve_ik

SOLVERS = ("auto", "closed_form", "numeric")
# Numeric solutions closer than this in every joint are the same solution [rad | m].
NUMERIC_DISTINCT = 1e-4


@dataclass(frozen=True)
class WrapGroup:
    """One distinct IK solution and its other in-limit wraps.

    Attributes:
        solution: the member with the fewest whole turns of its revolute joints.
        wraps: the other members, equal to ``solution`` up to whole turns (±2πk) of
            revolute joints; sorted by turns, then branch.
    """

    solution: Solution
    wraps: tuple[Solution, ...]


def _turns(q: np.ndarray, revolute: np.ndarray) -> int:
    return int(sum(abs(round((v - wrap_to_pi(v)) / (2 * math.pi))) for v in q[revolute]))


def group_wraps(model: RobotModel, solutions: list[Solution], tolerance: float = NUMERIC_DISTINCT) -> list[WrapGroup]:
    """``solutions`` grouped into distinct solutions: members differ only by whole turns of revolute joints.

    Two solutions are one when every prismatic joint agrees and every revolute joint agrees
    modulo 2π, within ``tolerance`` [rad | m]. Groups keep the order of their first member.
    """
    revolute = ~np.asarray(model.is_prismatic, dtype=bool)
    groups: list[tuple[np.ndarray, list[Solution]]] = []
    for solution in solutions:
        for representative, members in groups:
            difference = np.abs(solution.q - representative)
            turned = np.mod(difference[revolute], 2 * math.pi)
            difference[revolute] = np.minimum(turned, 2 * math.pi - turned)
            if float(np.max(difference, initial=0.0)) <= tolerance:
                members.append(solution)
                break
        else:
            groups.append((solution.q, [solution]))
    result = []
    for _, members in groups:
        members.sort(key=lambda s: (_turns(s.q, revolute), s.branch))
        result.append(WrapGroup(members[0], tuple(members[1:])))
    return result


@dataclass(frozen=True)
class AllSolutions:
    """Outcome of :func:`all_ik_solutions`.

    Attributes:
        solver: ``closed_form:<structure>`` or ``numeric``.
        solutions: the solutions within the limits, each verified; sorted by branch.
        task: the task solved (see :mod:`manip_kin.core.pose_rows`).
        reason: empty when solutions were found, else why none.
        attempts: numeric starts tried (0 for the closed form).
        elapsed: wall time [s].
    """

    solver: str
    solutions: list[Solution]
    task: str
    reason: str = ""
    attempts: int = 0
    elapsed: float = 0.0


def require_closed_form(model: RobotModel, frame: str | int | None, task: str | Task | None) -> None:
    """Raise :class:`InvalidArgumentError` unless the arm, frame and task have a closed form."""
    frame_index = model.frame_index(model.default_frame if frame is None else frame)
    task_spec = parse_task(task, model)
    if solver_for_task(model, frame_index, task_spec) is None:
        raise InvalidArgumentError(
            f"{model.name} has no closed form for frame '{model.frame_name(frame_index)}' and task "
            f"'{task_spec.name}' (closed forms: RPP position, SCARA position + yaw, 6R ortho-parallel arm with a "
            "spherical wrist, for a frame on the last link); valid: solver auto or numeric"
        )


def _check_target(target) -> np.ndarray:
    pose = np.asarray(target, dtype=float)
    if pose.shape != (4, 4):
        raise InvalidArgumentError(f"target has shape {pose.shape}; valid: a 4x4 homogeneous transform")
    if not np.all(np.isfinite(pose)):
        raise NonFiniteError("target")
    check_rotation(pose[:3, :3], "target rotation")
    return pose


def all_ik_solutions(
    model: RobotModel,
    target: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    frame: str | int | None = None,
    task: str | Task | None = None,
    solver: str = "auto",
    tolerance_position: float = 1e-6,
    tolerance_orientation: float = 1e-6,
    restarts: int = 100,
    time_budget: float = 0.5,
    seed: int | None = None,
) -> AllSolutions:
    """Every solution putting ``frame`` at ``target`` within the joint limits.

    Args:
        model: the robot.
        target: target pose of the frame in base, shape (4, 4).
        q0: first start of the numeric search, and the value of joints a singular target
            leaves free in the closed form, shape (n,) (default: the start configuration).
        frame: ``tool``, ``ee``, a joint frame or link name (default: tool if any, else ee).
        task: components to achieve (default: what the arm can do, :func:`~manip_kin.core.pose_rows.default_task`).
        solver: ``auto`` (closed form when there is one), ``closed_form`` (an error without
            one) or ``numeric``.
        tolerance_position, tolerance_orientation: a solution's largest errors [m], [rad].
        restarts, time_budget, seed: the numeric search's random starts, wall-time limit [s]
            and seed.
    """
    started = time.perf_counter()
    if solver not in SOLVERS:
        raise InvalidArgumentError(f"solver {solver!r}; valid: {', '.join(SOLVERS)}")
    pose = _check_target(target)
    frame_index = model.frame_index(model.default_frame if frame is None else frame)
    task_spec = parse_task(task, model)
    start = model.start_configuration() if q0 is None else model.check_q(q0, "q0")
    tolerances = {"tolerance_position": tolerance_position, "tolerance_orientation": tolerance_orientation}
    if solver == "closed_form":
        require_closed_form(model, frame_index, task_spec)
    found = None
    if solver != "numeric":
        found = closed_form_solutions(model, pose, frame_index, task_spec, start, **tolerances)
    if found is not None:
        solutions = list(found.solutions)
        for candidate in found.unverified:
            refined = solve_ik(
                model, pose, candidate.q, frame=frame_index, task=task_spec, restarts=0, closed_form=False, **tolerances
            )
            if refined.success:
                solutions.append(
                    Solution(
                        refined.q, candidate.branch + " refined", refined.position_error, refined.orientation_error
                    )
                )
        solutions = sorted(distinct(solutions), key=lambda s: s.branch)
        reason = ""
        if not solutions:
            reason = (
                "unreachable: the closed form has no solution for this target"
                if found.branches == 0
                else f"limits: none of the {found.branches} closed-form branches is within the joint limits"
            )
        return AllSolutions(found.solver, solutions, task_spec.name, reason, 0, time.perf_counter() - started)
    return _numeric_solutions(
        model, pose, start, frame_index, task_spec, tolerances, restarts, time_budget, seed, started
    )


def _numeric_solutions(
    model, pose, start, frame_index, task_spec, tolerances, restarts, time_budget, seed, started
) -> AllSolutions:
    rng = np.random.default_rng(seed)
    deadline = started + time_budget
    solutions: list[Solution] = []
    attempts = 0
    q_start = start
    errors = task_error_function(model, pose, frame_index, task_spec)
    while attempts <= restarts:
        attempts += 1
        result = solve_ik(
            model,
            pose,
            q_start,
            frame=frame_index,
            task=task_spec,
            restarts=0,
            closed_form=False,
            time_budget=max(deadline - time.perf_counter(), 1e-3),
            **tolerances,
        )
        if result.success:
            for values, suffix in in_limit_variants(model, result.q):
                variant = np.array(values)
                position, orientation = errors(variant)
                candidate = Solution(variant, f"start {attempts - 1}{suffix}", position, orientation)
                if all(float(np.max(np.abs(variant - other.q))) > NUMERIC_DISTINCT for other in solutions):
                    solutions.append(candidate)
        if time.perf_counter() >= deadline:
            break
        q_start = model.random_configuration(rng)
    reason = "" if solutions else f"no start converged ({attempts} attempts in {time.perf_counter() - started:.3g} s)"
    return AllSolutions("numeric", solutions, task_spec.name, reason, attempts, time.perf_counter() - started)
