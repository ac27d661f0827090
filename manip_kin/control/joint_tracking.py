"""Joint-space tracking: the law ``cartesian_controller`` runs when it follows a joint reference.

``q̇ = q̇_ref + K (q_ref − q)``: the reference velocity as feed-forward plus a proportional
correction (gain ``K`` [1/s]; a constant offset decays as ``exp(−K t)``). Then the limits,
as the cartesian law applies them (:mod:`manip_kin.control.resolved_rate`):

1. position limits: a joint whose rate, held to its velocity limit, would carry it past a
   limit within the control period ``dt`` gets the rate that lands it exactly on the limit
   (zero once there);
2. velocity limits: the whole ``q̇`` is scaled by one factor so every joint is within its
   limit, which keeps the direction of motion in joint space (a straight joint-space move
   stays straight, only slower).

Plain numpy: no ROS here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError


@dataclass(frozen=True)
class JointTrackingOutput:
    """Result of one :func:`joint_tracking_step`.

    Attributes:
        qdot: joint rates to command, shape (n,) [rad/s | m/s].
        joint_error: ``q_ref − q``, shape (n,) [rad | m].
        velocity_scale: factor applied to q̇ for the velocity limits (1.0 = not saturated).
        limited_joints: indices of joints held at (or stopped exactly on) a position limit.
    """

    qdot: np.ndarray
    joint_error: np.ndarray
    velocity_scale: float
    limited_joints: tuple[int, ...]


def joint_tracking_step(
    model: RobotModel,
    q: np.ndarray,
    q_reference: np.ndarray,
    qdot_reference: np.ndarray | None,
    gain: float,
    dt: float,
    respect_position_limits: bool = True,
    respect_velocity_limits: bool = True,
) -> JointTrackingOutput:
    """Joint rates that make ``q`` follow ``q_reference`` (see the module docstring).

    Args:
        model: the robot (limits).
        q: joint positions, shape (n,) [rad | m].
        q_reference: reference positions, shape (n,) [rad | m].
        qdot_reference: reference velocities (feed-forward), shape (n,), or None (zero).
        gain: ``K`` [1/s], >= 0.
        dt: control period [s], > 0.
        respect_position_limits: keep ``q + q̇·dt`` within the position limits.
        respect_velocity_limits: scale q̇ into the velocity limits.
    """
    if not 0.0 < dt < math.inf:
        raise InvalidArgumentError(f"dt = {dt!r}; valid: a finite period > 0 [s]")
    q = model.check_q(q)
    error = model.check_q(q_reference, "q_reference") - q
    qdot = gain * error
    if qdot_reference is not None:
        qdot = qdot + model.check_q(qdot_reference, "qdot_reference")
    limited: tuple[int, ...] = ()
    if respect_position_limits:
        # The rate the joint can have: the scaling below brings every rate within its limit.
        reach = np.clip(qdot, -model.velocity_limits, model.velocity_limits) if respect_velocity_limits else qdot
        landing = q + reach * dt
        low = (qdot < 0.0) & (landing < model.lower)
        high = (qdot > 0.0) & (landing > model.upper)
        if low.any() or high.any():
            qdot = qdot.copy()
            qdot[low] = np.minimum((model.lower[low] - q[low]) / dt, 0.0)
            qdot[high] = np.maximum((model.upper[high] - q[high]) / dt, 0.0)
            limited = tuple(int(j) for j in np.flatnonzero(low | high))
    scale = 1.0
    if respect_velocity_limits:
        worst = float(np.max(np.abs(qdot) / model.velocity_limits))
        if worst > 1.0:
            scale = 1.0 / worst
            qdot = qdot * scale
    return JointTrackingOutput(qdot, error, scale, limited)
