"""Iterative inverse kinematics: joint values that put a frame at a target pose.

An attempt stops when the task errors are below the tolerances, when the error stops
decreasing (a local minimum, typically against a limit), or at ``max_iterations``. Further
attempts start from random configurations (seedable) until one succeeds, ``restarts`` are
used up or ``time_budget`` is spent. The result says why it failed.

The pieces: :mod:`manip_kin.ik.iteration` (the methods ``lm``, ``nr``, ``dls``, joint limits,
one attempt), :mod:`manip_kin.ik.problem` (what is built once per model, frame and task),
:mod:`manip_kin.ik.result` (:class:`IKResult` and the failure reasons). This module drives them:
argument checks, the closed-form shortcut, restarts and the time budget.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import Task, parse_task
from manip_kin.core.rotations import check_rotation
from manip_kin.errors import InvalidArgumentError, NonFiniteError
from manip_kin.ik.closed_form import nearest_closed_form, solver_for_task
from manip_kin.ik.iteration import DEFAULT_DAMPING, IK_METHODS, STALL_RATIO, STALL_WINDOW, Attempt, run_attempt
from manip_kin.ik.problem import problem_for
from manip_kin.ik.result import IKResult, failure_reason

# Names other modules, tests and benches import from here.
__all__ = ["DEFAULT_DAMPING", "IK_METHODS", "IKResult", "solve_ik"]

# The first attempt of lm (from the caller's guess) when restarts may follow gets less
# patience: its error must halve every 2 iterations. From a guess near the solution LM
# converges much faster than that; from a far one, a seeded restart is cheaper than
# persisting (Panda: ~10 % fewer iterations + attempts, genova7 ~5 %).
FIRST_STALL_WINDOW = 2
FIRST_STALL_RATIO = 0.5
# Restarts first start from the SEEDED_RESTARTS entries of the seed table nearest the
# target (:mod:`manip_kin.ik.seeds`), then from uniformly random configurations.
SEEDED_RESTARTS = 8


def _is_rotation_rows(rows: list) -> bool:
    """Orthonormal with det +1 within 1e-6, in plain floats (cheaper than numpy for 3x3)."""
    (a, b, c, _), (d, e, f, _), (g, h, i, _) = rows[0], rows[1], rows[2]
    products = (
        a * a + b * b + c * c - 1.0,
        d * d + e * e + f * f - 1.0,
        g * g + h * h + i * i - 1.0,
        a * d + b * e + c * f,
        a * g + b * h + c * i,
        d * g + e * h + f * i,
        a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) - 1.0,
    )
    return max(abs(p) for p in products) < 1e-6


def _check_positive(value, name: str) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InvalidArgumentError(f"{name} = {value!r}; valid: a finite number > 0")
    return float(value)


def solve_ik(
    model: RobotModel,
    target_pose: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    method: str = "lm",
    frame: str | int | None = None,
    task: str | Sequence | Task | None = None,
    mask: Sequence | None = None,
    tolerance_position: float = 1e-6,
    tolerance_orientation: float = 1e-6,
    max_iterations: int = 60,
    step: float = 1.0,
    damping: float | None = None,
    restarts: int = 100,
    time_budget: float = 0.5,
    seed: int | None = None,
    rng: np.random.Generator | None = None,
    closed_form: bool = True,
) -> IKResult:
    """Joint values putting ``frame`` at ``target_pose``, within the joint limits.

    Args:
        model: the robot.
        target_pose: target pose of the frame in base, shape (4, 4).
        q0: first initial guess, shape (n,) (default: the model's start configuration); moved
            into the limits.
        method: ``lm``, ``nr`` or ``dls`` (module docstring).
        frame: ``tool``, ``ee``, a joint frame number or link name (default: tool if any, else ee).
        task: the error components to solve for (:mod:`manip_kin.core.pose_rows`); default: all six
            for arms with six or more joints, else what the arm can achieve
            (:func:`manip_kin.core.pose_rows.default_task`).
        mask: alternative to ``task``: six 0/1 values over ``[rx, ry, rz, x, y, z]``.
        tolerance_position: success threshold on the position error [m].
        tolerance_orientation: success threshold on the orientation error [rad].
        max_iterations: iteration cap of one attempt.
        step: step size α in (0, 1]: ``q ← q + α Δq``.
        damping: ``lm``: λ̄ [m² | rad²] (default 1e-9); ``dls``: λ (default 0.01); ``nr``: the
            smallest singular value below which the step is damped (default 1e-3).
        restarts: how many random restarts may follow a failed first attempt.
        time_budget: wall-time limit over all attempts [s]; the first attempt always runs.
        seed: seed of the random restarts (ignored when ``rng`` is given).
        rng: random generator for the restarts.
        closed_form: use the closed form when the arm, frame and task have one
            (:mod:`manip_kin.ik.closed_form`): the solution nearest to ``q0``, refined by the
            iteration only when it misses the tolerances. Falls back to the iteration when the
            closed form has no solution within the limits (for its failure reason).

    Returns:
        An :class:`IKResult`; ``success`` False with a ``reason`` when no attempt converged.
    """
    if method not in IK_METHODS:
        raise InvalidArgumentError(f"IK method {method!r}; valid: {', '.join(IK_METHODS)}")
    goal = _target_rows(target_pose)
    if task is not None and mask is not None:
        raise InvalidArgumentError("give either task or mask, not both")
    task_spec = parse_task(mask if mask is not None else task, model)
    frame_index = model.frame_index(model.default_frame if frame is None else frame)
    tolerances = (
        _check_positive(tolerance_orientation, "tolerance_orientation"),
        _check_positive(tolerance_position, "tolerance_position"),
    )
    if not (isinstance(max_iterations, (int, np.integer)) and max_iterations >= 1):
        raise InvalidArgumentError(f"max_iterations = {max_iterations!r}; valid: an integer >= 1")
    if not (isinstance(step, (int, float)) and 0.0 < step <= 1.0):
        raise InvalidArgumentError(f"step = {step!r}; valid: a step size in (0, 1]")
    damping = DEFAULT_DAMPING[method] if damping is None else damping
    if not (isinstance(damping, (int, float)) and math.isfinite(damping) and damping >= 0.0):
        raise InvalidArgumentError(f"damping = {damping!r}; valid: a finite number >= 0")
    if method == "nr" and damping <= 0.0:
        raise InvalidArgumentError(f"damping = {damping!r}; valid for nr: the σ_min threshold, > 0")
    if not (isinstance(restarts, (int, np.integer)) and restarts >= 0):
        raise InvalidArgumentError(f"restarts = {restarts!r}; valid: an integer >= 0")
    time_budget = _check_positive(time_budget, "time_budget")
    problem = problem_for(model, frame_index, task_spec)
    if restarts > 0 and not (closed_form and solver_for_task(model, frame_index, task_spec) is not None):
        problem.seeds.configurations  # noqa: B018 - builds the table once, outside the budget
    # The clock starts after the one-time work for a new (model, frame, task): generating its
    # code and the seed table is not solving (a loaded machine would spend the budget on it).
    # Where the closed form answers, the table is only built if a restart ever needs it.
    started = time.perf_counter()
    start = model.start_configuration() if q0 is None else model.check_q(q0, "q0")
    generator = rng
    deadline = started + time_budget

    attempts: list[Attempt] = []
    total_iterations = 0
    q_start = problem.project(start.tolist())
    solver = "numeric"
    if closed_form:
        found = nearest_closed_form(model, np.asarray(goal), frame_index, task_spec, start, *tolerances[::-1])
        if found is not None and found[1] is not None:
            name, nearest, verified = found
            if verified:
                return IKResult(
                    q=nearest.q,
                    success=True,
                    iterations=0,
                    position_error=nearest.position_error,
                    orientation_error=nearest.orientation_error,
                    reason="converged",
                    task=task_spec.name,
                    elapsed=time.perf_counter() - started,
                    solver=name,
                )
            q_start, solver = nearest.q.tolist(), name + "+numeric"
    out_of_budget = False
    seed_distances: np.ndarray | None = None
    stall = (FIRST_STALL_WINDOW, FIRST_STALL_RATIO) if method == "lm" and restarts > 0 else (STALL_WINDOW, STALL_RATIO)
    while True:
        attempt = run_attempt(problem, goal, q_start, method, step, damping, max_iterations, tolerances, stall)
        stall = (STALL_WINDOW, STALL_RATIO)
        attempts.append(attempt)
        total_iterations += attempt.iterations
        if attempt.success or len(attempts) > restarts:
            break
        if time.perf_counter() >= deadline:
            out_of_budget = True
            break
        if len(attempts) <= SEEDED_RESTARTS:
            if seed_distances is None:
                seed_distances = problem.seeds.distances(goal)
            q_start = problem.seeds.pop_nearest(seed_distances)
            continue
        if generator is None:
            generator = np.random.default_rng(seed)
        q_start = problem.random_start(generator)
    best = min(attempts, key=lambda a: (not a.success, a.error))
    reason = "converged" if best.success else failure_reason(problem, goal, best, attempts, out_of_budget, time_budget)
    return IKResult(
        q=np.array(best.q),
        success=best.success,
        iterations=total_iterations,
        position_error=best.position,
        orientation_error=best.orientation,
        reason=reason,
        attempts=len(attempts),
        task=task_spec.name,
        elapsed=time.perf_counter() - started,
        solver=solver,
    )


def _target_rows(target_pose) -> list:
    target = np.asarray(target_pose, dtype=float)
    if target.shape != (4, 4):
        raise InvalidArgumentError(f"target_pose has shape {target.shape}; valid: a 4x4 homogeneous transform")
    rows = target.tolist()
    if not math.isfinite(sum(sum(row) for row in rows)):
        raise NonFiniteError("target_pose")
    if not _is_rotation_rows(rows):
        check_rotation(target[:3, :3], "target_pose rotation")  # raises with the details
    return rows
