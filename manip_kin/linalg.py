"""Moore–Penrose pseudo-inverses, plain and damped, and the manipulability measure."""

from __future__ import annotations

import numpy as np


def right_pinv(matrix) -> np.ndarray:
    """``Aᵀ (A Aᵀ)⁻¹`` for a full-row-rank ``A`` of shape (m, n), m <= n; shape (n, m)."""
    a = np.asarray(matrix, dtype=float)
    return a.T @ np.linalg.inv(a @ a.T)


def left_pinv(matrix) -> np.ndarray:
    """``(Aᵀ A)⁻¹ Aᵀ`` for a full-column-rank ``A`` of shape (m, n), m >= n; shape (n, m)."""
    a = np.asarray(matrix, dtype=float)
    return np.linalg.inv(a.T @ a) @ a.T


def damped_right_pinv(matrix, damping: float) -> np.ndarray:
    """``Aᵀ (A Aᵀ + λ² I)⁻¹``, finite for any ``A``; ``damping`` is λ (same units as A)."""
    a = np.asarray(matrix, dtype=float)
    rows = a.shape[0]
    return a.T @ np.linalg.inv(a @ a.T + damping * damping * np.eye(rows))


def damped_left_pinv(matrix, damping: float) -> np.ndarray:
    """``(Aᵀ A + λ² I)⁻¹ Aᵀ``, finite for any ``A``; equal to the damped right inverse."""
    a = np.asarray(matrix, dtype=float)
    cols = a.shape[1]
    return np.linalg.inv(a.T @ a + damping * damping * np.eye(cols)) @ a.T


def damped_solve(matrix, rhs, damping: float) -> np.ndarray:
    """``Aᵀ (A Aᵀ + λ² I)⁻¹ b`` without forming the inverse: the damped least-squares step.

    Args:
        matrix: A, shape (m, n).
        rhs: b, shape (m,).
        damping: λ >= 0.
    Returns:
        x, shape (n,), minimising ``|A x - b|² + λ² |x|²``.
    """
    a = np.asarray(matrix, dtype=float)
    gram = a @ a.T
    gram.flat[:: gram.shape[0] + 1] += damping * damping
    return a.T @ np.linalg.solve(gram, rhs)


def manipulability(matrix) -> float:
    """Yoshikawa's measure ``sqrt(det(A Aᵀ))``; 0 at a singularity."""
    a = np.asarray(matrix, dtype=float)
    return float(np.sqrt(max(np.linalg.det(a @ a.T), 0.0)))
