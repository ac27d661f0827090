"""The QP solve: daqp, a dense active-set solver, on ``min ½ xᵀHx + fᵀx, lower <= x <= upper, A x <= b``.

Why daqp: on this problem (7 joint rates, 7 bounds, a handful of damper rows) it takes 6 to
9 µs median per solve, where proxsuite's dense solver, updated in place, takes 65 to 75 µs
(300 random problems of this shape, ``make bench`` section ``collision``, docs/collision.md).
An active-set method suits a problem this small, and it is exact at the solution (no
tolerance-bounded interior iterate), which the "QP equals today's law" test relies on.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import daqp
import numpy as np

_NO_LOWER = -1e30  # daqp's "no bound"


class SolveStatus(StrEnum):
    """How a cycle's rates were found."""

    UNCONSTRAINED = "unconstrained"  # the tasks' rates satisfied every limit: no solve needed
    OPTIMAL = "optimal"
    INFEASIBLE = "infeasible"
    FAILED = "failed"


@dataclass(frozen=True)
class Solution:
    """The solver's answer: ``x`` (None unless optimal) and the status."""

    x: np.ndarray | None
    status: SolveStatus


def solve_qp(
    hessian: np.ndarray,
    linear: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    matrix: np.ndarray | None = None,
    bound: np.ndarray | None = None,
) -> Solution:
    """Solve ``min ½ xᵀ H x + fᵀ x`` s.t. ``lower <= x <= upper`` and ``matrix x <= bound``.

    Args:
        hessian: H, positive definite, shape (n, n).
        linear: f, shape (n,).
        lower, upper: simple bounds, shape (n,) (±inf allowed).
        matrix: A, shape (k, n), or None.
        bound: b, shape (k,), or None.
    """
    n = len(linear)
    rows = np.zeros((0, n)) if matrix is None else np.ascontiguousarray(matrix, dtype=float)
    upper_all = np.concatenate([np.minimum(upper, 1e30), [] if bound is None else bound])
    lower_all = np.concatenate([np.maximum(lower, _NO_LOWER), np.full(len(rows), _NO_LOWER)])
    try:
        x, _, flag, _ = daqp.solve(
            np.ascontiguousarray(hessian, dtype=float),
            np.ascontiguousarray(linear, dtype=float),
            rows,
            upper_all,
            lower_all,
        )
    except (ValueError, RuntimeError, TypeError):
        return Solution(None, SolveStatus.FAILED)
    if flag in (1, 2):  # optimal, soft optimal
        x = np.asarray(x, dtype=float)
        if np.isfinite(x).all():
            return Solution(x, SolveStatus.OPTIMAL)
        return Solution(None, SolveStatus.FAILED)
    if flag == -1:
        return Solution(None, SolveStatus.INFEASIBLE)
    return Solution(None, SolveStatus.FAILED)
