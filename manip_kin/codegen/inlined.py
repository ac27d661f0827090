"""The plain-float functions the generated code inlines from their own source.

The control step and the IK iteration (:mod:`manip_kin.codegen.control_step`,
:mod:`manip_kin.codegen.ik_step`) inline these through :mod:`manip_kin.codegen.source_inline`, so
each stays one definition, tested and called as Python too: the rotation vector by
:mod:`manip_kin.core.rotations`, the damping rule and the eigenvalue bound by
:class:`manip_kin.core.damped_least_squares.DampedSolver`. They live here, below ``core``, because
the generator reads their source. Each is straight-line code with one ``return``; the names
they read but do not assign (``sqrt``, ``atan2``, ``max``) are in the generated code's namespace.
"""

from __future__ import annotations

from collections.abc import Sequence
from math import atan2, sqrt


def shepperd_quaternion(
    m00: float, m01: float, m02: float, m10: float, m11: float, m12: float, m20: float, m21: float, m22: float
) -> tuple[float, float, float, float]:
    """Quaternion ``(x, y, z, w)``, ``w >= 0``, of a rotation matrix given by its entries, not normalised.

    Shepperd's method on plain floats (control loops call it where a numpy round trip
    would cost more than the arithmetic): it divides by the largest of the four candidate
    components, so there is no cancellation anywhere. For a rotation matrix the result has
    unit length up to rounding. Straight-line code with one ``return``: the generated control
    step and IK iteration inline this very function (:mod:`manip_kin.codegen.source_inline`).
    """
    trace = m00 + m11 + m22
    if trace >= m00 and trace >= m11 and trace >= m22:
        s = 2.0 * sqrt(1.0 + trace if trace > -1.0 else 0.0)
        x = (m21 - m12) / s
        y = (m02 - m20) / s
        z = (m10 - m01) / s
        w = 0.25 * s
    elif m00 >= m11 and m00 >= m22:
        s = 2.0 * sqrt(max(1.0 + m00 - m11 - m22, 0.0))
        x = 0.25 * s
        y = (m01 + m10) / s
        z = (m02 + m20) / s
        w = (m21 - m12) / s
    elif m11 >= m22:
        s = 2.0 * sqrt(max(1.0 + m11 - m00 - m22, 0.0))
        x = (m01 + m10) / s
        y = 0.25 * s
        z = (m12 + m21) / s
        w = (m02 - m20) / s
    else:
        s = 2.0 * sqrt(max(1.0 + m22 - m00 - m11, 0.0))
        x = (m02 + m20) / s
        y = (m12 + m21) / s
        z = 0.25 * s
        w = (m10 - m01) / s
    if w < 0.0:
        x = -x
        y = -y
        z = -z
        w = -w
    return x, y, z, w


def rotvec_from_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Rotation vector (axis × angle, angle in [0, π]) of a quaternion with ``w >= 0``, any length.

    ``2 atan2(|v|, w) v / |v|`` is exact near 0 and near π, where the textbook
    ``arccos((trace - 1) / 2)`` loses half the digits, and does not depend on the
    quaternion's length. Inlined by the generated code like :func:`shepperd_quaternion`.
    """
    vector_norm = sqrt(x * x + y * y + z * z)
    if vector_norm < 1e-8 * w:
        scale = 2.0 / w  # limit of 2·atan2(n, w)/n as n → 0
    else:
        scale = 2.0 * atan2(vector_norm, w) / vector_norm
    return x * scale, y * scale, z * scale


def damping_sq(sigma_min_sq: float, threshold_sq: float, damping_max_sq: float) -> float:
    """Chiaverini's rule: ``λ² = λ_max² (1 - σ_min²/ε²)`` below ``ε``, else 0.

    Args:
        sigma_min_sq: ``σ_min²``, the smallest eigenvalue of ``J Jᵀ`` (>= 0).
        threshold_sq: ``ε²`` (> 0).
        damping_max_sq: ``λ_max²``, the damping at an exact singularity (>= 0).

    One expression, so that the generated control step inlines this very function.
    """
    return damping_max_sq * (1.0 - sigma_min_sq / threshold_sq) if sigma_min_sq < threshold_sq else 0.0


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
