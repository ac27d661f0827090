"""Iterative inverse kinematics: joint values that put a frame at a target pose.

The error driven to zero is the controller's (:func:`manip_kin.control.pose_error`): the
rotation vector of ``frame_R_target`` expressed in base and the position difference in
base, restricted to the task components (:mod:`manip_kin.tasks`: ``full`` for arms with six
or more joints, ``position`` for the 3-DoF rpp, ``position_yaw`` for a SCARA, or any subset
given as ``task=`` or ``mask=``). Each iteration solves ``J Δq ≈ e`` over the task rows of
the geometric Jacobian:

* ``lm`` (default): Levenberg–Marquardt with Sugihara's error-dependent damping
  ``λ² = w·|e|² + λ̄`` (w = 0.02): Gauss–Newton near the solution, shorter steps far from it,
  finite at singularities. Fast and robust from random starts.
* ``nr``: Newton–Raphson, ``Δq = J⁺ e`` (minimum norm for redundant arms), damped only when
  the smallest singular value of J falls below ``damping`` (then ``λ² = damping² - σ_min²``),
  so it steps out of singular starts such as a stretched arm.
* ``dls``: damped least squares with a fixed λ = ``damping``.

``q ← q + step·Δq``. Joint limits: a joint at a limit whose gradient ``(Jᵀe)ⱼ`` points
outside is held (its column removed) so the other joints take the task; a joint stepping
past a limit stops on it, or is wrapped by whole turns when its range spans a full turn.
Every iterate, and so the result, is within limits.

An attempt stops when the task errors are below the tolerances, when the error stops
decreasing (a local minimum, typically against a limit), or at ``max_iterations``. Further
attempts start from random configurations (seedable) until one succeeds, ``restarts`` are
used up or ``time_budget`` is spent. The result says why it failed.

For speed, one iteration of ``lm``/``dls`` is a single generated function
(:func:`manip_kin.ik_codegen.ik_iteration_source`); ``nr`` and the rare cases it hands back
(singular systems) run the plain Python path below, which implements the same rules.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from manip_kin.closed_form import nearest_closed_form, solver_for_task
from manip_kin.control import _pose_error_values
from manip_kin.damped_least_squares import DampedSolver
from manip_kin.errors import InvalidArgumentError, NonFiniteError
from manip_kin.ik_codegen import compile_ik_iteration
from manip_kin.ik_seeds import SeedTable
from manip_kin.kinematics import compiled_kinematics
from manip_kin.model import RobotModel
from manip_kin.rotations import check_rotation
from manip_kin.tasks import Task, parse_task

IK_METHODS = ("lm", "nr", "dls")
# Default damping per method: λ̄ [m² | rad²] added to w·|e|² for lm (kept tiny: near a
# singular target, e.g. an irb120 wrist at q5 ≈ 0, a λ̄ of 1e-6 already slows the last
# iterations enough to stall); λ for dls; the smallest singular value below which nr damps.
DEFAULT_DAMPING = {"lm": 1e-9, "nr": 1e-3, "dls": 0.01}
# Weight w of |e|² in the lm damping. Sugihara's E = ½|e|² (w = 0.5) takes ~20% more
# iterations from random starts on the 7-DoF arms than this, measured on genova7 and Panda.
LM_ERROR_WEIGHT = 0.02
# An attempt is abandoned when the error has not dropped below STALL_RATIO times its value
# STALL_WINDOW iterations earlier: converging attempts shrink it much faster. (Cut early:
# the seeded restarts below are cheaper than finishing a poor attempt.)
STALL_WINDOW = 4
STALL_RATIO = 0.6
# The first attempt of lm (from the caller's guess) when restarts may follow gets less
# patience: its error must halve every 2 iterations. From a guess near the solution LM
# converges much faster than that; from a far one, a seeded restart is cheaper than
# persisting (Panda: ~10 % fewer iterations + attempts, genova7 ~5 %).
FIRST_STALL_WINDOW = 2
FIRST_STALL_RATIO = 0.5
# Restarts first start from the SEEDED_RESTARTS entries of the seed table nearest the
# target (:mod:`manip_kin.ik_seeds`), then from uniformly random configurations.
SEEDED_RESTARTS = 8
_TWO_PI = 2.0 * math.pi
_CONVERGED, _STEPPED, _GENERAL = 1, 0, 2


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
        task: name of the task solved (see :mod:`manip_kin.tasks`).
        elapsed: wall time spent solving [s] (without the one-time code generation for a new
            robot, frame and task).
        solver: ``numeric``, ``closed_form:<structure>`` (see :mod:`manip_kin.closed_form`), or
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


@dataclass
class _Attempt:
    """The best point of one attempt and how the attempt ended."""

    q: list
    orientation: float
    position: float
    iterations: int = 0
    success: bool = False
    stalled: bool = False

    @property
    def error(self) -> float:
        return math.hypot(self.orientation, self.position)


class _Problem:
    """Everything about (model, frame, task) an IK iteration needs, built once and cached."""

    def __init__(self, model: RobotModel, frame_index: int, task: Task):
        n = model.dof
        self.model = model
        self.n = n
        self.rows = task.rows
        self.orientation_rows = task.orientation_rows
        self.position_rows = task.position_rows
        self.chain = compiled_kinematics(model, frame_index, True)
        # The one damped solve; reads every Jacobian entry from the chain's output, so held
        # columns can be zeroed.
        self.solver = DampedSolver(self.chain, n, task.rows)
        self.solve = self.solver.shifted
        self.lower, self.upper = model.lower.tolist(), model.upper.tolist()
        # Revolute joints spanning a full turn are wrapped (q and q ± 2π are the same pose);
        # the others are clipped.
        span = [self.upper[j] - self.lower[j] for j in range(n)]
        self.wraps = [
            joint.is_revolute and math.isfinite(span[j]) and span[j] >= _TWO_PI - 1e-12
            for j, joint in enumerate(model.joints)
        ]
        self.clipped = [j for j in range(n) if not self.wraps[j]]
        self.iterate = compile_ik_iteration(self.chain, n, task.rows, self.lower, self.upper, self.wraps)
        # Random restarts: uniform within the limits (finite stand-ins for continuous joints).
        self.sample_low = [
            lo if math.isfinite(lo) else (-1.0 if j.type.value == "prismatic" else -math.pi)
            for lo, j in zip(self.lower, model.joints)
        ]
        sample_high = [
            hi if math.isfinite(hi) else (1.0 if j.type.value == "prismatic" else math.pi)
            for hi, j in zip(self.upper, model.joints)
        ]
        self.sample_span = [high - low for low, high in zip(self.sample_low, sample_high)]
        self.reach = _reach_bound(model, frame_index)
        self.first_joint = model.chain.fixed[0][:3, 3].copy()
        self.seeds = SeedTable(
            model,
            frame_index,
            self.sample_low,
            self.sample_span,
            bool(self.position_rows),
            bool(self.orientation_rows),
            self.reach,
        )

    def random_start(self, generator: np.random.Generator) -> list:
        return [
            low + span * u for low, span, u in zip(self.sample_low, self.sample_span, generator.random(self.n).tolist())
        ]

    def project(self, q: list) -> list:
        """``q`` moved into the limits: wrapped by whole turns or clipped."""
        lower, upper, wraps = self.lower, self.upper, self.wraps
        for j in range(self.n):
            value = q[j]
            if value < lower[j]:
                if wraps[j]:
                    value += _TWO_PI * math.ceil((lower[j] - value) / _TWO_PI)
                q[j] = value if lower[j] <= value <= upper[j] else lower[j]
            elif value > upper[j]:
                if wraps[j]:
                    value -= _TWO_PI * math.ceil((value - upper[j]) / _TWO_PI)
                q[j] = value if lower[j] <= value <= upper[j] else upper[j]
        return q

    def errors(self, values, goal) -> tuple[list, float, float]:
        """Task error vector (m values), orientation and position norms."""
        error = _pose_error_values(values, goal)
        task_error = [error[r] for r in self.rows]
        orientation = math.sqrt(sum(error[r] * error[r] for r in self.orientation_rows))
        position = math.sqrt(sum(error[r] * error[r] for r in self.position_rows))
        return task_error, orientation, position

    def held_joints(self, values, q: list, error: list) -> list[int]:
        """Joints at a limit whose gradient ``(Jᵀe)ⱼ`` points outside the limits."""
        n, rows = self.n, self.rows
        held = []
        for j in self.clipped:
            at_lower, at_upper = q[j] <= self.lower[j], q[j] >= self.upper[j]
            if at_lower or at_upper:
                gradient = sum(values[16 + r * n + j] * error[i] for i, r in enumerate(rows))
                if (at_lower and gradient < 0.0) or (at_upper and gradient > 0.0):
                    held.append(j)
        return held


_PROBLEMS: dict[tuple[int, int, tuple[int, ...]], tuple[RobotModel, _Problem]] = {}


def _problem(model: RobotModel, frame_index: int, task: Task) -> _Problem:
    key = (id(model), frame_index, task.rows)
    cached = _PROBLEMS.get(key)
    if cached is not None and cached[0] is model:
        return cached[1]
    problem = _Problem(model, frame_index, task)
    _PROBLEMS[key] = (model, problem)  # the model is kept so its id is not reused
    return problem


def _reach_bound(model: RobotModel, frame_index: int) -> float:
    """An upper bound of the distance from joint 1's origin to the frame [m].

    The sum of the fixed offsets between successive joint origins, the prismatic travels and
    the end-effector/tool offsets: no configuration puts the frame farther away.
    """
    chain = model.chain
    n = model.dof
    count = min(frame_index, n)
    total = 0.0
    for i in range(count):
        if i > 0:
            total += float(np.linalg.norm(chain.fixed[i][:3, 3]))
        if chain.prismatic_mask[i] > 0.5:
            total += max(abs(float(model.lower[i])), abs(float(model.upper[i])))
    if frame_index > n:
        tail = chain.moving_to_ee if frame_index == n + 1 or model.tool is None else chain.moving_to_ee @ model.tool
        total += float(np.linalg.norm(tail[:3, 3]))
    elif frame_index >= 1:
        total += float(np.linalg.norm(chain.frame_offsets[frame_index - 1][:3, 3]))
    return total


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
        task: the error components to solve for (:mod:`manip_kin.tasks`); default: all six
            for arms with six or more joints, else what the arm can achieve
            (:func:`manip_kin.tasks.default_task`).
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
            (:mod:`manip_kin.closed_form`): the solution nearest to ``q0``, refined by the
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
    problem = _problem(model, frame_index, task_spec)
    if restarts > 0 and not (closed_form and solver_for_task(model, frame_index, task_spec) is not None):
        problem.seeds.configurations  # noqa: B018 - builds the table once, outside the budget
    # The clock starts after the one-time work for a new (model, frame, task): generating its
    # code and the seed table is not solving (a loaded machine would spend the budget on it).
    # Where the closed form answers, the table is only built if a restart ever needs it.
    started = time.perf_counter()
    start = model.start_configuration() if q0 is None else model.check_q(q0, "q0")
    generator = rng
    deadline = started + time_budget

    attempts: list[_Attempt] = []
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
        attempt = _run_attempt(problem, goal, q_start, method, step, damping, max_iterations, tolerances, stall)
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
    reason = "converged" if best.success else _failure_reason(problem, goal, best, attempts, out_of_budget, time_budget)
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


def _run_attempt(
    problem: _Problem,
    goal: list,
    q: list,
    method: str,
    step: float,
    damping: float,
    max_iterations: int,
    tolerances: tuple[float, float],
    stall: tuple[int, float],
) -> _Attempt:
    """Iterate from ``q`` until converged, stalled or out of iterations; the best point found.

    ``stall``: (window, ratio): stalled when the error is above ratio times its value window
    iterations earlier.
    """
    tolerance_orientation, tolerance_position = tolerances
    stall_window, stall_ratio = stall
    fused = problem.iterate if method in ("lm", "dls") else None
    weight, shift = (LM_ERROR_WEIGHT, damping) if method == "lm" else (0.0, damping * damping)
    history: list[float] = []
    # The best point so far as locals (this loop runs every iteration).
    best_q, best_orientation, best_position, best_error = q, math.inf, math.inf, math.inf
    success = stalled = False
    iterations = 0
    while True:
        status = _GENERAL
        if fused is not None:
            status, q_next, orientation, position = fused(
                q, goal, weight, shift, step, tolerance_orientation, tolerance_position
            )
        if status == _GENERAL:
            status, q_next, orientation, position = _general_iteration(
                problem, goal, q, method, step, damping, tolerances
            )
        combined = math.hypot(orientation, position)
        if status == _CONVERGED:
            best_q, best_orientation, best_position, success = q, orientation, position, True
            break
        if combined < best_error:
            best_q, best_orientation, best_position, best_error = q, orientation, position, combined
        history.append(combined)
        if len(history) > stall_window and combined > stall_ratio * history[-1 - stall_window]:
            stalled = True
            break
        if iterations >= max_iterations:
            break
        iterations += 1
        q = q_next
    return _Attempt(best_q, best_orientation, best_position, iterations, success, stalled)


def _general_iteration(
    problem: _Problem, goal: list, q: list, method: str, step: float, damping: float, tolerances: tuple[float, float]
) -> tuple[int, list, float, float]:
    """One iteration in plain Python (``nr``, and what the generated iteration hands back)."""
    values = problem.chain(q)
    error, orientation, position = problem.errors(values, goal)
    if orientation < tolerances[0] and position < tolerances[1]:
        return _CONVERGED, q, orientation, position
    if not math.isfinite(orientation + position):
        raise NonFiniteError("the IK error (target pose, q or the model)")
    held = problem.held_joints(values, q, error)
    if held:
        n = problem.n
        values = list(values)
        for j in held:
            for r in range(6):
                values[16 + r * n + j] = 0.0
    if method == "lm":
        shift = LM_ERROR_WEIGHT * (orientation * orientation + position * position) + damping
        result = problem.solve(values, error, shift)
    elif method == "dls":
        result = problem.solve(values, error, damping * damping)
    else:
        result = None
    if result is None:
        result = _newton_step(problem, values, error, damping if method == "nr" else 1e-6)
    delta = result[0]
    return _STEPPED, problem.project([q[j] + step * delta[j] for j in range(problem.n)]), orientation, position


def _newton_step(problem: _Problem, values, error: list, threshold: float):
    """``J⁺ e``, damped only when σ_min < ``threshold``: Chiaverini's rule with λ_max = threshold,
    i.e. ``λ² = threshold² - σ_min²``."""
    threshold_sq = threshold * threshold
    return problem.solver.solve(values, error, threshold_sq, threshold_sq)


def _failure_reason(
    problem: _Problem, goal: list, best: _Attempt, attempts: list[_Attempt], out_of_budget: bool, time_budget: float
) -> str:
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
