"""What :func:`manip_kin.ik.iterative.solve_ik` returns: the result type, and why a failed solve failed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manip_kin.ik.iteration import Attempt
from manip_kin.ik.problem import IKProblem


@dataclass(frozen=True)
class IKResult:
    """Outcome of :func:`solve_ik`.

    Attributes:
        q: the best joint values found (within limits), shape (n,).
        success: both task errors below their tolerances.
        iterations: iterations over all attempts.
        position_error: norm of the task's position error at ``q`` [m].
        orientation_error: norm of the task's orientation error at ``q`` [rad].
        reason: ``converged``, or why not, starting with ``unreachable:``, ``limits:``,
            ``budget:``, ``stalled:`` or ``iterations:``.
        attempts: how many starts were tried (1 + restarts used).
        task: name of the task solved (see :mod:`manip_kin.core.pose_rows`).
        elapsed: wall time spent solving [s] (without the one-time code generation for a new
            robot, frame and task).
        solver: ``numeric``, ``closed_form:<structure>`` (see :mod:`manip_kin.ik.closed_form`), or
            ``closed_form:<structure>+numeric`` when a closed-form start needed refinement.
    """

    q: np.ndarray
    success: bool
    iterations: int
    position_error: float
    orientation_error: float
    reason: str
    attempts: int = 1
    task: str = "full"
    elapsed: float = 0.0
    solver: str = "numeric"


def failure_reason(
    problem: IKProblem, goal: list, best: Attempt, attempts: list[Attempt], out_of_budget: bool, time_budget: float
) -> str:
    """The ``reason`` of a failed solve: unreachable, limits, budget, stalled or iterations (checked in that order)."""
    model = problem.model
    errors = f"best position error {best.position:.3g} m, orientation error {best.orientation:.3g} rad"
    tries = f"{len(attempts)} attempt{'s' if len(attempts) != 1 else ''}"
    if problem.position_rows:
        target = np.array([goal[0][3], goal[1][3], goal[2][3]])
        distance = float(np.linalg.norm(target - problem.first_joint))
        if distance > problem.reach * (1 + 1e-9):
            return (
                f"unreachable: the target is {distance:.3g} m from the first joint, the arm reaches at most "
                f"{problem.reach:.3g} m ({errors}, {tries})"
            )
    held = [
        model.joints[j].name for j in problem.clipped if best.q[j] <= problem.lower[j] or best.q[j] >= problem.upper[j]
    ]
    if out_of_budget:
        return f"budget: the time budget of {time_budget:g} s ran out after {tries} ({errors})"
    if held and best.stalled:
        return f"limits: the best attempt stopped with {', '.join(held)} at a limit ({errors}, {tries})"
    if all(attempt.stalled for attempt in attempts):
        return f"stalled: every attempt ended in a local minimum of the error; the target may be out of reach ({errors}, {tries})"
    return f"iterations: no attempt converged within its iteration cap ({errors}, {tries})"
