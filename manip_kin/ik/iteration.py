"""One IK attempt: iterations of ``J Δq ≈ e`` from a start until converged, stalled or out of iterations.

The error driven to zero is the controller's (:func:`manip_kin.control.resolved_rate.pose_error`): the
rotation vector of ``frame_R_target`` expressed in base and the position difference in
base, restricted to the task components (:mod:`manip_kin.core.pose_rows`: ``full`` for arms with six
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
decreasing (a local minimum, typically against a limit), or at ``max_iterations``.

For speed, one iteration of ``lm``/``dls`` is a single generated function
(:func:`manip_kin.codegen.ik_step.ik_iteration_source`); ``nr`` and the rare cases it hands back
(singular systems) run the plain Python path below, which implements the same rules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from manip_kin.core.pose_jacobian import zero_joint_column
from manip_kin.errors import NonFiniteError
from manip_kin.ik.problem import IKProblem

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
# the seeded restarts of :func:`manip_kin.ik.iterative.solve_ik` are cheaper than finishing a poor attempt.)
STALL_WINDOW = 4
STALL_RATIO = 0.6
_CONVERGED, _STEPPED, _GENERAL = 1, 0, 2


@dataclass
class Attempt:
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


def run_attempt(
    problem: IKProblem,
    goal: list,
    q: list,
    method: str,
    step: float,
    damping: float,
    max_iterations: int,
    tolerances: tuple[float, float],
    stall: tuple[int, float],
) -> Attempt:
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
            status, q_next, orientation, position = general_iteration(
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
    return Attempt(best_q, best_orientation, best_position, iterations, success, stalled)


def general_iteration(
    problem: IKProblem, goal: list, q: list, method: str, step: float, damping: float, tolerances: tuple[float, float]
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
            zero_joint_column(values, n, j)
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


def _newton_step(problem: IKProblem, values, error: list, threshold: float):
    """``J⁺ e``, damped only when σ_min < ``threshold``: Chiaverini's rule with λ_max = threshold,
    i.e. ``λ² = threshold² - σ_min²``."""
    threshold_sq = threshold * threshold
    return problem.solver.solve(values, error, threshold_sq, threshold_sq)
