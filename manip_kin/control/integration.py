"""Integration of joint rates within the position and velocity limits: the one integrator.

An ideal velocity-controlled arm: ``q ← q + s·q̇·dt``, where ``s <= 1`` scales the whole rate
vector (not joint by joint, so the Cartesian direction holds) into the velocity limits, and
the result stops on the position limits the way a drive would. The simulated arm of the
``robot_state`` node and the offline simulation (:mod:`manip_kin.control.simulation`) both step with
:func:`integrate_joint_rates`. Plain floats: at 7 joints a numpy call costs more than the
arithmetic.
"""

from __future__ import annotations

from collections.abc import Sequence


def integrate_joint_rates(
    q: Sequence[float],
    rates: Sequence[float],
    dt: float,
    lower: Sequence[float],
    upper: Sequence[float],
    inverse_velocity_limits: Sequence[float] | None = None,
) -> tuple[list[float], list[float], float, float]:
    """One step of ``dt`` seconds from ``q`` with joint ``rates``.

    Args:
        q: joint positions [rad | m], n floats.
        rates: commanded joint rates [rad/s | m/s], n floats.
        dt: step [s], > 0.
        lower, upper: position limits, n floats each.
        inverse_velocity_limits: ``1 / velocity_limit`` per joint [s/rad | s/m]; None: no scaling.

    Returns:
        ``(q_next, applied_rates, scale, overshoot)``: the new positions; the rates actually
        applied, ``(q_next - q) / dt`` (zero for a joint stopped on a limit); the factor
        (<= 1) the rates were scaled by; and the largest amount [rad | m] by which the
        unclamped step left the position limits (0 when it stayed inside).
    """
    n = len(q)
    scale = 1.0
    if inverse_velocity_limits is not None:
        peak = max([abs(rates[i]) * inverse_velocity_limits[i] for i in range(n)], default=0.0)
        if peak > 1.0:
            scale = 1.0 / peak
    step = scale * dt
    q_next = []
    overshoot = 0.0
    for i in range(n):
        value = q[i] + rates[i] * step
        if value < lower[i]:
            overshoot = max(overshoot, lower[i] - value)
            value = lower[i]
        elif value > upper[i]:
            overshoot = max(overshoot, value - upper[i])
            value = upper[i]
        q_next.append(value)
    inverse_dt = 1.0 / dt
    # The scaled rate, or what was left of it before a limit; never more: for a tiny dt the
    # difference quotient alone can round above the velocity limit.
    applied = []
    for i in range(n):
        rate = rates[i] * scale
        moved = (q_next[i] - q[i]) * inverse_dt
        applied.append(rate if abs(moved) >= abs(rate) else moved)
    return q_next, applied, scale, overshoot
