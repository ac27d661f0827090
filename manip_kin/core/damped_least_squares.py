"""The damped least-squares solve and its damping rule: the one implementation.

``q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ b`` minimises ``|J q̇ - b|² + λ² |q̇|²``. The damping is zero while
the smallest singular value ``σ_min`` of ``J`` is at least ``ε`` (``threshold``) and rises
smoothly below it (Chiaverini's rule, :func:`manip_kin.codegen.inlined.damping_sq`):
``λ² = λ_max² (1 - (σ_min / ε)²)``: exact solutions away from singularities, bounded ones
at them.

* :func:`damped_least_squares`: the solve on numpy arrays for a given λ (offline code).
* :class:`DampedSolver`: the solve with the rule on a generated chain's output
  (:func:`manip_kin.core.kinematics.compiled_kinematics`), unrolled by
  :func:`manip_kin.codegen.unrolled_linalg.damped_solver`; used by the controller, by IK's
  Newton-Raphson method and, emitted, by the generated control step
  (:mod:`manip_kin.codegen.control_step`). ``σ_min`` is only computed when the cheap certificate
  (:func:`manip_kin.codegen.inlined.smallest_eigenvalue_bound` and ``1/tr((JJᵀ)⁻¹)``)
  cannot prove ``σ_min >= ε``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence

import numpy as np

from manip_kin.codegen.inlined import bound_group_sizes, damping_sq, smallest_eigenvalue_bound
from manip_kin.codegen.unrolled_linalg import damped_solver
from manip_kin.core.pose_jacobian import jacobian_of
from manip_kin.errors import NonFiniteError


def damped_least_squares(matrix, rhs, damping: float) -> np.ndarray:
    """``Aᵀ (A Aᵀ + λ² I)⁻¹ b`` without forming an inverse.

    Args:
        matrix: A, shape (m, n).
        rhs: b, shape (m,).
        damping: λ >= 0 (same unit as A's singular values).
    Returns:
        x, shape (n,), minimising ``|A x - b|² + λ² |x|²``.
    """
    a = np.asarray(matrix, dtype=float)
    gram = a @ a.T
    gram.flat[:: gram.shape[0] + 1] += damping * damping
    return a.T @ np.linalg.solve(gram, rhs)


def _lapack_eigenvalues():
    """numpy's LAPACK kernel behind ``eigvalsh`` (lower triangle), or None.

    ``np.linalg.eigvalsh`` spends most of its ~5 µs on a 6x6 matrix in Python checks and an
    error-state context around this one call; the control step near a singularity calls it
    every cycle. It is numpy's private module, so it is only used where it exists and gives
    the public function's answer (checked once here); otherwise the public path runs.
    """
    try:
        from numpy.linalg import _umath_linalg

        kernel = _umath_linalg.eigvalsh_lo
        probe = np.array([[2.0, 1.0], [1.0, 2.0]])
        if np.allclose(kernel(probe, signature="d->d"), np.linalg.eigvalsh(probe), rtol=0.0, atol=1e-12):
            return kernel
    except (ImportError, AttributeError, TypeError, ValueError):
        pass
    return None


_EIGENVALUES_KERNEL = _lapack_eigenvalues()


_PACKERS: dict[int, Callable[..., bytes]] = {}


def _packed_matrix(entries, size: int) -> np.ndarray:
    """``size²`` floats as a read-only (size, size) array: packed into bytes and viewed, which
    costs a third of what ``np.array`` takes to inspect a tuple of Python floats."""
    pack = _PACKERS.get(size)
    if pack is None:
        pack = _PACKERS.setdefault(size, struct.Struct(f"{size * size}d").pack)
    return np.frombuffer(pack(*entries)).reshape(size, size)


def symmetric_eigenvalues(entries, size: int) -> list[float]:
    """Eigenvalues, ascending, of a small symmetric matrix given as ``size²`` floats, row-major.

    Uses the lower triangle. The same values as ``np.linalg.eigvalsh``, faster where numpy's
    kernel can be called directly (see :func:`_lapack_eigenvalues`); a non-finite result
    (which the public function would report as an error) goes through the public path.
    """
    if _EIGENVALUES_KERNEL is not None:
        values = _EIGENVALUES_KERNEL(_packed_matrix(entries, size), signature="d->d").tolist()
        if values[0] - values[0] == 0.0 and values[-1] - values[-1] == 0.0:
            return values
    return np.linalg.eigvalsh(np.array(entries).reshape(size, size)).tolist()


def gram_eigenvalues(jacobian: np.ndarray) -> np.ndarray:
    """Eigenvalues of ``J Jᵀ`` (= σ²), ascending; raises on a non-finite Jacobian."""
    gram = jacobian @ jacobian.T
    if not np.all(np.isfinite(gram)):
        raise NonFiniteError("the Jacobian (q or the model)")
    return np.linalg.eigvalsh(gram)


class DampedSolver:
    """The damped least-squares solve with Chiaverini's rule, over one chain's output.

    Args:
        chain: generated chain returning the pose then the 6 x n Jacobian (row-major).
        dof: number of joints n.
        rows: task rows of the Jacobian.

    Every Jacobian entry is read from the chain's output (no constant folded in), so a
    caller may zero the columns of joints it holds.
    """

    def __init__(self, chain: Callable, dof: int, rows: Sequence[int]):
        self.dof = dof
        self.rows = tuple(rows)
        self._group_sizes = bound_group_sizes(self.rows)
        #: ``shifted(values, b, d)``: the raw unrolled solve with a given ``d = λ²`` (see
        #: :func:`manip_kin.codegen.unrolled_linalg.damped_solver`), or None when not positive definite.
        self.shifted = damped_solver(chain, dof, self.rows, inverse_trace=True, fold_constants=False)

    def task_jacobian(self, values: Sequence[float]) -> np.ndarray:
        """The task rows of the Jacobian in a chain output, shape (m, n)."""
        return jacobian_of(values, self.dof)[list(self.rows)]

    def certified(self, result: tuple, threshold_sq: float) -> bool:
        """True when an unshifted solve's ``(x, det, tr_angular, tr_linear, tr⁻¹)`` proves
        σ_min² >= ``threshold_sq``."""
        _, determinant, trace_angular, trace_linear, inverse_trace = result
        angular, linear = self._group_sizes
        bound = smallest_eigenvalue_bound(determinant, trace_angular, angular, trace_linear, linear)
        if bound >= threshold_sq:
            return True
        return inverse_trace * threshold_sq <= 1.0

    def solve(
        self,
        values: Sequence[float],
        rhs: Sequence[float],
        threshold_sq: float,
        damping_max_sq: float,
        try_certificate: bool = True,
    ) -> tuple:
        """``q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ rhs`` with λ from σ_min (:func:`manip_kin.codegen.inlined.damping_sq`).

        Args:
            values: the chain's output (pose, then the Jacobian).
            rhs: the task-space right-hand side, ``len(rows)`` floats.
            threshold_sq: ε², > 0.
            damping_max_sq: λ_max², >= 0.
            try_certificate: first try the cheap certificate (False when the caller already
                knows it fails).

        Returns:
            ``(qdot, λ, singular, manipulability)``: n floats, the damping used, σ_min < ε,
            and ``sqrt(det(J Jᵀ))``.
        """
        result = None
        if try_certificate:
            result = self.shifted(values, rhs, 0.0)
            if result is not None and self.certified(result, threshold_sq):
                return result[0], 0.0, False, math.sqrt(result[1])
        # Possibly near a singularity: decide the damping from the exact σ_min.
        jacobian = self.task_jacobian(values)
        eigenvalues = gram_eigenvalues(jacobian)
        sigma_min_sq = max(float(eigenvalues[0]), 0.0)
        manipulability = math.sqrt(float(np.prod(np.maximum(eigenvalues, 0.0))))
        shift = damping_sq(sigma_min_sq, threshold_sq, damping_max_sq)
        if shift == 0.0 and sigma_min_sq >= threshold_sq:
            if result is None:
                result = self.shifted(values, rhs, 0.0)
            if result is not None:
                return result[0], 0.0, False, manipulability
        damped = self.shifted(values, rhs, shift) if shift > 0.0 else None
        if damped is not None:
            return damped[0], math.sqrt(shift), True, manipulability
        # No damping configured at an exact singularity: the minimum-norm least-squares rates.
        rates = np.linalg.lstsq(jacobian, np.asarray(rhs, dtype=float), rcond=1e-12)[0].tolist()
        return rates, math.sqrt(shift), True, manipulability
