"""One iteration of the damped least-squares IK as a single generated Python function.

Built from the same pieces as the control step (:mod:`manip_kin.codegen.control_step`): the chain
and the pose error (:mod:`manip_kin.codegen.pose_error`) and the damped solve's emitters
(:mod:`manip_kin.codegen.unrolled_linalg`). :mod:`manip_kin.ik.iterative` runs it; its
plain-Python path implements the same rules.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from manip_kin.codegen.chain import ChainSpec
from manip_kin.codegen.ir import Names, indented, product, render, total
from manip_kin.codegen.kernel_cache import bind, kernel
from manip_kin.codegen.pose_error import GENERATED_MATH, chain_and_pose_error
from manip_kin.codegen.unrolled_linalg import cholesky_factor, cholesky_solve, gram, jacobian_entries, transpose_times

_PARAMETERS = ("q", "g", "weight", "shift", "step", "tolerance_orientation", "tolerance_position")


def ik_iteration_source(
    spec: ChainSpec,
    rows: Sequence[int],
    has_lower: Sequence[bool],
    has_upper: Sequence[bool],
    wraps: Sequence[bool],
) -> str:
    """Source of one damped least-squares IK iteration (see :mod:`manip_kin.ik.iterative`).

    It depends only on the structure: the chain's ``spec``, which joints have a finite lower
    (``has_lower``) and upper (``has_upper``) limit and which wrap by whole turns (``wraps``);
    the limit values are globals ``LO{j}``/``HI{j}``, bound by :func:`compile_ik_iteration`.
    ``iterate(q, g, weight, shift, step, tolerance_orientation, tolerance_position)`` with
    ``q`` (n floats) and the target rows ``g`` evaluates the task error ``e`` at ``q`` and
    returns ``(status, q_next, orientation_error, position_error)``:

    * status 1: the errors are below the tolerances (``q_next`` is ``q``);
    * status 2: a non-finite error or a singular system: run the general path instead;
    * status 0: ``q_next = q + step·Δq`` with ``Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e``,
      ``λ² = weight·|e|² + shift``, brought back within the limits.

    A joint at a limit whose gradient ``(Jᵀe)_j`` points outside is held: its column is
    zeroed so the other joints take the task. Other joints stepping past a limit are clipped
    onto it, or wrapped by whole turns when their range spans a full turn (``wraps``).
    """
    n, m = spec.dof, len(rows)
    names = Names([*_PARAMETERS, *_IK_NAMESPACE, *_limit_names(has_lower, has_upper, wraps)])
    head = chain_and_pose_error(names, spec)
    joints, outputs, _, error = head.outputs
    lines = list(head.lines)
    clipped = [j for j in range(n) if not wraps[j] and (has_lower[j] or has_upper[j])]
    b = [names.fresh("b") for _ in range(m)]
    lines += [f"{b[i]} = {error[r]}" for i, r in enumerate(rows)]
    orientation = [b[i] for i, r in enumerate(rows) if r < 3]
    position = [b[i] for i, r in enumerate(rows) if r >= 3]
    o, p, w, d = (names.fresh(k) for k in ("O", "P", "W", "d"))
    lines.append(f"{o} = " + (f"sqrt({' + '.join(f'{v}*{v}' for v in orientation)})" if orientation else "0.0"))
    lines.append(f"{p} = " + (f"sqrt({' + '.join(f'{v}*{v}' for v in position)})" if position else "0.0"))
    fail = f"return 2, q, {o}, {p}"
    lines += [f"if {o} < tolerance_orientation and {p} < tolerance_position:", f"    return 1, q, {o}, {p}"]
    lines += [f"{w} = {o} + {p}", f"if {w} - {w} != 0.0:", f"    {fail}"]
    lines.append(f"{d} = weight * ({o} * {o} + {p} * {p}) + shift")
    # The columns of joints that can be held are locals (even their constant entries), so
    # that they can be zeroed.
    entries = jacobian_entries(n, rows, outputs)
    held_columns: dict[int, list[str]] = {}
    for j in clipped:
        held_columns[j] = []
        for i in range(m):
            value = entries[i, j]
            if value == 0.0:
                continue  # a constant zero stays zero when the column is zeroed
            entries[i, j] = names.fresh(f"J{i}_{j}_")
            lines.append(f"{entries[i, j]} = {render(value)}")
            held_columns[j].append(entries[i, j])
    for j in clipped:
        if not held_columns[j]:
            continue  # the joint does not move the task at all
        gradient = total([product(entries[i, j], b[i]) for i in range(m)])
        conditions = []
        if has_lower[j]:
            conditions.append(f"({joints[j]} <= LO{j} and {gradient} < 0.0)")
        if has_upper[j]:
            conditions.append(f"({joints[j]} >= HI{j} and {gradient} > 0.0)")
        lines += [f"if {' or '.join(conditions)}:", f"    {' = '.join(held_columns[j])} = 0.0"]
    a = gram(names, entries, m, n)
    factor = cholesky_factor(names, a.outputs, d, fail)
    x = cholesky_solve(names, factor.outputs, b)
    lines += a.lines + factor.lines + x.lines
    following = [names.fresh("N") for _ in range(n)]
    for j, (new, rate) in enumerate(zip(following, transpose_times(entries, x.outputs, n))):
        lines.append(f"{new} = {joints[j]} + step * ({rate})")
        if wraps[j]:
            lines += [f"if {new} < LO{j}:", f"    {new} += TWO_PI * ceil((LO{j} - {new}) / TWO_PI)"]
            lines += [f"elif {new} > HI{j}:", f"    {new} -= TWO_PI * ceil(({new} - HI{j}) / TWO_PI)"]
            continue
        if has_lower[j]:
            lines += [f"if {new} < LO{j}:", f"    {new} = LO{j}"]
        if has_upper[j]:
            lines += [f"if {new} > HI{j}:", f"    {new} = HI{j}"]
    lines.append(f"return 0, [{', '.join(following)}], {o}, {p}")
    return f"def iterate({', '.join(_PARAMETERS)}):\n" + "\n".join(indented(lines)) + "\n"


def _limit_names(has_lower: Sequence[bool], has_upper: Sequence[bool], wraps: Sequence[bool]) -> list[str]:
    """The limit globals ``LO{j}``/``HI{j}`` the iteration reads (a wrapping joint's both)."""
    lows = [f"LO{j}" for j in range(len(wraps)) if has_lower[j] or wraps[j]]
    return lows + [f"HI{j}" for j in range(len(wraps)) if has_upper[j] or wraps[j]]


_IK_NAMESPACE = {**GENERATED_MATH, "ceil": math.ceil, "TWO_PI": 2.0 * math.pi}


def compile_ik_iteration(
    chain: Callable,
    dof: int,
    rows: Sequence[int],
    lower: Sequence[float],
    upper: Sequence[float],
    wraps: Sequence[bool],
) -> Callable | None:
    """One IK iteration for these limits (see :func:`ik_iteration_source`); None when the
    chain is not a generated one (no ``spec``). The code is built once per structure
    (:mod:`manip_kin.codegen.kernel_cache`)."""
    spec = getattr(chain, "spec", None)
    if not isinstance(spec, ChainSpec):
        return None
    rows = tuple(int(r) for r in rows)
    wraps = tuple(bool(w) for w in wraps)
    has_lower = tuple(not math.isinf(v) for v in lower)
    has_upper = tuple(not math.isinf(v) for v in upper)
    template = kernel(
        "ik iteration",
        (spec, rows, has_lower, has_upper, wraps),
        lambda: ik_iteration_source(spec, rows, has_lower, has_upper, wraps),
        "iterate",
        _IK_NAMESPACE,
    )
    values = {f"LO{j}": float(lower[j]) for j in range(dof) if has_lower[j] or wraps[j]}
    values.update({f"HI{j}": float(upper[j]) for j in range(dof) if has_upper[j] or wraps[j]})
    return bind(template, values)
