"""One iteration of the damped least-squares IK as a single generated Python function.

Built from the same pieces as the control step (:mod:`manip_kin.codegen.control_step`): the model's
unrolled chain, the pose error with the rotation vector inlined from
:mod:`manip_kin.core.rotations`, and the unrolled damped solve of :mod:`manip_kin.codegen.unrolled_linalg`.
:mod:`manip_kin.ik.iterative` runs it; its plain-Python path implements the same rules.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from manip_kin.codegen.control_step import _GENERATED_MATH, _chain_and_error_lines
from manip_kin.codegen.kernel_cache import bind, kernel
from manip_kin.codegen.unrolled_linalg import _product, _sum, damped_solve_lines, jacobian_entries


def ik_iteration_source(
    chain: Callable,
    dof: int,
    rows: Sequence[int],
    has_lower: Sequence[bool],
    has_upper: Sequence[bool],
    wraps: Sequence[bool],
) -> str:
    """Source of one damped least-squares IK iteration (see :mod:`manip_kin.ik.iterative`).

    It depends only on the structure: which joints have a finite lower (``has_lower``) and
    upper (``has_upper``) limit and which wrap by whole turns (``wraps``); the limit values are
    globals ``LO{j}``/``HI{j}``, bound by :func:`compile_ik_iteration`.
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
    n, m = dof, len(rows)
    lines, tokens, constants = _chain_and_error_lines(
        "def iterate(q, g, weight, shift, step, tolerance_orientation, tolerance_position):", chain, dof
    )
    clipped = [j for j in range(n) if not wraps[j] and (has_lower[j] or has_upper[j])]
    for i, r in enumerate(rows):
        lines.append(f"    b{i} = E{r}")
    orientation = [i for i, r in enumerate(rows) if r < 3]
    position = [i for i, r in enumerate(rows) if r >= 3]
    lines.append("    O = " + (f"sqrt({' + '.join(f'b{i}*b{i}' for i in orientation)})" if orientation else "0.0"))
    lines.append("    P = " + (f"sqrt({' + '.join(f'b{i}*b{i}' for i in position)})" if position else "0.0"))
    lines.append("    if O < tolerance_orientation and P < tolerance_position:")
    lines.append("        return 1, q, O, P")
    lines.append("    W = O + P")
    lines.append("    if W - W != 0.0:")
    lines.append("        return 2, q, O, P")
    lines.append("    d = weight * (O * O + P * P) + shift")
    # The columns of joints that can be held are locals (even their constant entries), so
    # that they can be zeroed.
    entries = jacobian_entries(n, rows, tokens, constants)
    held_columns: dict[int, list[str]] = {}
    for j in clipped:
        held_columns[j] = []
        for i in range(m):
            value = entries[i, j]
            if value == 0.0:
                continue  # a constant zero stays zero when the column is zeroed
            lines.append(f"    J{i}_{j} = {value if isinstance(value, str) else repr(value)}")
            entries[i, j] = f"J{i}_{j}"
            held_columns[j].append(f"J{i}_{j}")
    for j in clipped:
        if not held_columns[j]:
            continue  # the joint does not move the task at all
        gradient = _sum([_product(entries[i, j], f"b{i}") for i in range(m)])
        column = " = ".join(held_columns[j])
        conditions = []
        if has_lower[j]:
            conditions.append(f"(q{j} <= LO{j} and {gradient} < 0.0)")
        if has_upper[j]:
            conditions.append(f"(q{j} >= HI{j} and {gradient} > 0.0)")
        lines.append(f"    if {' or '.join(conditions)}:")
        lines.append(f"        {column} = 0.0")
    body, qdot = damped_solve_lines(entries, m, n)
    lines += [line.replace("return None", "return 2, q, O, P") for line in body]
    for j in range(n):
        lines.append(f"    N{j} = q{j} + step * ({qdot[j]})")
        if wraps[j]:
            lines.append(f"    if N{j} < LO{j}:")
            lines.append(f"        N{j} += TWO_PI * ceil((LO{j} - N{j}) / TWO_PI)")
            lines.append(f"    elif N{j} > HI{j}:")
            lines.append(f"        N{j} -= TWO_PI * ceil((N{j} - HI{j}) / TWO_PI)")
            continue
        if has_lower[j]:
            lines.append(f"    if N{j} < LO{j}:")
            lines.append(f"        N{j} = LO{j}")
        if has_upper[j]:
            lines.append(f"    if N{j} > HI{j}:")
            lines.append(f"        N{j} = HI{j}")
    lines.append(f"    return 0, [{', '.join(f'N{j}' for j in range(n))}], O, P")
    return "\n".join(lines) + "\n"


_IK_NAMESPACE = {**_GENERATED_MATH, "ceil": math.ceil, "TWO_PI": 2.0 * math.pi}


def compile_ik_iteration(
    chain: Callable,
    dof: int,
    rows: Sequence[int],
    lower: Sequence[float],
    upper: Sequence[float],
    wraps: Sequence[bool],
) -> Callable | None:
    """One IK iteration for these limits (see :func:`ik_iteration_source`); None when the
    chain cannot be fused. The code is built once per structure (:mod:`manip_kin.codegen.kernel_cache`)."""
    if not isinstance(getattr(chain, "source", None), str):
        return None
    rows = tuple(int(r) for r in rows)
    wraps = tuple(bool(w) for w in wraps)
    has_lower = tuple(not math.isinf(v) for v in lower)
    has_upper = tuple(not math.isinf(v) for v in upper)
    try:
        template = kernel(
            "ik iteration",
            (chain.source, dof, rows, has_lower, has_upper, wraps),
            lambda: ik_iteration_source(chain, dof, rows, has_lower, has_upper, wraps),
            "iterate",
            _IK_NAMESPACE,
        )
    except ValueError:
        return None
    values = {f"LO{j}": float(lower[j]) for j in range(dof) if has_lower[j] or wraps[j]}
    values.update({f"HI{j}": float(upper[j]) for j in range(dof) if has_upper[j] or wraps[j]})
    return bind(template, values)
