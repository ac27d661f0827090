"""The control step as a single generated Python function.

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
chain and the pose error from :mod:`manip_kin.codegen.pose_error`, the solve from the emitters of
:mod:`manip_kin.codegen.unrolled_linalg`, the eigenvalue bound and the damping rule inlined from
:mod:`manip_kin.codegen.inlined`. Input it cannot use (a
non-finite value, ``dt <= 0``) makes it return None; the controller then says what is wrong.

:mod:`manip_kin.codegen.ik_step` builds one iteration of the damped least-squares IK
(:mod:`manip_kin.ik.iterative`) from the same pieces.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from manip_kin.codegen.chain import ChainSpec
from manip_kin.codegen.inlined import bound_group_sizes, damping_sq, smallest_eigenvalue_bound
from manip_kin.codegen.ir import Names, indented, render
from manip_kin.codegen.kernel_cache import bind, kernel
from manip_kin.codegen.pose_error import GENERATED_MATH, chain_and_pose_error
from manip_kin.codegen.source_inline import inline_lines
from manip_kin.codegen.unrolled_linalg import (
    cholesky_factor,
    cholesky_solve,
    determinant_and_traces,
    gram,
    inverse_trace,
    jacobian_entries,
    transpose_times,
)

#: The values :func:`compile_step` binds, read by the step as globals.
_VALUES = ("OUTPUT", "SOLVE", "REDISTRIBUTE", "EIGENVALUES", "GAIN_ANGULAR", "GAIN_LINEAR", "EPSILON_SQ")
_VALUES += ("DAMPING_MAX_SQ", "ABSURD", "NEGATIVE_ABSURD")


def _joint_values(position_limited: Sequence[int], speed_limited: Sequence[int]) -> list[str]:
    """The per-joint globals: the position limits ``LO{j}``/``HI{j}``, the speed limits ``SP{j}``/``NSP{j}``/``IV{j}``."""
    return [f"{k}{j}" for j in position_limited for k in ("LO", "HI")] + [
        f"{k}{j}" for j in speed_limited for k in ("SP", "NSP", "IV")
    ]


def step_source(
    spec: ChainSpec,
    rows: Sequence[int],
    position_limited: Sequence[int] = (),
    speed_limited: Sequence[int] = (),
) -> str:
    """Source of ``step(q, g, f, dt)``: the control law of :mod:`manip_kin.control.resolved_rate`, every case.

    The source depends only on the structure: the chain's ``spec``, the task ``rows``, the joints whose
    position limits are checked (``position_limited``: those with a finite limit, none when the
    limits are off) and those whose speed is bounded (``speed_limited``). The values are
    globals of the step, bound per controller by :func:`compile_step`: ``GAIN_ANGULAR``,
    ``GAIN_LINEAR``, ``EPSILON_SQ`` (ε²), ``DAMPING_MAX_SQ`` (λ_max²), ``ABSURD`` and
    ``NEGATIVE_ABSURD``, per limited joint j ``LO{j}``/``HI{j}`` (position limits) and
    ``SP{j}``/``NSP{j}``/``IV{j}`` (± the speed limit and its inverse), and ``OUTPUT``,
    ``SOLVE``, ``REDISTRIBUTE``, ``EIGENVALUES``. So retuning binds new values to the same code.

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
    n, m = spec.dof, len(rows)
    names = Names(["q", "g", "f", "dt", *_STEP_NAMESPACE, *_VALUES, *_joint_values(position_limited, speed_limited)])
    fresh = names.fresh
    head = chain_and_pose_error(names, spec)
    joints, outputs, (gx, gy, gz), error = head.outputs
    lines = ["if not 0.0 < dt < INFINITY:", "    return None", *head.lines]
    # Finite but absurd joint values or goal position (1e300) would overflow the arithmetic
    # into NaN rates: refused here (one comparison per value), explained by the caller.
    inside = " and ".join(f"NEGATIVE_ABSURD < {q} < ABSURD" for q in joints)
    lines += [f"if not ({inside} and abs({gx}) + abs({gy}) + abs({gz}) < ABSURD):", "    return None"]
    feed = [fresh("F") for _ in range(6)]
    lines.append(f"{', '.join(feed)} = f")
    b = [fresh("b") for _ in range(m)]
    for i, r in enumerate(rows):
        lines.append(f"{b[i]} = {'GAIN_ANGULAR' if r < 3 else 'GAIN_LINEAR'}*{error[r]} + {feed[r]}")
    # A NaN or an infinity anywhere in the task makes x - x non-zero (NaN).
    check = fresh("W")
    lines += [f"{check} = {' + '.join(b)}", f"if {check} - {check} != 0.0:", "    return None"]
    # The chain's output as a tuple, for the rare branches that hand it over.
    values = "(" + ", ".join(render(v) for v in outputs) + ",)"
    rhs = "[" + ", ".join(b) + "]"
    qd = [fresh("QD") for _ in range(n)]
    qd_names = ", ".join(qd) + ","
    entries = jacobian_entries(n, rows, outputs)
    # The undamped solve waits until the certificate has passed: a step near a singularity
    # solves the shifted system instead. One pass of a loop: `continue` (a pivot that is not
    # positive, a failed certificate) falls to the `else` branch, the damped solve; `break` skips it.
    a = gram(names, entries, m, n)
    factor = cholesky_factor(names, a.outputs, None, "continue")
    det, trace_a, trace_l, manipulability, bound = (fresh(k) for k in ("DET", "TA", "TL", "MANIPULABILITY", "BOUND"))
    once = [*a.lines, *factor.lines]
    once.append(f"{det}, {trace_a}, {trace_l} = {determinant_and_traces(a.outputs, factor.outputs, rows, None)}")
    # σ_min² >= ε² is certified by the scaled AM-GM bound from det and the angular and linear
    # traces (inlined.smallest_eigenvalue_bound), else by 1/tr((JJᵀ)⁻¹) (within a factor m of
    # λ_min, a few more flops).
    once.append(f"{manipulability} = sqrt({det})")
    angular, linear = bound_group_sizes(rows)
    arguments = [det, trace_a, str(angular), trace_l, str(linear)]
    once += inline_lines(smallest_eigenvalue_bound, arguments, [bound], names, "EB_")
    once.append(f"if not {bound} >= EPSILON_SQ:")
    if m > 1:
        # λ_min <= every Cholesky pivot (a pivot is a Schur complement, and eigenvalues
        # interlace): a pivot below ε² proves a singularity without the inverse trace.
        uncertified = fresh("UNCERTIFIED")
        trace = inverse_trace(names, factor.outputs)
        once.append(f"    {uncertified} = " + " or ".join(f"{p} < EPSILON_SQ" for p in factor.outputs.pivots))
        once += [f"    if not {uncertified}:", *indented(trace.lines, 2)]
        once += [f"        {uncertified} = {trace.outputs} * EPSILON_SQ > 1.0", f"    if {uncertified}:"]
    else:
        once.append("    if True:")
    # Possibly near a singularity: σ_min² from the eigenvalues of J Jᵀ (the a's above), the
    # damping from the one rule (inlined.damping_sq, inlined), a shifted solve.
    eig, sigma_sq, shift, damping, singular = (fresh(k) for k in ("EIG", "SIGMA_SQ", "d", "LAMBDA", "SINGULAR"))
    near = [
        f"{eig} = EIGENVALUES(({', '.join(a.outputs[max(i, k)][min(i, k)] for i in range(m) for k in range(m))},), {m})"
    ]
    near.append(f"{sigma_sq} = {eig}[0] if {eig}[0] > 0.0 else 0.0")
    near += inline_lines(damping_sq, [sigma_sq, "EPSILON_SQ", "DAMPING_MAX_SQ"], [shift], names, "DS_")
    # The shifted system in the unshifted one's locals: that one is not read after this branch.
    unshifted = cholesky_solve(names, factor.outputs, b)
    shifted = cholesky_factor(names, a.outputs, shift, "continue", into=factor.outputs)
    x = cholesky_solve(names, shifted.outputs, b, into=unshifted.outputs)
    near += [f"if {shift} > 0.0:", *indented(shifted.lines + x.lines)]
    near += [f"    {q} = {rate}" for q, rate in zip(qd, transpose_times(entries, x.outputs, n))]
    near += [f"    {damping} = sqrt({shift}); {singular} = True", "    break"]
    # No damping configured (λ_max = 0) below ε: the least-squares fallback of the solver.
    near += [f"if {sigma_sq} < EPSILON_SQ:", "    continue"]
    once += indented(near, 2)
    once += unshifted.lines + [f"{q} = {rate}" for q, rate in zip(qd, transpose_times(entries, unshifted.outputs, n))]
    once += [f"{damping} = 0.0; {singular} = False", "break"]
    qdot, limited, scale, out = fresh("QDOT"), fresh("LIMITED"), fresh("S"), fresh("OUT")
    lines += [f"for {fresh('_')} in ONCE:", *indented(once), "else:"]
    lines.append(f"    {qdot}, {damping}, {singular}, {manipulability} = SOLVE({values}, {rhs})")
    lines += [f"    {qd_names} = {qdot}", f"{limited} = ()"]
    if position_limited:
        inside = " and ".join(f"LO{j} <= {joints[j]} + {qd[j]} * dt <= HI{j}" for j in position_limited)
        lines.append(f"if not ({inside}):")
        lines.append(
            f"    {qdot}, {limited}, {damping}, {singular} = REDISTRIBUTE(q, {values}, {rhs}, "
            f"[{', '.join(qd)}], dt, {damping}, {singular})"
        )
        lines.append(f"    {qd_names} = {qdot}")
    lines.append(f"{scale} = 1.0")
    if speed_limited:
        # Comparisons only in the common case; the scale is computed when some rate exceeds.
        exceeds = " or ".join(f"{qd[j]} > SP{j} or {qd[j]} < NSP{j}" for j in speed_limited)
        worst = ", ".join(f"abs({qd[j]})*IV{j}" for j in speed_limited)
        lines.append(f"if {exceeds}:")
        lines.append(f"    {scale} = 1.0 / max({worst}{', 0.0' if len(speed_limited) == 1 else ''})")
        lines.append(f"    {qd_names} = {', '.join(f'{q} * {scale}' for q in qd)},")
    # The ControlOutput is filled through __dict__ (it is a frozen dataclass; its __init__
    # would set each field through object.__setattr__, several times slower).
    lines.append(f"{out} = NEW(OUTPUT)")
    # Three arrays of their own: no dearer than views into one (measured), and a kept q̇
    # does not keep the errors alive.
    lines.append(
        f"{out}.__dict__.update(qdot=array(({', '.join(qd)},)), "
        f"orientation_error=array(({', '.join(error[:3])})), position_error=array(({', '.join(error[3:])})), "
        f"manipulability={manipulability}, damping={damping}, velocity_scale={scale}, limited_joints={limited}, "
        f"singular={singular})"
    )
    lines.append(f"return {out}")
    return "def step(q, g, f, dt):\n" + "\n".join(indented(lines)) + "\n"


# What the generated steps call, by these names.
_STEP_NAMESPACE = {**GENERATED_MATH, "array": np.array, "NEW": object.__new__, "INFINITY": math.inf, "ONCE": (None,)}


def compile_step(
    chain: Callable,
    dof: int,
    rows: Sequence[int],
    output_class: type,
    solve: Callable,
    redistribute: Callable,
    eigenvalues: Callable,
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
        chain: the generated chain, carrying its ``spec``.
        dof: number of joints n.
        rows: task rows.
        output_class: :class:`manip_kin.control.resolved_rate.ControlOutput`.
        solve: ``SOLVE`` of :func:`step_source`.
        redistribute: ``REDISTRIBUTE`` of :func:`step_source`.
        eigenvalues: ``EIGENVALUES(entries, size)``, the ascending eigenvalues of a symmetric
            matrix given row-major (:func:`manip_kin.core.damped_least_squares.symmetric_eigenvalues`).
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
    spec = chain.spec
    template = kernel(
        "control step",
        (spec, rows, position_limited, speed_limited),
        lambda: step_source(spec, rows, position_limited, speed_limited),
        "step",
        _STEP_NAMESPACE,
    )
    # The values as the step's globals: read as fast as literals (a closure's cells are not).
    values: dict[str, object] = {
        "OUTPUT": output_class,
        "SOLVE": solve,
        "REDISTRIBUTE": redistribute,
        "EIGENVALUES": eigenvalues,
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
