"""Closed-form inverse kinematics: every solution of a pose, no iteration.

Three arm structures have one, each detected from the model's joint axes (never its name):

* :mod:`~manip_kin.closed_form.rpp`: revolute + two prismatic joints (position task), 2 branches;
* :mod:`~manip_kin.closed_form.scara`: three revolute and one prismatic joint along base z
  (position + yaw), 2 branches;
* :mod:`~manip_kin.closed_form.opw`: 6R with an ortho-parallel base and a spherical wrist
  (full pose), up to 8 branches.

:func:`closed_form_solutions` lists the solutions within the joint limits: each revolute joint
is wrapped by whole turns into its limits and every in-limit wrap is listed (the irb120's
joint 6 spans ±400°, so a branch can appear up to three times), and each listed solution is
verified by forward kinematics against the target.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from manip_kin.closed_form.geometry import chain_geometry, wrap_to_pi
from manip_kin.closed_form.opw import detect_opw
from manip_kin.closed_form.rpp import detect_rpp
from manip_kin.closed_form.scara import detect_scara
from manip_kin.control import pose_error
from manip_kin.kinematics import pose_in_base
from manip_kin.model import RobotModel
from manip_kin.tasks import Task

DETECTORS = (detect_rpp, detect_scara, detect_opw)
LIMIT_TOLERANCE = 1e-9  # [rad | m] a value this far outside a limit is put on it
_SOLVERS: dict[tuple[int, int], tuple[RobotModel, object]] = {}


@dataclass(frozen=True)
class Solution:
    """One IK solution.

    Attributes:
        q: joint values within the limits, shape (n,) [rad | m].
        branch: which branch of the closed form (e.g. ``shoulder=front elbow=up wrist=+``),
            with `` jointK+2pi``-style suffixes for whole turns added to fit the limits.
        position_error: task position error norm at ``q`` [m].
        orientation_error: task orientation error norm at ``q`` [rad].
    """

    q: np.ndarray
    branch: str
    position_error: float
    orientation_error: float


@dataclass(frozen=True)
class ClosedFormResult:
    """What :func:`closed_form_solutions` found.

    Attributes:
        solver: ``closed_form:rpp``, ``closed_form:scara`` or ``closed_form:opw``.
        solutions: verified solutions within the limits, sorted by branch.
        unverified: in-limit candidates whose FK misses the target beyond the tolerances
            (a model only nearly of the structure, or a target the task cannot fully reach).
        branches: how many branches the closed form produced before the limits.
    """

    solver: str
    solutions: list[Solution]
    unverified: list[Solution]
    branches: int


def closed_form_solver(model: RobotModel, frame_index: int):
    """The closed-form solver of ``model`` for a frame on its last link, or None (cached per model)."""
    key = (id(model), frame_index)
    cached = _SOLVERS.get(key)
    if cached is not None and cached[0] is model:
        return cached[1]
    solver = None
    geometry = chain_geometry(model, frame_index)
    if geometry is not None:
        for detect in DETECTORS:
            solver = detect(geometry)
            if solver is not None:
                break
    _SOLVERS[key] = (model, solver)  # the model is kept so its id is not reused
    return solver


def solver_for_task(model: RobotModel, frame_index: int, task: Task):
    """The closed-form solver when it determines every component ``task`` asks for, else None.

    A SCARA's ``position`` task leaves the yaw free (infinitely many solutions): no closed form.
    """
    solver = closed_form_solver(model, frame_index)
    if solver is None or not set(solver.required_rows) <= set(task.rows):
        return None
    return solver


def in_limit_variants(model: RobotModel, q: np.ndarray) -> list[tuple[np.ndarray, str]]:
    """Every copy of ``q`` within the limits: revolute joints shifted by whole turns.

    Returns ``(q, suffix)`` pairs; ``suffix`` names the turns added relative to the angle in
    (-π, π], e.g. `` joint6+2pi``. A joint without finite limits is wrapped into (-π, π].
    Empty when a prismatic joint (or a revolute joint whose range misses every turn) is out.
    """
    options: list[list[tuple[float, str]]] = []
    for j, joint in enumerate(model.joints):
        value, lower, upper = float(q[j]), float(model.lower[j]), float(model.upper[j])
        choices = []
        if joint.is_revolute:
            base = wrap_to_pi(value)
            if not (math.isfinite(lower) and math.isfinite(upper)):
                choices.append((base, ""))
            else:
                first = math.ceil((lower - LIMIT_TOLERANCE - base) / (2.0 * math.pi))
                last = math.floor((upper + LIMIT_TOLERANCE - base) / (2.0 * math.pi))
                for turns in range(first, last + 1):
                    shifted = min(upper, max(lower, base + 2.0 * math.pi * turns))
                    suffix = f" {joint.name}{turns * 2:+d}pi" if turns else ""
                    choices.append((shifted, suffix))
        elif lower - LIMIT_TOLERANCE <= value <= upper + LIMIT_TOLERANCE:
            choices.append((min(upper, max(lower, value)), ""))
        if not choices:
            return []
        options.append(choices)
    return [
        (np.array([value for value, _ in combination]), "".join(suffix for _, suffix in combination))
        for combination in itertools.product(*options)
    ]


def task_errors(model: RobotModel, q: np.ndarray, target: np.ndarray, frame_index: int, task: Task):
    """``(position, orientation)`` task error norms of ``q`` against ``target`` [m], [rad]."""
    orientation, position = pose_error(pose_in_base(model, q, frame_index), target)
    orientation_norm, position_norm = task.error_norms(orientation, position)
    return position_norm, orientation_norm


def distinct(solutions: list[Solution], tolerance: float = 1e-7) -> list[Solution]:
    """``solutions`` without repeats (joint values equal within ``tolerance``), first kept."""
    kept: list[Solution] = []
    for solution in solutions:
        if all(float(np.max(np.abs(solution.q - other.q))) > tolerance for other in kept):
            kept.append(solution)
    return kept


def closed_form_solutions(
    model: RobotModel,
    target: np.ndarray,
    frame_index: int,
    task: Task,
    hint: np.ndarray | None = None,
    tolerance_position: float = 1e-6,
    tolerance_orientation: float = 1e-6,
) -> ClosedFormResult | None:
    """Every closed-form solution within the limits putting the frame at ``target``.

    Args:
        model: the robot.
        target: the frame's target pose in base, shape (4, 4).
        frame_index: the controlled frame (see :meth:`RobotModel.frame_index`).
        task: the components to achieve; the closed form is used when it determines them all.
        hint: joint values for joints a singular target leaves free, shape (n,) (default 0).
        tolerance_position, tolerance_orientation: verification thresholds [m], [rad].

    Returns:
        None when the model, frame and task have no closed form; else a :class:`ClosedFormResult`.
    """
    solver = solver_for_task(model, frame_index, task)
    if solver is None:
        return None
    target = np.asarray(target, dtype=float)
    hint = np.zeros(model.dof) if hint is None else np.asarray(hint, dtype=float)
    raw = solver.solve(target, hint)
    verified, unverified = [], []
    for q, branch in raw:
        for variant, suffix in in_limit_variants(model, q):
            position, orientation = task_errors(model, variant, target, frame_index, task)
            solution = Solution(variant, branch + suffix, position, orientation)
            ok = position <= tolerance_position and orientation <= tolerance_orientation
            (verified if ok else unverified).append(solution)
    return ClosedFormResult(
        solver=f"closed_form:{solver.structure}",
        solutions=sorted(distinct(verified), key=lambda s: s.branch),
        unverified=distinct(unverified),
        branches=len(distinct([Solution(q, b, 0.0, 0.0) for q, b in raw], 1e-9)),
    )
