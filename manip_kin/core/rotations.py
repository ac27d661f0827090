"""Rotations and rigid transforms: rpy, angle-axis, quaternions, SE(3) exp/log, adjoint.

Conventions:
    * ``rpy`` is (roll, pitch, yaw) with ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, the same as
      URDF ``rpy="roll pitch yaw"``; ``ypr`` is the same rotation listed yaw first.
    * Quaternions are ``(x, y, z, w)`` like ``geometry_msgs/Quaternion``.
    * Twists and screw axes are 6-vectors ``[angular; linear]`` (``[ω; v]``), units [rad/s] and
      [m/s] for velocities.
    * Homogeneous transforms are 4x4 arrays ``[[R, p], [0, 1]]``.
"""

from __future__ import annotations

import math
from math import sqrt

import numpy as np

from manip_kin.codegen.inlined import rotvec_from_quaternion, shepperd_quaternion
from manip_kin.errors import NotARotationError, check_finite


def skew(vector) -> np.ndarray:
    """The 3x3 cross-product matrix ``[v]×`` of a 3-vector, so that ``skew(a) @ b == a × b``."""
    x, y, z = (float(value) for value in vector)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rot_x(angle: float) -> np.ndarray:
    """Rotation about x by ``angle`` [rad], shape (3, 3)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> np.ndarray:
    """Rotation about y by ``angle`` [rad], shape (3, 3)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> np.ndarray:
    """Rotation about z by ``angle`` [rad], shape (3, 3)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)``, angles in [rad], shape (3, 3)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(rotation) -> np.ndarray:
    """Roll, pitch, yaw [rad] of a rotation matrix, inverse of :func:`rpy_to_matrix`.

    Pitch is in [-π/2, π/2]. At gimbal lock (pitch = ±π/2) only roll ∓ yaw is
    defined; yaw is then reported as 0 and the rest of the rotation goes into roll.
    """
    r = np.asarray(rotation, dtype=float)
    # sin(pitch) = -r20; cos(pitch) from the first column is accurate near ±π/2.
    cos_pitch = math.hypot(r[0, 0], r[1, 0])
    pitch = math.atan2(-r[2, 0], cos_pitch)
    yaw = math.atan2(r[1, 0], r[0, 0]) if cos_pitch > 1e-12 else 0.0
    # Roll from what is left once yaw and pitch are undone: Rx(roll) = Ry(pitch)ᵀ Rz(yaw)ᵀ R.
    # Exact at and near gimbal lock, where atan2(r21, r22) loses the digits.
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    # rows 1 and 2 of Ry(pitch)ᵀ Rz(yaw)ᵀ, applied to columns 1 and 2 of R
    row1 = (-sy, cy, 0.0)
    row2 = (sp * cy, sp * sy, cp)
    m11 = row1[0] * r[0, 1] + row1[1] * r[1, 1]
    m21 = row2[0] * r[0, 1] + row2[1] * r[1, 1] + row2[2] * r[2, 1]
    roll = math.atan2(m21, m11)
    return np.array([roll, pitch, yaw])


def ypr_to_matrix(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """The same rotation as :func:`rpy_to_matrix`, arguments listed yaw first."""
    return rpy_to_matrix(roll, pitch, yaw)


def is_rotation(matrix, tolerance: float = 1e-6) -> bool:
    """True for a 3x3 orthonormal matrix with determinant +1 (within ``tolerance``)."""
    m = np.asarray(matrix, dtype=float)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        return False
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # huge entries: inf, then False, not a warning
        return bool(np.allclose(m @ m.T, np.eye(3), atol=tolerance) and abs(np.linalg.det(m) - 1.0) < tolerance)


def check_rotation(matrix, what: str = "rotation", tolerance: float = 1e-6) -> np.ndarray:
    """Return ``matrix`` as a float (3, 3) array or raise :class:`NotARotationError`."""
    m = np.asarray(matrix, dtype=float)
    if m.shape != (3, 3):
        raise NotARotationError(f"{what} has shape {m.shape}; a rotation is a 3x3 matrix")
    check_finite(m, what)
    if not is_rotation(m, tolerance):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            det = float(np.linalg.det(m))
            error = float(np.abs(m @ m.T - np.eye(3)).max())
        raise NotARotationError(
            f"{what} is not a rotation matrix (det {det:.6g}, |R Rᵀ - I| {error:.3g}); "
            f"valid: orthonormal with det +1 within {tolerance:g}"
        )
    return m


# --- quaternions ---------------------------------------------------------------------------

# Shepperd's method and the rotation vector of a quaternion, on plain floats, are in
# manip_kin.codegen.inlined: the generated control step inlines them from their source there.


def quaternion_from_entries(
    m00: float, m01: float, m02: float, m10: float, m11: float, m12: float, m20: float, m21: float, m22: float
) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` of a rotation matrix given by its entries."""
    x, y, z, w = shepperd_quaternion(m00, m01, m02, m10, m11, m12, m20, m21, m22)
    norm = sqrt(x * x + y * y + z * z + w * w)
    return x / norm, y / norm, z / norm, w / norm


def rotvec_from_entries(
    m00: float, m01: float, m02: float, m10: float, m11: float, m12: float, m20: float, m21: float, m22: float
) -> tuple[float, float, float]:
    """SO(3) logarithm on plain floats: the rotation vector of a rotation matrix given by its entries.

    The one definition of the rotation vector: :func:`matrix_to_rotvec`, the controller's pose
    error and (inlined) the generated control step and IK iteration all use it.
    """
    return rotvec_from_quaternion(*shepperd_quaternion(m00, m01, m02, m10, m11, m12, m20, m21, m22))


def matrix_to_quat(rotation) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` of a rotation matrix (Shepperd's method)."""
    return np.array(quaternion_from_entries(*np.asarray(rotation, dtype=float).ravel().tolist()))


def quat_to_matrix(quat) -> np.ndarray:
    """Rotation matrix of a quaternion ``(x, y, z, w)``; it is normalised first."""
    x, y, z, w = check_finite(quat, "quaternion").tolist()
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if norm < 1e-12:
        raise NotARotationError("quaternion has zero length; a rotation needs a unit quaternion")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_slerp(quat_from, quat_to, fraction: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions ``(x, y, z, w)``, shortest path.

    Args:
        quat_from: start quaternion, shape (4,).
        quat_to: end quaternion, shape (4,).
        fraction: 0 gives ``quat_from``, 1 gives ``quat_to``.
    """
    a = np.asarray(quat_from, dtype=float)
    b = np.asarray(quat_to, dtype=float)
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    dot = float(a @ b)
    if dot < 0.0:
        b, dot = -b, -dot
    if dot > 1.0 - 1e-12:
        out = a + fraction * (b - a)
        return out / np.linalg.norm(out)
    theta = math.acos(min(dot, 1.0))
    sin_theta = math.sin(theta)
    out = (math.sin((1.0 - fraction) * theta) * a + math.sin(fraction * theta) * b) / sin_theta
    return out / np.linalg.norm(out)


# --- angle-axis / rotation vector (SO(3) exp and log) ----------------------------------------


def rotvec_to_matrix(rotvec) -> np.ndarray:
    """SO(3) exponential: the rotation by ``|rotvec|`` [rad] about ``rotvec / |rotvec|``."""
    wx, wy, wz = (float(v) for v in rotvec)
    angle_sq = wx * wx + wy * wy + wz * wz
    angle = math.sqrt(angle_sq)
    if angle < 1e-4:
        # Taylor series of sin(θ)/θ and (1 - cos θ)/θ², exact to double precision here.
        a = 1.0 - angle_sq / 6.0
        b = 0.5 - angle_sq / 24.0
    else:
        a = math.sin(angle) / angle
        b = (1.0 - math.cos(angle)) / angle_sq
    k = skew((wx, wy, wz))
    return np.eye(3) + a * k + b * (k @ k)


def matrix_to_rotvec(rotation) -> np.ndarray:
    """SO(3) logarithm: rotation vector (axis × angle, angle in [0, π]) of a rotation matrix.

    See :func:`rotvec_from_entries`.
    """
    return np.array(rotvec_from_entries(*np.asarray(rotation, dtype=float).ravel().tolist()))


def angle_axis_to_matrix(angle: float, axis) -> np.ndarray:
    """Rotation by ``angle`` [rad] about ``axis`` (normalised here), shape (3, 3)."""
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis)
    if norm < 1e-12:
        raise NotARotationError("rotation axis has zero length")
    return rotvec_to_matrix(axis / norm * angle)


def matrix_to_angle_axis(rotation) -> tuple[float, np.ndarray]:
    """``(angle, axis)`` with angle in [0, π] [rad]; the axis is z for the identity."""
    rotvec = matrix_to_rotvec(rotation)
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-15:
        return 0.0, np.array([0.0, 0.0, 1.0])
    return angle, rotvec / angle


def rotation_z_onto(direction) -> np.ndarray:
    """The shortest-arc rotation taking the z axis onto the unit vector ``direction``, shape (3, 3)."""
    direction = np.asarray(direction, dtype=float)
    cross = np.array([-direction[1], direction[0], 0.0])  # z × direction
    sin_angle = float(np.linalg.norm(cross))
    cos_angle = float(direction[2])
    if sin_angle < 1e-12:
        return np.eye(3) if cos_angle > 0 else np.diag([1.0, -1.0, -1.0])
    k = skew(cross / sin_angle)
    return np.eye(3) + sin_angle * k + (1.0 - cos_angle) * (k @ k)


# --- homogeneous transforms and SE(3) ----------------------------------------------------------


def make_transform(rotation=None, translation=None) -> np.ndarray:
    """4x4 transform from a (3, 3) rotation (default I) and a (3,) translation (default 0)."""
    transform = np.eye(4)
    if rotation is not None:
        transform[:3, :3] = rotation
    if translation is not None:
        transform[:3, 3] = translation
    return transform


def transform_from_xyz_rpy(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 transform from a position [m] and roll, pitch, yaw [rad] (URDF ``<origin>``)."""
    return make_transform(rpy_to_matrix(*rpy), xyz)


def invert_transform(transform) -> np.ndarray:
    """Inverse of a rigid transform, using ``Rᵀ`` rather than a general matrix inverse."""
    t = np.asarray(transform, dtype=float)
    inverse = np.eye(4)
    rotation_t = t[:3, :3].T
    inverse[:3, :3] = rotation_t
    inverse[:3, 3] = -rotation_t @ t[:3, 3]
    return inverse


def se3_exp(twist) -> np.ndarray:
    """SE(3) exponential of a twist ``[ω; v]`` (unit time), a 4x4 transform."""
    twist = np.asarray(twist, dtype=float)
    omega, v = twist[:3], twist[3:]
    angle_sq = float(omega @ omega)
    angle = math.sqrt(angle_sq)
    k = skew(omega)
    k2 = k @ k
    if angle < 1e-4:
        b = 0.5 - angle_sq / 24.0
        c = 1.0 / 6.0 - angle_sq / 120.0
    else:
        b = (1.0 - math.cos(angle)) / angle_sq
        c = (angle - math.sin(angle)) / (angle_sq * angle)
    transform = np.eye(4)
    transform[:3, :3] = rotvec_to_matrix(omega)
    transform[:3, 3] = (np.eye(3) + b * k + c * k2) @ v
    return transform


def se3_log(transform) -> np.ndarray:
    """SE(3) logarithm: the twist ``[ω; v]`` with ``se3_exp(twist) == transform``."""
    t = np.asarray(transform, dtype=float)
    omega = matrix_to_rotvec(t[:3, :3])
    angle_sq = float(omega @ omega)
    angle = math.sqrt(angle_sq)
    k = skew(omega)
    if angle < 1e-4:
        d = 1.0 / 12.0 + angle_sq / 720.0
    else:
        # V⁻¹ = I - K/2 + (1/θ²)(1 - θ sinθ / (2(1 - cosθ))) K²
        d = (1.0 - angle * math.sin(angle) / (2.0 * (1.0 - math.cos(angle)))) / angle_sq
    v_inverse = np.eye(3) - 0.5 * k + d * (k @ k)
    return np.concatenate([omega, v_inverse @ t[:3, 3]])


def adjoint(transform) -> np.ndarray:
    """6x6 adjoint of a transform for twists ordered ``[ω; v]``: ``V_a = Ad(T_ab) V_b``."""
    t = np.asarray(transform, dtype=float)
    rotation = t[:3, :3]
    out = np.zeros((6, 6))
    out[:3, :3] = rotation
    out[3:, 3:] = rotation
    out[3:, :3] = skew(t[:3, 3]) @ rotation
    return out


def rpy_rate_matrix(rpy) -> np.ndarray:
    """``E(rpy)`` mapping roll/pitch/yaw rates to angular velocity in the fixed frame.

    ``ω = E @ [roll_dot, pitch_dot, yaw_dot]`` for ``R = Rz(yaw) Ry(pitch) Rx(roll)``;
    singular at pitch = ±π/2.
    """
    _roll, pitch, yaw = (float(v) for v in rpy)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])
