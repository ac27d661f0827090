"""Unrolled small linear algebra for the control and IK hot paths.

A damped least-squares step ``q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ b`` with J of shape (m, n), m <= 6,
costs a handful of numpy calls (copy J in, ``J Jᵀ``, ``linalg.solve``, ``Jᵀ x``) at about a
microsecond of overhead each for a few hundred flops. Generated once as straight-line
float arithmetic reading J directly from the tuple the unrolled kinematics
(:func:`manip_kin.core.kinematics.compiled_kinematics`) return (J's constant entries folded in,
unless columns are to be zeroed by the caller), it costs less and yields for free what the damping rule needs: ``det(JJᵀ)``
(the manipulability) and, with the traces of its angular and linear rows, a lower bound of the smallest eigenvalue
(:func:`smallest_eigenvalue_bound`) that spares the eigen-decomposition away from
singularities.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from manip_kin.codegen.kernel_cache import kernel


def _cholesky_body(m: int, shifted: bool = True) -> list[str]:
    """Lines factoring ``a + d I`` (locals ``a{i}_{k}``, k <= i; without the shift ``d`` when
    not ``shifted``) and solving for ``b{i}`` into ``x{i}``; the pivots (squared diagonal
    of L) are ``p{j}``."""
    return _cholesky_factor_lines(m, shifted) + _cholesky_solve_lines(m)


def _cholesky_factor_lines(m: int, shifted: bool = True) -> list[str]:
    """The factoring part of :func:`_cholesky_body`: ``l{i}_{k}``, ``p{j}`` and ``r{j} = 1/sqrt(p{j})``."""
    lines = []
    shift = " + d" if shifted else ""
    for j in range(m):
        lines.append(f"    p{j} = a{j}_{j}{shift}" + "".join(f" - l{j}_{k}*l{j}_{k}" for k in range(j)))
        # `not p > 0` is also true for NaN: a non-finite input never reaches sqrt.
        lines.append(f"    if not p{j} > 0.0:")
        lines.append("        return None")
        lines.append(f"    r{j} = 1.0 / sqrt(p{j})")
        for i in range(j + 1, m):
            lines.append(f"    l{i}_{j} = (a{i}_{j}" + "".join(f" - l{i}_{k}*l{j}_{k}" for k in range(j)) + f") * r{j}")
    return lines


def _cholesky_solve_lines(m: int) -> list[str]:
    """The solving part of :func:`_cholesky_body`: ``L y = b``, then ``Lᵀ x = y`` (the diagonal of L is 1 / r)."""
    lines = []
    for i in range(m):
        lines.append(f"    y{i} = (b{i}" + "".join(f" - l{i}_{k}*y{k}" for k in range(i)) + f") * r{i}")
    for i in reversed(range(m)):
        lines.append(f"    x{i} = (y{i}" + "".join(f" - l{k}_{i}*x{k}" for k in range(i + 1, m)) + f") * r{i}")
    return lines


def _inverse_trace_lines(m: int) -> list[str]:
    """Lines computing ``inverse_trace = tr((A + dI)⁻¹) = |L⁻¹|_F²`` after :func:`_cholesky_body`
    (column j of L⁻¹ by forward substitution of e_j)."""
    lines = []
    for j in range(m):
        lines.append(f"    w{j}_{j} = r{j}")
        for i in range(j + 1, m):
            lines.append(f"    w{i}_{j} = -(" + " + ".join(f"l{i}_{k}*w{k}_{j}" for k in range(j, i)) + f") * r{i}")
    lines.append("    inverse_trace = " + " + ".join(f"w{i}_{j}*w{i}_{j}" for j in range(m) for i in range(j, m)))
    return lines


def _determinant_and_traces(rows: Sequence[int], shifted: bool = True) -> str:
    """``det, trace of the angular rows, trace of the linear rows`` of ``J Jᵀ + dI`` after
    :func:`_cholesky_factor_lines` (an empty group's trace is ``0.0``)."""
    m = len(rows)
    shift = " + d" if shifted else ""
    angular = [f"a{i}_{i}{shift}" for i in range(m) if rows[i] < 3]
    linear = [f"a{i}_{i}{shift}" for i in range(m) if rows[i] >= 3]
    return "*".join(f"p{j}" for j in range(m)) + f", {' + '.join(angular) or '0.0'}, {' + '.join(linear) or '0.0'}"


def bound_group_sizes(rows: Sequence[int]) -> tuple[int, int]:
    """The group sizes :func:`smallest_eigenvalue_bound` takes for ``J Jᵀ`` of task ``rows``
    (components 0-5 = rx, ry, rz, x, y, z): ``(angular rows, linear rows)``."""
    angular = sum(1 for r in rows if r < 3)
    return angular, len(rows) - angular


def smallest_eigenvalue_bound(determinant: float, trace_a: float, size_a: int, trace_b: float, size_b: int) -> float:
    """A lower bound of the smallest eigenvalue of a symmetric positive semi-definite matrix A.

    A's diagonal splits into two groups of ``size_a`` (m_a) and ``size_b`` (m_b) entries whose
    sums are ``trace_a`` (t_a) and ``trace_b`` (t_b); for ``J Jᵀ``: the angular and the linear
    task rows. m = m_a + m_b.

    With eigenvalues λ₁ <= … <= λ_m: ``λ₁ = det / (λ₂ ⋯ λ_m)`` and, by the AM–GM inequality,
    ``λ₂ ⋯ λ_m <= (tr / (m - 1))^(m-1)``, so ``λ₁ >= det · ((m - 1) / tr)^(m-1)``. That is
    nearly tight when the other eigenvalues are similar and loose when they are spread, as
    they are when one group's diagonal is much larger than the other's (the angular rows of
    an arm whose links are under a metre). Scaling first tightens it: for a diagonal D with
    entries <= 1, ``λ₁(A) >= λ₁(D A D)`` (``xᵀAx = yᵀ(DAD)y`` with ``|y| = |D⁻¹x| >= |x|``).
    Shrinking group a by ``u <= 1`` (``D² = u`` there) gives
    ``λ₁ >= det · u^m_a · ((m - 1) / (u·t_a + t_b))^(m-1)``, largest at
    ``u = m_a·t_b / ((m_b - 1)·t_a)``, where it equals
    ``det · m_a^m_a · (m_b - 1)^(m_b - 1) / (t_a^m_a · t_b^(m_b - 1))``. That u is below 1 for
    at most one of the two groups; for neither, the plain bound is the best of these.

    On random Panda configurations the scaled bound certifies half of the regular ones the
    plain bound leaves to ``1/tr(A⁻¹)``. One return expression, so that the generated control
    step inlines this very function (with the sizes as literals the constants fold).
    """
    return (
        determinant * (size_a**size_a * (size_b - 1) ** (size_b - 1)) / (trace_a**size_a * trace_b ** (size_b - 1))
        if 0.0 < size_a * trace_b < (size_b - 1) * trace_a
        else determinant * (size_b**size_b * (size_a - 1) ** (size_a - 1)) / (trace_b**size_b * trace_a ** (size_a - 1))
        if 0.0 < size_b * trace_a < (size_a - 1) * trace_b
        else determinant * ((size_a + size_b - 1) / (trace_a + trace_b)) ** (size_a + size_b - 1)
        if trace_a + trace_b > 0.0
        else 0.0
    )


def chain_constants(chain: Callable, dof: int, samples: int = 3, seed: int = 0) -> dict[int, float]:
    """Entries of a generated chain's output that do not depend on ``q`` (index -> value).

    The chain is evaluated at a few random configurations drawn over [-4, 4] per joint,
    ignoring limits; an entry equal in all of them is a constant the code generator folded
    (a zero or unit Jacobian entry), never a coincidence of random floats.
    """
    import random

    generator = random.Random(seed)
    outputs = [chain([generator.uniform(-4.0, 4.0) for _ in range(dof)]) for _ in range(samples)]
    first = outputs[0]
    return {
        index: float(value)
        for index, value in enumerate(first)
        if all(output[index] == value for output in outputs[1:])
    }


def _product(a: float | str, b: float | str) -> float | str:
    """``a * b`` as a constant or an expression; names may carry a leading minus (folded)."""
    if isinstance(a, float) and isinstance(b, float):
        return a * b
    if isinstance(a, float) or isinstance(b, float):
        constant, name = (a, b) if isinstance(a, float) else (b, a)
        if constant == 0.0:
            return 0.0
        if name.startswith("-"):
            constant, name = -constant, name[1:]
        if constant == 1.0:
            return name
        if constant == -1.0:
            return f"-{name}"
        return f"{constant!r}*{name}"
    negative = a.startswith("-") != b.startswith("-")
    product = f"{a.lstrip('-')}*{b.lstrip('-')}"
    return f"-{product}" if negative else product


#: Terms per bracket in a generated sum: ``a + b + …`` nests one level of the syntax tree per
#: term, and Python's compiler recurses on it (a 3000-joint chain's ``J Jᵀ`` entries hit its
#: recursion limit). Longer sums are bracketed in groups; sums of up to this many terms (every
#: arm's) are left as they are, so their floating-point result does not change.
SUM_GROUP = 64


def _sum(terms: Sequence[float | str]) -> str:
    """``Σ terms`` as an expression: constants added up, negative terms subtracted.

    More than :data:`SUM_GROUP` terms are summed in brackets of that many, so the expression's
    nesting stays shallow however many joints the chain has.
    """
    constant = sum(t for t in terms if isinstance(t, float))
    parts = [t for t in terms if not isinstance(t, float)]
    if constant != 0.0 or not parts:
        parts.append(repr(constant))
    while len(parts) > SUM_GROUP:
        parts = [f"({_joined(parts[i : i + SUM_GROUP])})" for i in range(0, len(parts), SUM_GROUP)]
    return _joined(parts)


def _joined(parts: Sequence[str]) -> str:
    expression = parts[0]
    for part in parts[1:]:
        expression += f" - {part[1:]}" if part.startswith("-") else f" + {part}"
    return expression


def jacobian_entries(
    dof: int, rows: Sequence[int], tokens: Sequence[str] | None, constants: dict[int, float], offset: int = 16
) -> dict[tuple[int, int], float | str]:
    """Task Jacobian entries ``(i, j)`` as constants or expressions over a chain's output.

    Args:
        dof: number of joints n.
        rows: task rows of the 6 x n Jacobian.
        tokens: for generated code that has the chain's output in locals, the expression of
            every output entry (a name, ``-name`` or a literal); None to read them from a
            tuple by unpacking into ``j{i}_{j}`` locals.
        constants: output index -> value for entries that never change (:func:`chain_constants`).
        offset: index of the Jacobian's first entry in the chain's output.
    """
    entries: dict[tuple[int, int], float | str] = {}
    for i, r in enumerate(rows):
        for j in range(dof):
            index = offset + r * dof + j
            if index in constants:
                entries[i, j] = constants[index]
            elif tokens is not None:
                entries[i, j] = tokens[index]
            else:
                entries[i, j] = f"j{i}_{j}"
    return entries


def damped_solve_lines(
    entries: dict[tuple[int, int], float | str], size: int, dof: int, shifted: bool = True, solve: bool = True
) -> tuple[list[str], list[str]]:
    """Lines forming ``A = J Jᵀ`` (locals ``a{i}_{k}``), its Cholesky factorisation with the
    diagonal shift ``d`` and the solve of ``A x = b`` (``b{i}`` locals must exist), plus the
    expressions of ``q̇_j = (Jᵀ x)_j``. The lines ``return None`` on a non-positive pivot.
    Without ``solve`` the lines stop after the factorisation (the caller places
    :func:`_cholesky_solve_lines` where it needs ``x``)."""
    lines = []
    for i in range(size):
        for k in range(i + 1):
            lines.append(f"    a{i}_{k} = " + _sum([_product(entries[i, j], entries[k, j]) for j in range(dof)]))
    lines += _cholesky_body(size, shifted) if solve else _cholesky_factor_lines(size, shifted)
    qdot = [_sum([_product(entries[i, j], f"x{i}") for i in range(size)]) for j in range(dof)]
    return lines, qdot


def _damped_solve_source(
    dof: int, rows: Sequence[int], constants: dict[int, float], offset: int, inverse_trace: bool
) -> str:
    n, m = dof, len(rows)
    entries = jacobian_entries(dof, rows, None, constants, offset)
    unpacked = {offset + r * n + j: f"j{i}_{j}" for i, r in enumerate(rows) for j in range(n)}
    lines = ["def solve(values, b, d):"]
    lines.append("    " + ", ".join(unpacked.get(k, "_") for k in range(offset + 6 * n)) + ", = values")
    lines.append(f"    {', '.join(f'b{i}' for i in range(m))}, = b")
    body, qdot = damped_solve_lines(entries, m, n)
    lines += body
    if inverse_trace:
        lines += _inverse_trace_lines(m)
        lines.append(f"    return [{', '.join(qdot)}], {_determinant_and_traces(rows)}, inverse_trace")
    else:
        lines.append(f"    return [{', '.join(qdot)}], {_determinant_and_traces(rows)}")
    return "\n".join(lines) + "\n"


def damped_solver(
    chain: Callable,
    dof: int,
    rows: Sequence[int],
    offset: int = 16,
    inverse_trace: bool = False,
    fold_constants: bool = True,
) -> Callable:
    """The damped least-squares step ``q̇ = Jᵀ (J Jᵀ + d I)⁻¹ b``, unrolled for one chain.

    ``J`` is read straight from the flat tuple a generated chain returns (the task ``rows``
    of the 6 x n geometric Jacobian starting at ``offset``); its constant entries are folded
    in (see :func:`chain_constants`), ``J Jᵀ`` is formed, Cholesky-factored and solved
    without any numpy call.

    Args:
        chain: the generated chain (:func:`manip_kin.core.kinematics.compiled_kinematics`).
        dof: number of joints n.
        rows: task rows, indices into ``[ωx, ωy, ωz, vx, vy, vz]``.
        offset: index of the Jacobian's first entry in the chain's output.
        inverse_trace: also return ``tr((J Jᵀ + dI)⁻¹)``, whose inverse is a lower bound of
            the smallest eigenvalue within a factor m (tighter than
            :func:`smallest_eigenvalue_bound` when the eigenvalues are spread).
        fold_constants: fold the chain's constant Jacobian entries into the code. Without it
            every entry is read from ``values``, so a caller may zero any column there (a
            joint held at a limit) and use one solver for every subset of held joints.

    Returns:
        ``solve(values, b, d)`` -> ``(qdot, determinant, trace_angular, trace_linear)`` (plus
        ``inverse_trace``) or None, where ``values`` is the chain's output, ``b`` the
        ``len(rows)`` task-space values, ``d`` = λ² >= 0; ``determinant`` is that of
        ``J Jᵀ + dI``, the traces are over its angular and its linear task rows (0.0 for none);
        None when a Cholesky pivot is not positive (``J Jᵀ + dI`` singular to working
        precision, or NaN in the input).
    """
    rows = tuple(int(r) for r in rows)

    def source() -> str:
        constants = chain_constants(chain, dof) if fold_constants else {}
        return _damped_solve_source(dof, rows, constants, offset, inverse_trace)

    # The chain's source is its structure (the folded constants come from it).
    key = (chain.source, dof, rows, offset, inverse_trace, fold_constants)
    return kernel("damped solve", key, source, "solve", {"sqrt": math.sqrt})
