"""Closed-form inverse kinematics: every solution of a pose, no iteration.

Three arm structures have one, each detected from the model's joint axes (never its name):

* :mod:`~manip_kin.ik.closed_form.rpp`: revolute + two prismatic joints (position task), 2 branches;
* :mod:`~manip_kin.ik.closed_form.scara`: three revolute and one prismatic joint along base z
  (position + yaw), 2 branches;
* :mod:`~manip_kin.ik.closed_form.opw`: 6R with an ortho-parallel base and a spherical wrist
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

from manip_kin.control.resolved_rate import _pose_error_values
from manip_kin.core.kinematics import compiled_kinematics
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import Task
from manip_kin.ik.closed_form.geometry import chain_geometry, wrap_to_pi
from manip_kin.ik.closed_form.opw import detect_opw
from manip_kin.ik.closed_form.rpp import detect_rpp
from manip_kin.ik.closed_form.scara import detect_scara

DETECTORS = (detect_rpp, detect_scara, detect_opw)
LIMIT_TOLERANCE = 1e-9  # [rad | m] a value this far outside a limit is put on it


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
    """The closed-form solver of ``model`` for a frame on its last link, or None (kept in ``model.kernels``)."""
    return model.kernels.get(("closed-form solver", frame_index), _detected_solver, model, frame_index)


def _detected_solver(model: RobotModel, frame_index: int):
    geometry = chain_geometry(model, frame_index)
    if geometry is not None:
        for detect in DETECTORS:
            solver = detect(geometry)
            if solver is not None:
                return solver
    return None


def solver_for_task(model: RobotModel, frame_index: int, task: Task):
    """The closed-form solver when it determines every component ``task`` asks for, else None.

    A SCARA's ``position`` task leaves the yaw free (infinitely many solutions): no closed form.
    """
    solver = closed_form_solver(model, frame_index)
    if solver is None or not set(solver.required_rows) <= set(task.rows):
        return None
    return solver


def _joint_choices(model: RobotModel) -> list[tuple[bool, float, float, str]]:
    """Per joint ``(revolute, lower, upper, name)`` as plain floats (cached per model)."""
    return model.kernels.get(("joint choices",), _joint_values, model)


def _joint_values(model: RobotModel) -> list[tuple[bool, float, float, str]]:
    return [(j.is_revolute, float(j.lower), float(j.upper), j.name) for j in model.joints]


def _wraps(revolute: bool, lower: float, upper: float, name: str, value: float) -> list[tuple[float, str]]:
    """The in-limit values of one joint: every whole-turn shift of a revolute one, a prismatic one as is."""
    if not revolute:
        if lower - LIMIT_TOLERANCE <= value <= upper + LIMIT_TOLERANCE:
            return [(min(upper, max(lower, value)), "")]
        return []
    base = wrap_to_pi(value)
    if not (math.isfinite(lower) and math.isfinite(upper)):
        return [(base, "")]
    first = math.ceil((lower - LIMIT_TOLERANCE - base) / (2.0 * math.pi))
    last = math.floor((upper + LIMIT_TOLERANCE - base) / (2.0 * math.pi))
    return [
        (min(upper, max(lower, base + 2.0 * math.pi * turns)), f" {name}{turns * 2:+d}pi" if turns else "")
        for turns in range(first, last + 1)
    ]


def in_limit_variants(model: RobotModel, q) -> list[tuple[list[float], str]]:
    """Every copy of ``q`` within the limits: revolute joints shifted by whole turns.

    Returns ``(q, suffix)`` pairs; ``suffix`` names the turns added relative to the angle in
    (-π, π], e.g. `` joint6+2pi``. A joint without finite limits is wrapped into (-π, π].
    Empty when a prismatic joint (or a revolute joint whose range misses every turn) is out.
    """
    options = []
    for (revolute, lower, upper, name), value in zip(_joint_choices(model), q):
        choices = _wraps(revolute, lower, upper, name, float(value))
        if not choices:
            return []
        options.append(choices)
    return [
        ([value for value, _ in combination], "".join(suffix for _, suffix in combination))
        for combination in itertools.product(*options)
    ]


def _nearest_variant(model: RobotModel, raw: list, reference: list[float]) -> tuple[list[float], int, str] | None:
    """The in-limit copy nearest to ``reference`` over every raw solution, and which one it copies.

    The distance is a sum over joints, so each joint takes its own nearest whole-turn shift.
    Plain floats: a few microseconds per branch.
    """
    joints = _joint_choices(model)
    turn = 2.0 * math.pi
    best, best_distance, best_index = None, math.inf, -1
    for index, (q, _) in enumerate(raw):
        values, distance = [], 0.0
        for (revolute, lower, upper, _name), value, wanted in zip(joints, q, reference):
            if revolute:
                value = wrap_to_pi(value)
                if lower > -math.inf and upper < math.inf:
                    first = math.ceil((lower - LIMIT_TOLERANCE - value) / turn)
                    last = math.floor((upper + LIMIT_TOLERANCE - value) / turn)
                    if first > last:
                        break
                    value = min(upper, max(lower, value + turn * min(last, max(first, round((wanted - value) / turn)))))
            elif not lower - LIMIT_TOLERANCE <= value <= upper + LIMIT_TOLERANCE:
                break
            else:
                value = min(upper, max(lower, value))
            values.append(value)
            distance += (value - wanted) ** 2
        else:
            if distance < best_distance:
                best, best_distance, best_index = values, distance, index
    if best is None:
        return None
    suffix = ""
    for (revolute, _, _, name), value, original in zip(joints, best, raw[best_index][0]):
        turns = round((value - wrap_to_pi(original)) / turn) if revolute else 0
        if turns:
            suffix += f" {name}{turns * 2:+d}pi"
    return best, best_index, suffix


def task_error_function(model: RobotModel, target: np.ndarray, frame_index: int, task: Task):
    """``errors(q) -> (position, orientation)``: task error norms of ``q`` at ``target`` [m], [rad].

    Runs the model's unrolled forward kinematics on plain floats (about 10 µs a call).
    """
    chain = compiled_kinematics(model, frame_index, False)
    goal = np.asarray(target, dtype=float).tolist()
    position_rows, orientation_rows = task.position_rows, task.orientation_rows

    def errors(q) -> tuple[float, float]:
        error = _pose_error_values(chain([float(v) for v in q]), goal)
        position = math.sqrt(sum(error[r] * error[r] for r in position_rows))
        orientation = math.sqrt(sum(error[r] * error[r] for r in orientation_rows))
        return position, orientation

    return errors


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
    errors = task_error_function(model, target, frame_index, task)
    verified, unverified = [], []
    for q, branch in raw:
        for variant, suffix in in_limit_variants(model, q):
            position, orientation = errors(variant)
            solution = Solution(np.array(variant), branch + suffix, position, orientation)
            ok = position <= tolerance_position and orientation <= tolerance_orientation
            (verified if ok else unverified).append(solution)
    return ClosedFormResult(
        solver=f"closed_form:{solver.structure}",
        solutions=sorted(distinct(verified), key=lambda s: s.branch),
        unverified=distinct(unverified),
        branches=len(distinct([Solution(np.asarray(q, dtype=float), b, 0.0, 0.0) for q, b in raw], 1e-9)),
    )


def nearest_closed_form(
    model: RobotModel,
    target: np.ndarray,
    frame_index: int,
    task: Task,
    reference: np.ndarray,
    tolerance_position: float = 1e-6,
    tolerance_orientation: float = 1e-6,
) -> tuple[str, Solution | None, bool] | None:
    """The in-limit closed-form solution nearest to ``reference`` (what :func:`solve_ik` wants).

    Only that one is checked by forward kinematics, so this is cheaper than listing them all.

    Returns:
        None without a closed form; else ``(solver, nearest or None, verified)``: ``nearest``
        is None when no solution is within the limits; ``verified`` False when it misses the
        tolerances (the caller refines it).
    """
    solver = solver_for_task(model, frame_index, task)
    if solver is None:
        return None
    name = f"closed_form:{solver.structure}"
    reference = [float(v) for v in reference]
    raw = solver.solve(target, reference)
    nearest = _nearest_variant(model, raw, reference) if raw else None
    if nearest is None:
        return name, None, False
    values, index, suffix = nearest
    position, orientation = task_error_function(model, target, frame_index, task)(values)
    verified = position <= tolerance_position and orientation <= tolerance_orientation
    return name, Solution(np.array(values), raw[index][1] + suffix, position, orientation), verified
