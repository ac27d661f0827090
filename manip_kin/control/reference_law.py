"""The resolved-rate control step of :mod:`manip_kin.control.resolved_rate`, written plainly in numpy.

:class:`manip_kin.control.resolved_rate.CartesianController` runs the law as one generated function
(:mod:`manip_kin.codegen.control_step`): fast, and hard to read. This module is the same law as a
reader would write it from the control module's docstring, one numbered step at a time, on
numpy arrays and the numpy kinematics (:func:`manip_kin.core.kinematics.forward_kinematics`), sharing
no code with the generated step. The tests check the generated step against it over random
robots, configurations, goals and configurations of the controller, limits included.

It is a specification, not a fast path: about a hundred times slower than the generated step.
"""

from __future__ import annotations

import math

import numpy as np

from manip_kin.control.resolved_rate import ControllerConfig, ControlOutput
from manip_kin.core.kinematics import KinematicsData, forward_kinematics, frame_in_base, geometric_jacobian_from_data
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import parse_task
from manip_kin.core.rotations import matrix_to_rotvec


def reference_step(
    model: RobotModel,
    q: np.ndarray,
    goal_pose: np.ndarray,
    config: ControllerConfig = ControllerConfig(),
    goal_twist: tuple[np.ndarray, np.ndarray] | None = None,
    dt: float = 0.002,
) -> ControlOutput:
    """One step of the control law, as :meth:`CartesianController.step` computes it.

    Args:
        model: the robot.
        q: joint positions, shape (n,) [rad | m].
        goal_pose: goal pose of the controlled frame in base, shape (4, 4).
        config: the controller's parameters.
        goal_twist: feed-forward ``(angular [rad/s], linear [m/s])``, shapes (3,) each.
        dt: control period [s], > 0.
    """
    q = np.asarray(q, dtype=float)
    goal = np.asarray(goal_pose, dtype=float)
    frame = model.frame_index(config.frame if config.frame is not None else model.default_frame)
    rows = list(parse_task(config.task, model).rows)
    data = KinematicsData(model)
    forward_kinematics(model, data, q)
    pose = frame_in_base(model, data, frame)
    jacobian = geometric_jacobian_from_data(model, data, frame, pose[:3, 3])[rows]

    # 1. The error: the rotation vector of R_goal Rᵀ, and p_goal - p.
    orientation_error = matrix_to_rotvec(goal[:3, :3] @ pose[:3, :3].T)
    position_error = goal[:3, 3] - pose[:3, 3]

    # 2. The reference twist v* = [K_o e_o + ω_ff; K_p e_p + v_ff], over the task rows.
    feed_forward = np.zeros(6) if goal_twist is None else np.concatenate([goal_twist[0], goal_twist[1]])
    twist = np.concatenate([config.gain_angular * orientation_error, config.gain_linear * position_error])
    task_twist = (twist + feed_forward)[rows]

    # 3. q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ v*, λ by Chiaverini's rule from σ_min.
    epsilon_sq = config.singular_threshold**2
    damping_max_sq = config.damping_max**2
    qdot, damping, singular, manipulability = _damped_rates(jacobian, task_twist, epsilon_sq, damping_max_sq)

    # 4. Position limits: hold the worst offender on the rate that lands it on its limit,
    # re-solve the rest of the task over the other joints, repeat. A joint offends when its
    # rate, held to its velocity limit (step 5 scales it there), crosses a limit within dt.
    held: dict[int, float] = {}
    if config.respect_position_limits:
        top_speeds = model.velocity_limits if config.respect_velocity_limits else np.full(model.dof, np.inf)
        reduced = jacobian.copy()
        residual = task_twist.copy()
        for _ in range(model.dof):
            worst, worst_excess, worst_rate = -1, 0.0, 0.0
            for j in range(model.dof):
                if j in held:
                    continue
                landing = q[j] + np.clip(qdot[j], -top_speeds[j], top_speeds[j]) * dt
                if qdot[j] < 0.0 and landing < model.lower[j]:
                    rate = min((model.lower[j] - q[j]) / dt, 0.0)
                elif qdot[j] > 0.0 and landing > model.upper[j]:
                    rate = max((model.upper[j] - q[j]) / dt, 0.0)
                else:
                    continue
                excess = abs(qdot[j] - rate) / model.velocity_limits[j]
                if worst < 0 or excess > worst_excess:
                    worst, worst_excess, worst_rate = j, excess, rate
            if worst < 0:
                break
            held[worst] = worst_rate
            qdot[worst] = worst_rate
            residual = residual - reduced[:, worst] * worst_rate
            reduced[:, worst] = 0.0
            if len(held) == model.dof:
                break
            solved, damping, singular, _ = _damped_rates(reduced, residual, epsilon_sq, damping_max_sq)
            free = [j for j in range(model.dof) if j not in held]
            qdot[free] = solved[free]

    # 5. Velocity limits: one factor for every joint, so the direction is kept.
    scale = 1.0
    if config.respect_velocity_limits:
        worst_ratio = float(np.max(np.abs(qdot) / model.velocity_limits))
        if worst_ratio > 1.0:
            scale = 1.0 / worst_ratio
            qdot = qdot * scale
    return ControlOutput(
        qdot=qdot,
        orientation_error=orientation_error,
        position_error=position_error,
        manipulability=manipulability,
        damping=damping,
        velocity_scale=scale,
        limited_joints=tuple(sorted(held)),
        singular=singular,
    )


def _damped_rates(
    jacobian: np.ndarray, twist: np.ndarray, epsilon_sq: float, damping_max_sq: float
) -> tuple[np.ndarray, float, bool, float]:
    """``(q̇, λ, σ_min < ε, sqrt(det(J Jᵀ)))`` for the task Jacobian (m, n) and twist (m,)."""
    gram = jacobian @ jacobian.T
    eigenvalues = np.linalg.eigvalsh(gram)
    sigma_min_sq = max(float(eigenvalues[0]), 0.0)
    manipulability = math.sqrt(float(np.prod(np.maximum(eigenvalues, 0.0))))
    if sigma_min_sq >= epsilon_sq:
        return jacobian.T @ np.linalg.solve(gram, twist), 0.0, False, manipulability
    damping_sq = damping_max_sq * (1.0 - sigma_min_sq / epsilon_sq)
    if damping_sq > 0.0:
        shifted = gram + damping_sq * np.eye(len(twist))
        return jacobian.T @ np.linalg.solve(shifted, twist), math.sqrt(damping_sq), True, manipulability
    # No damping configured at a singularity: the minimum-norm least-squares rates.
    return np.linalg.lstsq(jacobian, twist, rcond=1e-12)[0], 0.0, True, manipulability
