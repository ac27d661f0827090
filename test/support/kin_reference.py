"""Independent reference implementations for tests: naive, obviously-correct, slow.

Nothing here imports manip_kin's kinematics, so agreement with it means something.
"""

from __future__ import annotations

import numpy as np


def rodrigues(axis, angle: float) -> np.ndarray:
    """Rotation matrix about a unit axis (textbook Rodrigues)."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def homogeneous(rotation=None, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = np.eye(3) if rotation is None else rotation
    out[:3, 3] = translation
    return out


def euler_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll) by multiplying the three elementary rotations."""
    return rodrigues([0, 0, 1], yaw) @ rodrigues([0, 1, 0], pitch) @ rodrigues([1, 0, 0], roll)


def expm(matrix: np.ndarray, terms: int = 30) -> np.ndarray:
    """Matrix exponential by scaling and squaring a Taylor series."""
    norm = np.linalg.norm(matrix, 1)
    squarings = max(0, int(np.ceil(np.log2(norm))) + 1) if norm > 0.5 else 0
    scaled = matrix / (2**squarings)
    result = np.eye(matrix.shape[0])
    term = np.eye(matrix.shape[0])
    for k in range(1, terms):
        term = term @ scaled / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def twist_matrix(screw) -> np.ndarray:
    """4x4 se(3) matrix of a screw [w; v]."""
    w, v = np.asarray(screw[:3], float), np.asarray(screw[3:], float)
    out = np.zeros((4, 4))
    out[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
    out[:3, 3] = v
    return out


def fixed_then_z_fk(fixed_transforms, joint_types, q) -> list[np.ndarray]:
    """Frames of the robots.md convention T_i(q) = T_i(0) · Rz(q) or · Trans(0, 0, q)."""
    pose = np.eye(4)
    frames = []
    for fixed, kind, value in zip(fixed_transforms, joint_types, q):
        motion = (
            homogeneous(rodrigues([0, 0, 1], value)) if kind == "revolute" else homogeneous(translation=(0, 0, value))
        )
        pose = pose @ fixed @ motion
        frames.append(pose)
    return frames


def dh_fk(rows, q) -> np.ndarray:
    """Standard DH: product of Rz(θ) Tz(d) Tx(a) Rx(α); rows (d, theta, a, alpha, variable or None)."""
    pose = np.eye(4)
    values = iter(q)
    for d, theta, a, alpha, variable in rows:
        if variable == "theta":
            theta = theta + next(values)
        elif variable == "d":
            d = d + next(values)
        pose = (
            pose
            @ homogeneous(rodrigues([0, 0, 1], theta))
            @ homogeneous(translation=(0, 0, d))
            @ homogeneous(translation=(a, 0, 0))
            @ homogeneous(rodrigues([1, 0, 0], alpha))
        )
    return pose


def poe_fk(screws, home, q) -> np.ndarray:
    """Space-frame product of exponentials e^[S1]q1 … e^[Sn]qn M."""
    pose = np.eye(4)
    for screw, value in zip(screws, q):
        pose = pose @ expm(twist_matrix(screw) * value)
    return pose @ home


def numeric_derivative(function, q, index: int, step: float = 1e-6):
    """Central difference of ``function`` w.r.t. q[index]."""
    plus, minus = np.array(q, float), np.array(q, float)
    plus[index] += step
    minus[index] -= step
    return (function(plus) - function(minus)) / (2 * step)


def unskew(matrix) -> np.ndarray:
    return np.array([matrix[2, 1] - matrix[1, 2], matrix[0, 2] - matrix[2, 0], matrix[1, 0] - matrix[0, 1]]) / 2.0


def rotation_log(rotation) -> np.ndarray:
    """Rotation vector of a rotation matrix (textbook: angle from the trace, axis from the skew
    part); valid for angles well inside (0, π), which is where tests use it."""
    angle = np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))
    if angle < 1e-12:
        return np.zeros(3)
    return unskew(rotation) / np.sin(angle) * angle


def numeric_geometric_jacobian(fk, q, step: float = 1e-6) -> np.ndarray:
    """[angular; linear] Jacobian (6, n) in the base frame by central differences of ``fk(q) -> 4x4``."""
    pose = fk(np.asarray(q, float))
    columns = []
    for index in range(len(q)):
        derivative = numeric_derivative(fk, q, index, step)
        columns.append(np.concatenate([unskew(derivative[:3, :3] @ pose[:3, :3].T), derivative[:3, 3]]))
    return np.array(columns).T


def resolved_rates(
    jacobian, orientation_error, position_error, rows, gains=(0.8, 0.8), twist=None, damping=(0.04, 0.02)
):
    """The resolved-rate law written out plainly: v* = K e (+ feed-forward) on the task ``rows``,
    q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ v* with λ² = λ_max² (1 - (σ_min / ε)²) below ε, else 0."""
    angular, linear = (np.zeros(3), np.zeros(3)) if twist is None else twist
    reference = np.concatenate(
        [gains[0] * np.asarray(orientation_error) + angular, gains[1] * np.asarray(position_error) + linear]
    )[list(rows)]
    task = np.asarray(jacobian)[list(rows)]
    sigma_min = np.linalg.svd(task, compute_uv=False)[-1]
    damping_max, threshold = damping
    lambda_squared = damping_max**2 * (1.0 - (sigma_min / threshold) ** 2) if sigma_min < threshold else 0.0
    return task.T @ np.linalg.solve(task @ task.T + lambda_squared * np.eye(len(rows)), reference)


def velocity_scaled(qdot, limits) -> np.ndarray:
    """``qdot`` scaled by one factor into ``|q̇_i| <= limits_i``."""
    ratio = np.max(np.abs(qdot) / np.asarray(limits))
    return qdot / ratio if ratio > 1.0 else qdot
