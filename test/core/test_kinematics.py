"""Forward kinematics and Jacobians against independent constructions."""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest
from kin_reference import (
    dh_fk,
    euler_rpy,
    fixed_then_z_fk,
    homogeneous,
    numeric_derivative,
    poe_fk,
    rodrigues,
    unskew,
)

from manip_kin.core.kinematics import (
    JACOBIAN_KINDS,
    KinematicsData,
    all_frames,
    batch_frame_pose,
    forward_kinematics,
    frame_pose,
    frame_poses,
    jacobian,
    transform_between,
)
from manip_kin.core.loaders import model_from_dict
from manip_kin.core.robots import bundled_robot_names, load_robot
from manip_kin.core.rotations import matrix_to_rpy
from manip_kin.errors import JointCountError, NonFiniteError, UnknownFrameError

ROBOTS = ["genova7", "mocom7", "irb120", "rpp", "scara"]


def _panda():
    from robot_data_files import example_robot_data_urdf

    from manip_kin.core.urdf import load_urdf

    return load_urdf(example_robot_data_urdf("panda_description/urdf/panda.urdf"), tip_link="panda_hand")


def _model(name):
    return _panda() if name == "panda" else load_robot(name)


def test_all_shared_robots_are_bundled():
    assert set(ROBOTS) <= set(bundled_robot_names())


# --- FK against the source conventions, written out independently ------------------------------

GENOVA7_TABLE = [  # (type, rows of R_i, p_i) from shared/robots.md
    ("revolute", [[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0, 0, 0.105]),
    ("revolute", [[0, 1, 0], [0, 0, 1], [1, 0, 0]], [0, 0, 0.110]),
    ("revolute", [[0, 0, 1], [0, -1, 0], [1, 0, 0]], [0.100, 0, 0]),
    ("revolute", [[0, 0, 1], [0, -1, 0], [1, 0, 0]], [0, 0, 0.325]),
    ("revolute", [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], [0.095, 0, 0]),
    ("prismatic", [[-1, 0, 0], [0, -1, 0], [0, 0, 1]], [0, 0, 0.095]),
    ("revolute", [[0, -1, 0], [0, 0, -1], [1, 0, 0]], [0, 0, 0.355]),
]


def _genova7_reference(q):
    fixed = [homogeneous(np.array(r, float), p) for _, r, p in GENOVA7_TABLE]
    frames = fixed_then_z_fk(fixed, [t for t, _, _ in GENOVA7_TABLE], q)
    tool = homogeneous(euler_rpy(math.pi / 6, 0.0, math.pi / 10), [0.3, 0.1, 0.0])
    return frames, frames[-1] @ tool


def test_genova7_matches_the_convention_and_the_sanity_pose():
    model = load_robot("genova7")
    q0 = model.initial_positions
    frames, tool = _genova7_reference(q0)
    np.testing.assert_allclose(frame_pose(model, q0, "tool"), tool, atol=1e-12)
    # The sanity value printed in robots.md (4 decimals).
    sanity = np.array([[0, 0.5, 0.866, 0], [-0.454, 0.7716, -0.4455, -1.1369], [-0.891, -0.3932, 0.227, 0.2327]])
    np.testing.assert_allclose(frame_pose(model, q0)[:3], sanity, atol=6e-4)
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = model.random_configuration(rng)
        frames, tool = _genova7_reference(q)
        computed = frame_poses(model, q)
        np.testing.assert_allclose(computed[1:8], np.array(frames), atol=1e-12)
        np.testing.assert_allclose(computed[8], frames[-1], atol=1e-12)  # ee = frame 7
        np.testing.assert_allclose(computed[9], tool, atol=1e-12)


def test_mocom7_millimetre_source_is_loaded_in_metres():
    table = [
        ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0, 0, 175]),
        ([[-1, 0, 0], [0, 0, 1], [0, 1, 0]], [0, 0, 98]),
        ([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], [105, 0, 0]),
        ([[0, 0, -1], [0, -1, 0], [-1, 0, 0]], [0, 145.5, 326.5]),
        ([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], [35, 0, 0]),
        ([[0, 0, 1], [0, -1, 0], [1, 0, 0]], [0, 0, 385]),
        ([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], [153, 0, 0]),
    ]
    fixed = [homogeneous(np.array(r, float), np.array(p) / 1000.0) for r, p in table]
    model = load_robot("mocom7")
    for q in (np.full(7, 1.3), np.full(7, 2.0), np.zeros(7)):
        expected = fixed_then_z_fk(fixed, ["revolute"] * 7, q)
        np.testing.assert_allclose(frame_poses(model, q)[1:8], np.array(expected), atol=1e-12)


def test_irb120_home_is_the_sum_of_offsets_and_axes_act_as_listed():
    model = load_robot("irb120")
    offsets = np.array([[0, 0, 0.145], [0, 0, 0.145], [0, 0, 0.270], [0.134, 0, 0.070], [0.168, 0, 0], [0.072, 0, 0]])
    home = frame_pose(model, np.zeros(6), "ee")
    np.testing.assert_allclose(home[:3, 3], offsets.sum(axis=0), atol=1e-12)
    np.testing.assert_allclose(home[:3, :3], np.eye(3), atol=1e-12)
    # Joint 2 (about y through [0, 0, 0.29]) pitches the whole arm: closed form for the wrist point.
    angle = 0.3
    rotated = frame_pose(model, [0, angle, 0, 0, 0, 0], "ee")
    pivot = np.array([0, 0, 0.29])
    np.testing.assert_allclose(rotated[:3, 3], pivot + rodrigues([0, 1, 0], angle) @ (home[:3, 3] - pivot), atol=1e-12)


RPP_ROWS = [
    (0.4, 0.0, 0.0, math.pi / 2, None),
    (0.0, 0.0, 0.3, 0.0, "theta"),
    (0.2, math.pi / 2, 0.0, math.pi / 2, "d"),
    (0.1, math.pi / 2, 0.0, 0.0, "d"),
]


def test_rpp_dh_table_matches_a_naive_dh_product():
    model = load_robot("rpp")
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = model.random_configuration(rng)
        np.testing.assert_allclose(frame_pose(model, q, "ee"), dh_fk(RPP_ROWS, q), atol=1e-12)
        # Frame 2 is the end of the second DH row.
        np.testing.assert_allclose(frame_pose(model, q, 2), dh_fk(RPP_ROWS[:3], q[:2]), atol=1e-12)


SCARA_SCREWS = [[0, 0, 1, 0, 0, 0], [0, 0, 1, 0, -0.5, 0], [0, 0, 0, 0, 0, 1], [0, 0, 1, 0, -1.0, 0]]
SCARA_AS_JOINT_LIST = {
    "name": "scara_joints",
    "joints": [
        {"name": "a", "origin": {"xyz": [0, 0, 0]}},
        {"name": "b", "origin": {"xyz": [0.5, 0, 0]}},
        {"name": "c", "type": "prismatic", "origin": {"xyz": [0.5, 0, 0]}, "limits": {"lower": 0, "upper": 0.5}},
        {"name": "d", "origin": {"xyz": [0, 0, 0]}},
    ],
}
SCARA_AS_DH = {
    "name": "scara_dh",
    "dh": [
        {"joint": "theta", "d": 0, "theta": 0, "a": 0.5, "alpha": 0},
        {"joint": "theta", "d": 0, "theta": 0, "a": 0.5, "alpha": 0},
        {"joint": "d", "d": 0, "theta": 0, "a": 0, "alpha": 0, "limits": {"lower": 0, "upper": 0.5}},
        {"joint": "theta", "d": 0, "theta": 0, "a": 0, "alpha": 0},
    ],
}


def test_scara_poe_dh_and_joint_list_forms_agree_with_the_exponential_product():
    poe = load_robot("scara")
    as_list = model_from_dict(SCARA_AS_JOINT_LIST, "test")
    as_dh = model_from_dict(SCARA_AS_DH, "test")
    home = homogeneous(translation=(1.0, 0, 0))
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = poe.random_configuration(rng)
        expected = poe_fk(SCARA_SCREWS, home, q)
        for model in (poe, as_list, as_dh):
            np.testing.assert_allclose(frame_pose(model, q, "ee"), expected, atol=1e-10)


def test_panda_urdf_matches_its_own_joint_chain():
    model = _panda()
    assert model.dof == 7
    rng = np.random.default_rng(11)
    for _ in range(5):
        q = model.random_configuration(rng)
        frames = frame_poses(model, q)
        # Frame i is frame i-1 · origin_i · rotation about axis_i: recomposed step by step.
        pose = np.eye(4)
        for i, joint in enumerate(model.joints):
            pose = pose @ joint.origin @ homogeneous(rodrigues(joint.axis, q[i]))
            np.testing.assert_allclose(frames[i + 1], pose, atol=1e-12)


# --- frames compose ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", ROBOTS)
def test_frame_to_frame_transforms_compose_and_invert(name):
    model = load_robot(name)
    q = model.random_configuration(np.random.default_rng(1))
    frames = model.frame_names
    a, b, c = frames[1], frames[-1], frames[len(frames) // 2]
    t_ab = transform_between(model, q, a, b)
    t_bc = transform_between(model, q, b, c)
    t_ac = transform_between(model, q, a, c)
    np.testing.assert_allclose(t_ab @ t_bc, t_ac, atol=1e-12)
    np.testing.assert_allclose(t_ab @ transform_between(model, q, b, a), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(transform_between(model, q, "base", b), frame_pose(model, q, b), atol=1e-12)


@pytest.mark.parametrize("name", ROBOTS)
def test_batched_fk_equals_single_fk(name):
    model = load_robot(name)
    rng = np.random.default_rng(2)
    configurations = np.array([model.random_configuration(rng) for _ in range(50)])
    for frame in (model.default_frame, "ee", "1", "base"):
        batched = batch_frame_pose(model, configurations, frame)
        index = model.frame_index(frame)
        single = np.array([frame_poses(model, q)[index] for q in configurations])  # the numpy chain
        np.testing.assert_allclose(batched, single, atol=1e-12)


@pytest.mark.parametrize("frame", ["tool", "3", "base"])
def test_batched_fk_across_its_block_boundary_and_for_no_configurations(frame):
    """N = one block + 5 (the last block partly filled, after a full one) and N = 0."""
    from manip_kin.core.kinematics import _BATCH_BLOCK

    model = load_robot("genova7")
    rng = np.random.default_rng(21)
    configurations = np.array([model.random_configuration(rng) for _ in range(_BATCH_BLOCK + 5)])
    batched = batch_frame_pose(model, configurations, frame)
    index = model.frame_index(frame)
    assert batched.shape == (_BATCH_BLOCK + 5, 4, 4)
    # Every pose, the ones either side of the boundary included, against the single-pose chain.
    for i in list(range(0, _BATCH_BLOCK + 5, 97)) + list(range(_BATCH_BLOCK - 3, _BATCH_BLOCK + 5)):
        np.testing.assert_allclose(batched[i], frame_poses(model, configurations[i])[index], atol=1e-12, err_msg=i)
    # The partial block must not show the previous block's values: a shorter batch gives the same.
    np.testing.assert_array_equal(batch_frame_pose(model, configurations[_BATCH_BLOCK:], frame), batched[_BATCH_BLOCK:])
    empty = batch_frame_pose(model, np.zeros((0, model.dof)), frame)
    assert empty.shape == (0, 4, 4)


def test_workspace_reuse_gives_the_same_answers():
    model = load_robot("genova7")
    data = KinematicsData(model)
    rng = np.random.default_rng(4)
    for _ in range(5):
        q = model.random_configuration(rng)
        forward_kinematics(model, data, q)
        np.testing.assert_allclose(all_frames(model, data), frame_poses(model, q), atol=0)


# --- Jacobians against numeric differentiation -------------------------------------------------


def _numeric_jacobians(model, q, frame):
    """Geometric, space, body and analytical Jacobians from central differences of FK."""
    pose = frame_pose(model, q, frame)
    n = model.dof
    out = {kind: np.zeros((6, n)) for kind in JACOBIAN_KINDS}
    for i in range(n):
        derivative = numeric_derivative(lambda x: frame_pose(model, x, frame), q, i)
        rotation = pose[:3, :3]
        omega = unskew(derivative[:3, :3] @ rotation.T)
        velocity = derivative[:3, 3]
        out["geometric"][:, i] = np.concatenate([omega, velocity])
        spatial = derivative @ np.linalg.inv(pose)
        out["space"][:, i] = np.concatenate([unskew(spatial[:3, :3]), spatial[:3, 3]])
        body = np.linalg.inv(pose) @ derivative
        out["body"][:, i] = np.concatenate([unskew(body[:3, :3]), body[:3, 3]])
        rpy_rate = numeric_derivative(lambda x: matrix_to_rpy(frame_pose(model, x, frame)[:3, :3]), q, i)
        out["analytical"][:, i] = np.concatenate([rpy_rate, velocity])
    return out


@pytest.mark.parametrize("name", ROBOTS + ["panda"])
def test_every_jacobian_kind_matches_numeric_differentiation(name):
    model = _model(name)
    # A seed fixed per robot (crc32 is stable across processes, unlike hash() of a str).
    seed = zlib.crc32(name.encode()) % 1000
    rng = np.random.default_rng(seed)
    frames = [model.default_frame, "ee", str(max(1, model.dof - 2))]
    for _ in range(4):
        q = model.random_configuration(rng, margin=0.05)
        for frame in frames:
            pitch = matrix_to_rpy(frame_pose(model, q, frame)[:3, :3])[1]
            numeric = _numeric_jacobians(model, q, frame)
            for kind in JACOBIAN_KINDS:
                if kind == "analytical" and abs(abs(pitch) - math.pi / 2) < 0.1:
                    continue  # rpy rates are singular at gimbal lock
                analytic = jacobian(model, q, frame, kind)
                np.testing.assert_allclose(
                    analytic.matrix,
                    numeric[kind],
                    atol=2e-7,
                    err_msg=f"{name} {frame} {kind} seed {seed} q {q.tolist()}",
                )
                assert analytic.angular.shape == (3, model.dof) and analytic.linear.shape == (3, model.dof)


def test_joint_frame_jacobian_ignores_joints_beyond_it():
    model = load_robot("genova7")
    q = model.initial_positions
    j3 = jacobian(model, q, 3)
    assert np.all(j3.matrix[:, 3:] == 0.0)
    assert np.linalg.norm(j3.matrix[:, :3]) > 0.1


# --- bad input ------------------------------------------------------------------------------


def test_wrong_joint_count_and_non_finite_values_are_rejected():
    model = load_robot("irb120")
    with pytest.raises(JointCountError, match="has 5 values, the robot has 6 joints"):
        frame_pose(model, np.zeros(5))
    with pytest.raises(NonFiniteError, match="NaN or infinity"):
        frame_pose(model, [0, 0, np.nan, 0, 0, 0])


def test_unknown_frame_lists_the_valid_ones():
    model = load_robot("irb120")
    with pytest.raises(UnknownFrameError) as error:
        frame_pose(model, np.zeros(6), "tool")  # irb120 has no tool
    assert "valid frames: base, 1, 2, 3, 4, 5, 6, ee" in str(error.value)


# --- the unrolled fast path against the numpy chain --------------------------------------------


@pytest.mark.parametrize("name", ROBOTS + ["panda"])
def test_unrolled_pose_and_jacobian_match_the_numpy_chain(name):
    from manip_kin.core.kinematics import geometric_jacobian_from_data, pose_and_jacobian_in_base

    model = _model(name)
    data = KinematicsData(model)
    rng = np.random.default_rng(9)
    for _ in range(10):
        q = model.random_configuration(rng)
        forward_kinematics(model, data, q)
        frames = all_frames(model, data)
        for index in range(len(model.frame_names)):
            pose, geometric = pose_and_jacobian_in_base(model, q, index)
            np.testing.assert_allclose(pose, frames[index], atol=1e-12)
            np.testing.assert_allclose(geometric, geometric_jacobian_from_data(model, data, index), atol=1e-12)
