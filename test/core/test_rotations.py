"""Rotation and transform utilities: round trips at random and at the edge cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from kin_reference import euler_rpy, expm, rodrigues, twist_matrix

from manip_kin.core.damped_least_squares import damped_least_squares
from manip_kin.core.rotations import (
    adjoint,
    check_rotation,
    invert_transform,
    matrix_to_angle_axis,
    matrix_to_quat,
    matrix_to_rotvec,
    matrix_to_rpy,
    quat_slerp,
    quat_to_matrix,
    rotvec_to_matrix,
    rpy_to_matrix,
    se3_exp,
    se3_log,
    ypr_to_matrix,
)
from manip_kin.errors import NotARotationError

angles = st.floats(min_value=-math.pi, max_value=math.pi, allow_nan=False)
unit_vectors = (
    st.tuples(*[st.floats(-1, 1)] * 3)
    .filter(lambda v: 0.1 < np.linalg.norm(v))
    .map(lambda v: np.array(v) / np.linalg.norm(v))
)


@given(angles, st.floats(-1.5, 1.5), angles)
def test_rpy_matches_the_elementary_product_and_round_trips(roll, pitch, yaw):
    rotation = rpy_to_matrix(roll, pitch, yaw)
    np.testing.assert_allclose(rotation, euler_rpy(roll, pitch, yaw), atol=1e-12)
    np.testing.assert_allclose(ypr_to_matrix(yaw, pitch, roll), rotation, atol=0)
    np.testing.assert_allclose(rpy_to_matrix(*matrix_to_rpy(rotation)), rotation, atol=1e-10)


@pytest.mark.parametrize("pitch", [math.pi / 2, -math.pi / 2])
@pytest.mark.parametrize("roll, yaw", [(0.3, 0.0), (0.2, -1.1), (-2.5, 2.0)])
def test_rpy_at_gimbal_lock_reproduces_the_rotation(roll, pitch, yaw):
    rotation = rpy_to_matrix(roll, pitch, yaw)
    recovered = matrix_to_rpy(rotation)
    assert recovered[1] == pytest.approx(pitch, abs=1e-9)
    np.testing.assert_allclose(rpy_to_matrix(*recovered), rotation, atol=1e-9)


@given(unit_vectors, st.floats(0.0, math.pi))
def test_rotvec_round_trip_and_agreement_with_rodrigues(axis, angle):
    rotation = rotvec_to_matrix(axis * angle)
    np.testing.assert_allclose(rotation, rodrigues(axis, angle), atol=1e-12)
    recovered = matrix_to_rotvec(rotation)
    np.testing.assert_allclose(rotvec_to_matrix(recovered), rotation, atol=1e-12)
    assert np.linalg.norm(recovered) <= math.pi + 1e-12


@pytest.mark.parametrize(
    "angle", [0.0, 1e-12, 1e-9, 1e-6, 1e-3, math.pi - 1e-3, math.pi - 1e-6, math.pi - 1e-9, math.pi]
)
def test_rotvec_is_exact_near_zero_and_near_pi(angle):
    axis = np.array([0.36, -0.48, 0.8])
    rotation = rodrigues(axis, angle)
    rotvec = matrix_to_rotvec(rotation)
    recovered_angle, recovered_axis = matrix_to_angle_axis(rotation)
    assert recovered_angle == pytest.approx(angle, abs=1e-12)
    if angle > 1e-12:
        # near π the axis sign is arbitrary (a rotation by π about -a is the same)
        sign = 1.0 if angle < math.pi - 1e-6 else float(np.sign(recovered_axis @ axis))
        np.testing.assert_allclose(recovered_axis * sign, axis, atol=1e-7 if angle > 1e-9 else 1e-3)
    np.testing.assert_allclose(rotvec_to_matrix(rotvec), rotation, atol=1e-14)


@given(unit_vectors, st.floats(0.0, math.pi))
def test_quaternion_round_trip_and_unit_length(axis, angle):
    rotation = rodrigues(axis, angle)
    quat = matrix_to_quat(rotation)
    assert np.linalg.norm(quat) == pytest.approx(1.0, abs=1e-12)
    assert quat[3] >= 0.0
    np.testing.assert_allclose(quat_to_matrix(quat), rotation, atol=1e-12)
    np.testing.assert_allclose(
        quat[:3],
        axis * math.sin(angle / 2) * (1 if quat[3] > 0 or angle < math.pi else np.sign(quat[:3] @ axis)),
        atol=1e-9,
    )


def test_quaternion_of_identity_and_of_half_turns():
    np.testing.assert_allclose(matrix_to_quat(np.eye(3)), [0, 0, 0, 1])
    for axis in np.eye(3):
        quat = matrix_to_quat(rodrigues(axis, math.pi))
        np.testing.assert_allclose(np.abs(quat), np.append(axis, 0.0), atol=1e-12)


def test_slerp_moves_at_constant_angular_rate():
    start = matrix_to_quat(np.eye(3))
    end = matrix_to_quat(rodrigues([0, 0, 1], 2.0))
    for fraction in (0.0, 0.25, 0.5, 1.0):
        np.testing.assert_allclose(
            quat_to_matrix(quat_slerp(start, end, fraction)), rodrigues([0, 0, 1], 2.0 * fraction), atol=1e-12
        )


@settings(max_examples=50)
@given(st.tuples(*[st.floats(-3, 3)] * 6))
def test_se3_exp_matches_the_matrix_exponential_and_log_inverts_it(twist):
    twist = np.array(twist)
    if np.linalg.norm(twist[:3]) >= math.pi:
        twist[:3] *= 3.0 / np.linalg.norm(twist[:3])  # log returns angles in [0, π)
    transform = se3_exp(twist)
    np.testing.assert_allclose(transform, expm(twist_matrix(twist)), atol=1e-10)
    np.testing.assert_allclose(se3_log(transform), twist, atol=1e-8)


def test_adjoint_maps_twists_between_frames():
    rng = np.random.default_rng(0)
    transform = se3_exp(rng.normal(size=6))
    twist_b = rng.normal(size=6)
    # [V_a] = T [V_b] T⁻¹
    expected = transform @ twist_matrix(twist_b) @ invert_transform(transform)
    twist_a = adjoint(transform) @ twist_b
    np.testing.assert_allclose(twist_matrix(twist_a), expected, atol=1e-12)
    np.testing.assert_allclose(invert_transform(transform) @ transform, np.eye(4), atol=1e-12)


def test_check_rotation_names_what_is_wrong():
    with pytest.raises(NotARotationError, match="det"):
        check_rotation(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(NotARotationError, match="shape"):
        check_rotation(np.eye(4))
    with pytest.raises(NotARotationError, match="zero length"):
        quat_to_matrix([0, 0, 0, 0])


def test_damped_least_squares_solves_the_normal_equations():
    rng = np.random.default_rng(1)
    wide = rng.normal(size=(3, 5))
    damping = 0.3
    expected = np.linalg.solve(wide.T @ wide + damping**2 * np.eye(5), wide.T)  # normal equations
    b = rng.normal(size=3)
    np.testing.assert_allclose(damped_least_squares(wide, b, damping), expected @ b, atol=1e-12)
    # without damping: the minimum-norm solution of a full-row-rank system
    np.testing.assert_allclose(damped_least_squares(wide, b, 0.0), np.linalg.pinv(wide) @ b, atol=1e-12)
    # A rank-deficient matrix: the damped inverse is V diag(σ / (σ² + λ²)) Uᵀ from the SVD, the
    # zero singular value contributing nothing (finite, not 1/0).
    singular = np.array([[1.0, 0.0], [1.0, 0.0]])
    u, sigma, vt = np.linalg.svd(singular)
    expected = vt.T @ np.diag(sigma / (sigma**2 + 0.1**2)) @ u.T
    np.testing.assert_allclose(expected, [[1 / (2 + 0.01), 1 / (2 + 0.01)], [0.0, 0.0]], atol=1e-15)
    rhs = np.array([1.0, 2.0])
    np.testing.assert_allclose(damped_least_squares(singular, rhs, 0.1), expected @ rhs, atol=1e-12)


@given(unit_vectors)
def test_rotation_z_onto_maps_z_to_the_direction(direction):
    from manip_kin.core.rotations import rotation_z_onto

    rotation = rotation_z_onto(direction)
    np.testing.assert_allclose(rotation @ [0, 0, 1], direction, atol=1e-12)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_rotation_z_onto_minus_z_is_a_half_turn():
    from manip_kin.core.rotations import rotation_z_onto

    np.testing.assert_allclose(rotation_z_onto([0, 0, -1]) @ [0, 0, 1], [0, 0, -1], atol=0)
