"""Unrolled small linear algebra for the control and IK hot paths: emitters and the damped solve.

A damped least-squares step ``q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ b`` with J of shape (m, n), m <= 6,
costs a handful of numpy calls (copy J in, ``J Jᵀ``, ``linalg.solve``, ``Jᵀ x``) at about a
microsecond of overhead each for a few hundred flops. Generated once as straight-line float
arithmetic reading J directly from the tuple a generated chain returns
(:func:`manip_kin.core.kinematics.compiled_kinematics`), with J's structural constants folded in
(unless columns are to be zeroed by the caller), it costs less and yields for free what the
damping rule needs: ``det(JJᵀ)`` (the manipulability) and, with the traces of its angular and
linear rows, a lower bound of the smallest eigenvalue
(:func:`manip_kin.codegen.inlined.smallest_eigenvalue_bound`) that spares the eigen-decomposition
away from singularities.

The emitters (:func:`gram`, :func:`cholesky_factor`, :func:`cholesky_solve`,
:func:`inverse_trace`, :func:`determinant_and_traces`, :func:`transpose_times`) are shared by
:func:`damped_solver`, the control step and the IK iteration. Each takes its inputs as values
(:mod:`manip_kin.codegen.ir`), allocates its locals from the caller's names and returns a
fragment; one that can fail takes the statement that bails out (``on_fail``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

from manip_kin.codegen.ir import Fragment, Names, Value, indented, product, total
from manip_kin.codegen.kernel_cache import kernel

#: Task Jacobian entries ``(i, j)`` (task row i, joint j) -> value.
Entries = Mapping[tuple[int, int], Value]


class Factor(NamedTuple):
    """A Cholesky factor ``L Lᵀ = A + d I`` as locals: ``lower[i][k]`` (k < i) of L, the pivots
    (the squared diagonal of L) and their ``1 / sqrt``, the reciprocal diagonal of L."""

    lower: tuple[tuple[str, ...], ...]
    pivots: tuple[str, ...]
    reciprocals: tuple[str, ...]


def jacobian_entries(dof: int, rows: Sequence[int], outputs: Sequence[Value], offset: int = 16) -> dict:
    """Task Jacobian entries ``(i, j)`` from a chain's outputs (constants, names or ``-name``).

    Args:
        dof: number of joints n.
        rows: task rows of the 6 x n Jacobian.
        outputs: the chain's output values (:meth:`manip_kin.codegen.chain.ChainSpec.emit`).
        offset: index of the Jacobian's first entry in the outputs.
    """
    return {(i, j): outputs[offset + r * dof + j] for i, r in enumerate(rows) for j in range(dof)}


def gram(names: Names, entries: Entries, size: int, dof: int) -> Fragment[tuple[tuple[str, ...], ...]]:
    """``A = J Jᵀ`` of ``size`` task rows: outputs ``a[i][k]`` for k <= i (the lower triangle)."""
    lines, a = [], []
    for i in range(size):
        row = []
        for k in range(i + 1):
            name = names.fresh(f"a{i}_{k}_")
            lines.append(f"{name} = " + total([product(entries[i, j], entries[k, j]) for j in range(dof)]))
            row.append(name)
        a.append(tuple(row))
    return Fragment(lines, tuple(a))


def cholesky_factor(
    names: Names, a: Sequence[Sequence[str]], shift: str | None, on_fail: str, into: Factor | None = None
) -> Fragment[Factor]:
    """The Cholesky factor of ``a + shift·I`` (``a`` lower triangular, ``shift`` a local or
    None for none); runs ``on_fail`` (a statement leaving the code: ``return None``,
    ``continue``) at a pivot that is not positive.

    With ``into`` the factor is written into the locals of that earlier factor of the same
    size, whose values must not be read afterwards: a long function's locals past the 256th
    cost an extra instruction (``EXTENDED_ARG``) at every access.
    """
    m = len(a)
    plus = f" + {shift}" if shift else ""
    if into is None:
        lower = [[names.fresh(f"l{i}_{j}_") if j < i else "" for j in range(m)] for i in range(m)]
        pivots = [names.fresh(f"p{j}_") for j in range(m)]
        reciprocals = [names.fresh(f"r{j}_") for j in range(m)]
        into = Factor(tuple(map(tuple, lower)), tuple(pivots), tuple(reciprocals))
    lower, lines = into.lower, []
    for j, (p, r) in enumerate(zip(into.pivots, into.reciprocals)):
        lines.append(f"{p} = {a[j][j]}{plus}" + "".join(f" - {lower[j][k]}*{lower[j][k]}" for k in range(j)))
        # `not p > 0` is also true for NaN: a non-finite input never reaches sqrt.
        lines += [f"if not {p} > 0.0:", f"    {on_fail}", f"{r} = 1.0 / sqrt({p})"]
        for i in range(j + 1, m):
            terms = "".join(f" - {lower[i][k]}*{lower[j][k]}" for k in range(j))
            lines.append(f"{lower[i][j]} = ({a[i][j]}{terms}) * {r}")
    return Fragment(lines, into)


def cholesky_solve(
    names: Names, factor: Factor, b: Sequence[str], into: Sequence[str] | None = None
) -> Fragment[tuple[str, ...]]:
    """``x`` with ``L Lᵀ x = b``: ``L y = b``, then ``Lᵀ x = y`` in place (``x_i`` replaces
    ``y_i``, which nothing reads after; the diagonal of L is 1 / r). With ``into``, ``x`` is
    written into those locals (no longer needed) instead of fresh ones."""
    lower, r, m = factor.lower, factor.reciprocals, len(b)
    x = list(into) if into is not None else [names.fresh(f"x{i}_") for i in range(m)]
    lines = []
    for i in range(m):
        lines.append(f"{x[i]} = ({b[i]}" + "".join(f" - {lower[i][k]}*{x[k]}" for k in range(i)) + f") * {r[i]}")
    for i in reversed(range(m)):
        terms = "".join(f" - {lower[k][i]}*{x[k]}" for k in range(i + 1, m))
        lines.append(f"{x[i]} = ({x[i]}{terms}) * {r[i]}")
    return Fragment(lines, tuple(x))


def inverse_trace(names: Names, factor: Factor) -> Fragment[str]:
    """``tr((A + dI)⁻¹) = |L⁻¹|_F²`` (column j of L⁻¹ by forward substitution of e_j)."""
    lower, r, m = factor.lower, factor.reciprocals, len(factor.pivots)
    w = [[""] * m for _ in range(m)]
    lines = []
    for j in range(m):
        w[j][j] = names.fresh(f"w{j}_{j}_")
        lines.append(f"{w[j][j]} = {r[j]}")
        for i in range(j + 1, m):
            w[i][j] = names.fresh(f"w{i}_{j}_")
            lines.append(
                f"{w[i][j]} = -(" + " + ".join(f"{lower[i][k]}*{w[k][j]}" for k in range(j, i)) + f") * {r[i]}"
            )
    trace = names.fresh("inverse_trace")
    lines.append(f"{trace} = " + " + ".join(f"{w[i][j]}*{w[i][j]}" for j in range(m) for i in range(j, m)))
    return Fragment(lines, trace)


def determinant_and_traces(a: Sequence[Sequence[str]], factor: Factor, rows: Sequence[int], shift: str | None) -> str:
    """The expression ``det, trace of the angular rows, trace of the linear rows`` of
    ``a + shift·I`` from its factor (an empty group's trace is ``0.0``)."""
    plus = f" + {shift}" if shift else ""
    angular = [f"{a[i][i]}{plus}" for i, row in enumerate(rows) if row < 3]
    linear = [f"{a[i][i]}{plus}" for i, row in enumerate(rows) if row >= 3]
    return "*".join(factor.pivots) + f", {' + '.join(angular) or '0.0'}, {' + '.join(linear) or '0.0'}"


def transpose_times(entries: Entries, x: Sequence[str], dof: int) -> list[str]:
    """The expressions of ``(Jᵀ x)_j``, j = 0..dof-1."""
    return [total([product(entries[i, j], x[i]) for i in range(len(x))]) for j in range(dof)]


def _damped_solve_source(
    dof: int, rows: Sequence[int], constants: Mapping[int, float], offset: int, with_trace: bool
) -> str:
    n, m = dof, len(rows)
    names = Names(["values", "b", "d", "sqrt"])
    # J's entries unpacked from `values`, except the constants (folded in).
    read = {offset + r * n + j: names.fresh(f"j{i}_{j}_") for i, r in enumerate(rows) for j in range(n)}
    outputs = [constants.get(k, read.get(k, "_")) for k in range(offset + 6 * n)]
    entries = jacobian_entries(n, rows, outputs, offset)
    b = [names.fresh("b") for _ in range(m)]
    lines = [", ".join(v if isinstance(v, str) else "_" for v in outputs) + ", = values", f"{', '.join(b)}, = b"]
    a = gram(names, entries, m, n)
    factor = cholesky_factor(names, a.outputs, "d", "return None")
    x = cholesky_solve(names, factor.outputs, b)
    lines += a.lines + factor.lines + x.lines
    returned = f"[{', '.join(transpose_times(entries, x.outputs, n))}], "
    returned += determinant_and_traces(a.outputs, factor.outputs, rows, "d")
    if with_trace:
        trace = inverse_trace(names, factor.outputs)
        lines += trace.lines
        returned += f", {trace.outputs}"
    return "def solve(values, b, d):\n" + "\n".join(indented([*lines, f"return {returned}"])) + "\n"


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
    of the 6 x n geometric Jacobian starting at ``offset``); its structural constants are
    folded in (:meth:`manip_kin.codegen.chain.ChainSpec.constants`), ``J Jᵀ`` is formed,
    Cholesky-factored and solved without any numpy call.

    Args:
        chain: the generated chain (:func:`manip_kin.core.kinematics.compiled_kinematics`),
            carrying its ``spec``.
        dof: number of joints n.
        rows: task rows, indices into ``[ωx, ωy, ωz, vx, vy, vz]``.
        offset: index of the Jacobian's first entry in the chain's output.
        inverse_trace: also return ``tr((J Jᵀ + dI)⁻¹)``, whose inverse is a lower bound of
            the smallest eigenvalue within a factor m (tighter than
            :func:`manip_kin.codegen.inlined.smallest_eigenvalue_bound` when the eigenvalues are spread).
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
    spec = chain.spec if fold_constants else None

    def source() -> str:
        constants = spec.constants() if spec is not None else {}
        return _damped_solve_source(dof, rows, constants, offset, inverse_trace)

    # Unfolded, the code depends on the sizes only.
    key = (spec, dof, rows, offset, inverse_trace)
    return kernel("damped solve", key, source, "solve", {"sqrt": math.sqrt})
