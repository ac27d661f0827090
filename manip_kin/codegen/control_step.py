"""The control step and the IK iteration, each as a single generated Python function.

:class:`manip_kin.control.resolved_rate.CartesianController` runs every cycle. Away from singularities
and position limits a step is: forward kinematics and Jacobian, the pose error, the
reference twist, ``J Jᵀ``, a Cholesky solve, ``Jᵀ x``, a limit check and the velocity
scaling — about a thousand float operations. Separate functions (and numpy calls) for
each of those cost more in call overhead and tuple packing than in arithmetic, so this
module generates one function doing all of it on local variables, with the model's geometry
and constant Jacobian entries folded in. The controller's values (gains, ε, λ_max, the limits)
are the generated step's globals, bound per controller (:func:`compile_step`): the code
depends only on the structure, is built once per structure (:mod:`manip_kin.codegen.kernel_cache`), and
retuning binds the new values to it without generating anything.

The generated step is the only implementation of the control law. The common case runs
inline; the rare ones are calls from it: near a singularity (the cheap eigenvalue bound does
not clear ε²) to the one damped least-squares solve
(:class:`manip_kin.core.damped_least_squares.DampedSolver`), at a position limit to the
controller's SNS redistribution. Pieces defined elsewhere enter as their own code: the
rotation vector is inlined from :mod:`manip_kin.core.rotations` (:mod:`manip_kin.codegen.source_inline`),
the solve from :mod:`manip_kin.codegen.unrolled_linalg`'s generator. Input it cannot use (a
non-finite value, ``dt <= 0``) makes it return None; the controller then says what is wrong.

:mod:`manip_kin.codegen.ik_step` builds one iteration of the damped least-squares IK
(:mod:`manip_kin.ik.iterative`) from the same pieces.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence

import numpy as np

from manip_kin.codegen.kernel_cache import bind, kernel
from manip_kin.codegen.source_inline import inline_lines
from manip_kin.codegen.unrolled_linalg import (
    _cholesky_body,
    _cholesky_solve_lines,
    _determinant_and_traces,
    _inverse_trace_lines,
    _product,
    _sum,
    bound_group_sizes,
    chain_constants,
    damped_solve_lines,
    jacobian_entries,
    smallest_eigenvalue_bound,
)
from manip_kin.core.damped_least_squares import damping_sq, symmetric_eigenvalues
from manip_kin.core.rotations import rotvec_from_quaternion, shepperd_quaternion

# Functions the generated sources call by these names.
_GENERATED_MATH = {"sqrt": math.sqrt, "atan2": math.atan2, "cos": math.cos, "sin": math.sin}

# Locals of the generated step: upper-case names and the solver's (a, b, d, l, p, r, x, y
# with digits). The chain's own locals (q0.., c0.., s0.., v0.. today) must not be among
# them: checked on generation.
_STEP_NAMES = re.compile(
    r"^([A-Z]\w*|a\d+_\d+|b\d+|d|l\d+_\d+|w\d+_\d+|p\d+|r\d+|x\d+|y\d+|inverse_trace|weight|shift|step|g|q|f|dt|_)$"
)
_ASSIGNMENT = re.compile(r"^\s*([A-Za-z_][\w\s,]*?)\s*=(?!=)")


def _split_chain_source(source: str) -> tuple[list[str], list[str]]:
    """Body lines and returned expressions of a generated chain ``def chain(q): … return (…,)``."""
    lines = source.rstrip("\n").split("\n")
    if not lines[0].startswith("def ") or not lines[-1].strip().startswith("return ("):
        raise ValueError("unexpected chain source layout")
    returned = lines[-1].strip()[len("return (") :].rstrip(")").rstrip(",")
    tokens = [token.strip() for token in returned.split(",")]
    return lines[1:-1], tokens


def _literal(token: str) -> float | None:
    try:
        return float(token)
    except ValueError:
        return None


def _assigned_names(lines: Sequence[str]) -> set[str]:
    """Names assigned by simple statements ``a = …`` / ``a, b = …`` (``;``-separated too)."""
    names = set()
    for line in lines:
        for statement in line.split(";"):
            match = _ASSIGNMENT.match(statement)
            if match:
                names.update(name.strip() for name in match.group(1).split(",") if name.strip())
    return names


def _chain_and_error_lines(header: str, chain: Callable, dof: int) -> tuple[list[str], list[str], dict[int, float]]:
    """The function header, ``Q0..`` unpacked, the chain body and the pose error ``E0..E5``.

    Returns the lines, the chain's output expressions and its constant outputs.
    """
    chain_lines, tokens = _split_chain_source(chain.source)
    clashes = sorted(name for name in _assigned_names(chain_lines) if _STEP_NAMES.match(name))
    if clashes:
        raise ValueError(f"generated chain uses names the step needs: {clashes}")
    constants = chain_constants(chain, dof)
    # Output entries the chain writes as literals are constants too.
    for index, token in enumerate(tokens):
        value = _literal(token)
        if value is not None:
            constants.setdefault(index, value)
    pose = [constants[k] if k in constants else tokens[k] for k in range(12)]
    # The chain's first line unpacks q into q0..q{n-1}: the step reads the joints from there.
    unpack = chain_lines[0].strip().rstrip(",").replace(" ", "")
    if (
        unpack != ",".join(f"q{j}" for j in range(dof)) + "=q"
        and unpack != ",".join(f"q{j}" for j in range(dof)) + ",=q"
    ):
        raise ValueError("unexpected chain source layout")
    lines = [header]
    lines += chain_lines
    lines.append("    (G0, G1, G2, GX), (G3, G4, G5, GY), (G6, G7, G8, GZ) = g[0], g[1], g[2]")
    # E = R_goal · Rᵀ: entry (i, j) = goal row i · current row j.
    goal = [["G0", "G1", "G2"], ["G3", "G4", "G5"], ["G6", "G7", "G8"]]
    current = [[pose[0], pose[1], pose[2]], [pose[4], pose[5], pose[6]], [pose[8], pose[9], pose[10]]]
    for i in range(3):
        for j in range(3):
            lines.append(f"    M{i}{j} = " + _sum([_product(goal[i][k], current[j][k]) for k in range(3)]))
    # The rotation vector of M: rotations.rotvec_from_entries, inlined from its own source.
    entries = [f"M{i}{j}" for i in range(3) for j in range(3)]
    lines += inline_lines(shepperd_quaternion, entries, ["QX", "QY", "QZ", "QW"], "SQ_")
    lines += inline_lines(rotvec_from_quaternion, ["QX", "QY", "QZ", "QW"], ["E0", "E1", "E2"], "RV_")
    for axis, (goal_name, index) in enumerate((("GX", 3), ("GY", 7), ("GZ", 11))):
        lines.append(f"    E{3 + axis} = " + _sum([goal_name, _product(-1.0, pose[index])]))
    return lines, tokens, constants


def step_source(
    chain: Callable,
    dof: int,
    rows: Sequence[int],
    position_limited: Sequence[int] = (),
    speed_limited: Sequence[int] = (),
) -> str:
    """Source of ``step(q, g, f, dt)``: the control law of :mod:`manip_kin.control.resolved_rate`, every case.

    The source depends only on the structure: the chain, the task ``rows``, the joints whose
    position limits are checked (``position_limited``: those with a finite limit, none when the
    limits are off) and those whose speed is bounded (``speed_limited``). The values are
    globals of the step, bound per controller by :func:`compile_step`: ``GAIN_ANGULAR``,
    ``GAIN_LINEAR``, ``EPSILON_SQ`` (ε²), ``DAMPING_MAX_SQ`` (λ_max²), ``ABSURD`` and
    ``NEGATIVE_ABSURD``, per limited joint j ``LO{j}``/``HI{j}`` (position limits) and
    ``SP{j}``/``NSP{j}``/``IV{j}`` (± the speed limit and its inverse), and ``OUTPUT``,
    ``SOLVE``, ``REDISTRIBUTE``. So retuning binds new values to the same code.

    The step takes ``q`` (n floats), the goal pose rows ``g`` (at least 3 rows of 4 floats),
    the feed-forward twist ``f`` (6 floats ``[ω; v]``) and ``dt`` [s], and returns an
    ``OUTPUT`` (:class:`manip_kin.control.resolved_rate.ControlOutput`), or None for input it cannot use (a
    non-finite value, ``dt <= 0``, a joint value or the sum of the goal position's absolute
    coordinates not within ``±ABSURD``; it may also raise on a wrong ``q`` length).

    The common case runs inline: the undamped solve, certified by the eigenvalue bounds of
    ``J Jᵀ`` (σ_min² >= ``EPSILON_SQ``). When the certificate fails the step calls
    ``SOLVE(values, b)`` (:meth:`manip_kin.core.damped_least_squares.DampedSolver.solve`: exact
    σ_min and the damping rule); when a joint would cross a position limit it calls
    ``REDISTRIBUTE(q, values, b, qdot, dt, damping, singular)`` (the SNS step of
    :class:`manip_kin.control.resolved_rate.CartesianController`).
    """
    n, m = dof, len(rows)
    lines, tokens, constants = _chain_and_error_lines("def step(q, g, f, dt):", chain, dof)
    lines.insert(1, "    if not 0.0 < dt < INFINITY:")
    lines.insert(2, "        return None")
    # Finite but absurd joint values or goal position (1e300) would overflow the arithmetic
    # into NaN rates: refused here (one comparison per value), explained by the caller.
    inside = " and ".join(f"NEGATIVE_ABSURD < q{j} < ABSURD" for j in range(n))
    lines.append(f"    if not ({inside} and abs(GX) + abs(GY) + abs(GZ) < ABSURD):")
    lines.append("        return None")
    lines.append("    F0, F1, F2, F3, F4, F5 = f")
    for i, r in enumerate(rows):
        lines.append(f"    b{i} = {'GAIN_ANGULAR' if r < 3 else 'GAIN_LINEAR'}*E{r} + F{r}")
    # A NaN or an infinity anywhere in the task makes x - x non-zero (NaN).
    check = " + ".join(f"b{i}" for i in range(m))
    lines.append(f"    W = {check}")
    lines.append("    if W - W != 0.0:")
    lines.append("        return None")
    # The chain's output as a tuple, for the rare branches that hand it over.
    values = "(" + ", ".join(repr(constants[k]) if k in constants else tokens[k] for k in range(len(tokens))) + ",)"
    rhs = "[" + ", ".join(f"b{i}" for i in range(m)) + "]"
    qdot_names = ", ".join(f"QD{j}" for j in range(n)) + ","
    entries = jacobian_entries(n, rows, tokens, constants)
    # The undamped solve waits until the certificate has passed: a step near a singularity
    # solves the shifted system instead.
    body, qdot = damped_solve_lines(entries, m, n, shifted=False, solve=False)
    # One pass of a loop: `continue` (a pivot that is not positive, a failed certificate) falls
    # to the `else` branch, the damped solve; `break` skips it.
    lines.append("    for _ in ONCE:")
    lines += ["    " + line.replace("return None", "continue") for line in body]
    lines.append(f"        DET, TA, TL = {_determinant_and_traces(rows, shifted=False)}")
    # σ_min² >= ε² is certified by the scaled AM-GM bound from det and the angular and linear
    # traces (unrolled_linalg.smallest_eigenvalue_bound, inlined), else by 1/tr((JJᵀ)⁻¹)
    # (within a factor m of λ_min, a few more flops).
    lines.append("        MANIPULABILITY = sqrt(DET)")
    angular, linear = bound_group_sizes(rows)
    arguments = ["DET", "TA", str(angular), "TL", str(linear)]
    lines += inline_lines(smallest_eigenvalue_bound, arguments, ["BOUND"], "EB_", "        ")
    if m > 1:
        # λ_min <= every Cholesky pivot (a pivot is a Schur complement, and eigenvalues
        # interlace): a pivot below ε² proves a singularity without the inverse trace.
        pivots = " or ".join(f"p{j} < EPSILON_SQ" for j in range(m))
        lines.append("        if not BOUND >= EPSILON_SQ:")
        lines.append(f"            UNCERTIFIED = {pivots}")
        lines.append("            if not UNCERTIFIED:")
        lines += ["            " + line for line in _inverse_trace_lines(m)]
        lines.append("                UNCERTIFIED = inverse_trace * EPSILON_SQ > 1.0")
        lines.append("            if UNCERTIFIED:")
    else:
        lines += ["        if not BOUND >= EPSILON_SQ:", "            if True:"]
    # Possibly near a singularity: σ_min² from the eigenvalues of J Jᵀ (the a's above), the
    # damping from the one rule (damped_least_squares.damping_sq, inlined), a shifted solve.
    gram = ", ".join(f"a{max(i, k)}_{min(i, k)}" for i in range(m) for k in range(m))
    deep = "                "
    lines.append(f"{deep}EIG = EIGENVALUES(({gram},), {m})")
    lines.append(f"{deep}SIGMA_SQ = EIG[0] if EIG[0] > 0.0 else 0.0")
    lines += inline_lines(damping_sq, ["SIGMA_SQ", "EPSILON_SQ", "DAMPING_MAX_SQ"], ["d"], "DS_", deep)
    lines.append(f"{deep}if d > 0.0:")
    lines += [deep + line.replace("return None", "continue") for line in _cholesky_body(m, shifted=True)]
    for j in range(n):
        lines.append(f"{deep}    QD{j} = {qdot[j]}")
    lines.append(f"{deep}    LAMBDA = sqrt(d); SINGULAR = True")
    lines.append(f"{deep}    break")
    # No damping configured (λ_max = 0) below ε: the least-squares fallback of the solver.
    lines.append(f"{deep}if SIGMA_SQ < EPSILON_SQ:")
    lines.append(f"{deep}    continue")
    lines += ["    " + line for line in _cholesky_solve_lines(m)]
    for j in range(n):
        lines.append(f"        QD{j} = {qdot[j]}")
    lines.append("        LAMBDA = 0.0; SINGULAR = False")
    lines.append("        break")
    lines.append("    else:")
    lines.append(f"        QDOT, LAMBDA, SINGULAR, MANIPULABILITY = SOLVE({values}, {rhs})")
    lines.append(f"        {qdot_names} = QDOT")
    lines.append("    LIMITED = ()")
    if position_limited:
        inside = " and ".join(f"LO{j} <= q{j} + QD{j} * dt <= HI{j}" for j in position_limited)
        lines.append(f"    if not ({inside}):")
        lines.append(
            f"        QDOT, LIMITED, LAMBDA, SINGULAR = REDISTRIBUTE(q, {values}, {rhs}, "
            f"[{', '.join(f'QD{j}' for j in range(n))}], dt, LAMBDA, SINGULAR)"
        )
        lines.append(f"        {qdot_names} = QDOT")
    lines.append("    S = 1.0")
    if speed_limited:
        # Comparisons only in the common case; the scale is computed when some rate exceeds.
        exceeds = " or ".join(f"QD{j} > SP{j} or QD{j} < NSP{j}" for j in speed_limited)
        worst = ", ".join(f"abs(QD{j})*IV{j}" for j in speed_limited)
        lines.append(f"    if {exceeds}:")
        lines.append(f"        S = 1.0 / max({worst}{', 0.0' if len(speed_limited) == 1 else ''})")
        lines.append(f"        {qdot_names} = {', '.join(f'QD{j} * S' for j in range(n))},")
    # The ControlOutput is filled through __dict__ (it is a frozen dataclass; its __init__
    # would set each field through object.__setattr__, several times slower).
    lines.append("    OUT = NEW(OUTPUT)")
    # Three arrays of their own: no dearer than views into one (measured), and a kept q̇
    # does not keep the errors alive.
    lines.append(
        f"    OUT.__dict__.update(qdot=array(({', '.join(f'QD{j}' for j in range(n))},)), "
        "orientation_error=array((E0, E1, E2)), position_error=array((E3, E4, E5)), "
        "manipulability=MANIPULABILITY, damping=LAMBDA, velocity_scale=S, limited_joints=LIMITED, "
        "singular=SINGULAR)"
    )
    lines.append("    return OUT")
    return "\n".join(lines) + "\n"


# What the generated steps call, by these names.
_STEP_NAMESPACE = {
    **_GENERATED_MATH,
    "array": np.array,
    "NEW": object.__new__,
    "INFINITY": math.inf,
    "ONCE": (None,),
    "EIGENVALUES": symmetric_eigenvalues,
}


def compile_step(
    chain: Callable,
    dof: int,
    rows: Sequence[int],
    output_class: type,
    solve: Callable,
    redistribute: Callable,
    *,
    gain_angular: float,
    gain_linear: float,
    epsilon_sq: float,
    damping_max_sq: float,
    lower: Sequence[float] | None,
    upper: Sequence[float] | None,
    inverse_velocity_limits: Sequence[float] | None,
    absurd: float,
) -> Callable:
    """A control step ``step(q, g, f, dt)`` (see :func:`step_source`) with these values.

    The code is built once per structure (:mod:`manip_kin.codegen.kernel_cache`); the values only
    bind a new function to it, so calling this with other gains compiles nothing.

    Args:
        chain: the generated chain with its ``source``.
        dof: number of joints n.
        rows: task rows.
        output_class: :class:`manip_kin.control.resolved_rate.ControlOutput`.
        solve: ``SOLVE`` of :func:`step_source`.
        redistribute: ``REDISTRIBUTE`` of :func:`step_source`.
        gain_angular: K_o [1/s].
        gain_linear: K_p [1/s].
        epsilon_sq: ε², the squared singular threshold.
        damping_max_sq: λ_max².
        lower: lower position limits (n values), None with ``upper`` to skip the position limits.
        upper: upper position limits (n values).
        inverse_velocity_limits: 1 / the speed limit per joint (0: none), None to skip the
            velocity scaling.
        absurd: joint values and goal coordinates beyond ± this are refused.
    """
    rows = tuple(int(r) for r in rows)
    position_limited: tuple[int, ...] = ()
    if lower is not None and upper is not None:
        position_limited = tuple(j for j in range(dof) if not (math.isinf(lower[j]) and math.isinf(upper[j])))
    speed_limited: tuple[int, ...] = ()
    if inverse_velocity_limits is not None:
        speed_limited = tuple(j for j in range(dof) if inverse_velocity_limits[j] > 0.0)
    template = kernel(
        "control step",
        (chain.source, dof, rows, position_limited, speed_limited),
        lambda: step_source(chain, dof, rows, position_limited, speed_limited),
        "step",
        _STEP_NAMESPACE,
    )
    # The values as the step's globals: read as fast as literals (a closure's cells are not).
    values: dict[str, object] = {
        "OUTPUT": output_class,
        "SOLVE": solve,
        "REDISTRIBUTE": redistribute,
        "GAIN_ANGULAR": float(gain_angular),
        "GAIN_LINEAR": float(gain_linear),
        "EPSILON_SQ": float(epsilon_sq),
        "DAMPING_MAX_SQ": float(damping_max_sq),
        "ABSURD": float(absurd),
        "NEGATIVE_ABSURD": -float(absurd),
    }
    for j in position_limited:
        values[f"LO{j}"], values[f"HI{j}"] = float(lower[j]), float(upper[j])
    for j in speed_limited:
        inverse = float(inverse_velocity_limits[j])
        values[f"IV{j}"], values[f"SP{j}"], values[f"NSP{j}"] = inverse, 1.0 / inverse, -1.0 / inverse
    return bind(template, values)
