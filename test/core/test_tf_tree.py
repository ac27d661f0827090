"""TF from a URDF and a joint state (manip_kin.core.tf_tree) against the model's forward kinematics.

The expected poses come from the compiled kinematics of the model (an independent code
path: unrolled chain arithmetic), the transforms from the URDF that robot_state
publishes, composed link by link as a TF listener would.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from robot_data_files import example_robot_data_urdf
from rosbags.typesys import Stores, get_typestore

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import bundled_robot_names, load_robot
from manip_kin.core.tf_tree import (
    LinkTransform,
    LinkTree,
    StampDecimator,
    compose,
    joint_positions,
    moving_transforms,
    static_transforms,
)
from manip_kin.core.urdf import load_urdf, model_to_urdf
from manip_kin.errors import InvalidArgumentError, ModelFileError
from manip_kin.recording.tf_message import TF_MESSAGE_TYPE, encode_tf_message
from manip_kin.recording.type_hash import type_hash

ROBOTS = bundled_robot_names()


def _tree_poses(model, q, prefix=""):
    tree = LinkTree.from_urdf(model_to_urdf(model))
    transforms = static_transforms(tree, prefix) + moving_transforms(tree, dict(zip(model.joint_names, q)), prefix)
    return tree, transforms, compose(transforms, prefix + tree.root)


@pytest.mark.parametrize("robot", ROBOTS)
@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_composed_tree_puts_every_frame_where_fk_does(robot, seed):
    model = load_robot(robot)
    q = model.random_configuration(np.random.default_rng(seed))
    tree, transforms, poses = _tree_poses(model, q)
    assert tree.root == model.base_frame
    # One transform per movable joint on /tf, every fixed joint on /tf_static.
    assert len(moving_transforms(tree, dict(zip(model.joint_names, q)))) == model.dof
    names = ["ee"] + (["tool"] if model.has_tool else [])
    for name in names:
        np.testing.assert_allclose(poses[name], frame_pose(model, q, name), atol=1e-12)
    for index, joint in enumerate(model.joints, start=1):
        if np.allclose(joint.child_offset, np.eye(4)):  # DH frames sit on a fixed child link
            np.testing.assert_allclose(
                poses[joint.link_name or f"link{index}"], frame_pose(model, q, index), atol=1e-12
            )


def test_frame_prefix_prefixes_every_frame_id():
    model = load_robot("genova7")
    q = model.start_configuration()
    _, transforms, poses = _tree_poses(model, q, prefix="arm1/")
    assert all(t.parent.startswith("arm1/") and t.child.startswith("arm1/") for t in transforms)
    np.testing.assert_allclose(poses["arm1/tool"], frame_pose(model, q, "tool"), atol=1e-12)


def test_unknown_joint_names_are_ignored_and_missing_joints_left_out():
    model = load_robot("irb120")
    tree = LinkTree.from_urdf(model_to_urdf(model))
    positions = dict(zip(model.joint_names, [0.1] * model.dof))
    positions.update({"gripper_joint": 0.3, "wheel": 2.0})
    assert [t.child for t in moving_transforms(tree, positions)] == [j.child for j in tree.movable]
    del positions[model.joint_names[2]]
    children = [t.child for t in moving_transforms(tree, positions)]
    assert len(children) == model.dof - 1
    assert tree.movable[2].child not in children


def test_joint_positions_drops_non_finite_values():
    assert joint_positions(["a", "b", "c"], [1.0, math.nan, math.inf]) == {"a": 1.0}


def test_panda_mimic_finger_follows_its_leader_and_arm_matches_fk():
    path = example_robot_data_urdf("panda_description/urdf/panda.urdf")
    tree = LinkTree.from_urdf(path.read_text())
    arm = load_urdf(path)
    rng = np.random.default_rng(7)
    q = arm.random_configuration(rng)
    positions = dict(zip(arm.joint_names, q)) | {"panda_finger_joint1": 0.03}
    transforms = static_transforms(tree) + moving_transforms(tree, positions)
    poses = compose(transforms, tree.root)
    np.testing.assert_allclose(poses["panda_hand"], frame_pose(arm, q, "ee"), atol=1e-12)
    # finger_joint2 mimics finger_joint1: the fingers open symmetrically, 2 x 0.03 m apart.
    hand = np.linalg.inv(poses["panda_hand"])
    left, right = ((hand @ poses[name])[:3, 3] for name in ("panda_leftfinger", "panda_rightfinger"))
    assert abs(np.linalg.norm(left - right) - 0.06) < 1e-12


def test_bad_urdf_names_the_source():
    with pytest.raises(ModelFileError, match="robot_description"):
        LinkTree.from_urdf("<robot name='x'><link name='a'/><joint name='j'/></robot>")


def test_decimator_takes_stamps_a_period_apart():
    decimator = StampDecimator(50.0)
    stamps = [0, 5_000_000, 19_999_999, 20_000_000, 21_000_000, 45_000_000, 60_000_000, 64_999_999, 65_000_000]
    taken = [s for s in stamps if decimator.due(s)]
    assert taken == [0, 20_000_000, 45_000_000, 65_000_000]
    assert decimator.due(10_000_000)  # a stamp from before (a restarted clock) starts over
    with pytest.raises(InvalidArgumentError):
        StampDecimator(0.0)


TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(
    stamp_ns=st.integers(0, 2**31 * 10**9 - 1),
    names=st.lists(st.text(min_size=0, max_size=9), min_size=0, max_size=4),
)
def test_tf_message_cdr_is_what_rosbags_decodes(stamp_ns, names):
    rng = np.random.default_rng(len(names))
    transforms = []
    for i, name in enumerate(names):
        quat = rng.normal(size=4)
        transforms.append(LinkTransform(f"p{i}{name}", name, rng.normal(size=3), quat / np.linalg.norm(quat)))
    data = encode_tf_message(stamp_ns, transforms)
    decoded = TYPESTORE.deserialize_cdr(data, TF_MESSAGE_TYPE)
    assert len(decoded.transforms) == len(transforms)
    for got, sent in zip(decoded.transforms, transforms):
        assert (got.header.stamp.sec, got.header.stamp.nanosec) == divmod(stamp_ns, 10**9)
        assert (got.header.frame_id, got.child_frame_id) == (sent.parent, sent.child)
        t, r = got.transform.translation, got.transform.rotation
        assert [t.x, t.y, t.z] == sent.translation.tolist()
        assert [r.x, r.y, r.z, r.w] == sent.rotation_xyzw.tolist()
    # rosbags' own encoder writes the same bytes.
    assert TYPESTORE.serialize_cdr(decoded, TF_MESSAGE_TYPE) == data


def test_tf_message_type_hash_equals_rosbags():
    assert type_hash(TF_MESSAGE_TYPE) == TYPESTORE.hash_rihs01(TF_MESSAGE_TYPE)


def test_tf_message_decodes_to_what_was_encoded():
    from manip_kin.recording.tf_message import decode_tf_message

    transforms = [LinkTransform("base_link", "link1", np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.6, 0.0, 0.8]))] * 2
    decoded = decode_tf_message(encode_tf_message(1_700_000_000_123_456_789, transforms))
    assert [s for s, _ in decoded] == [1_700_000_000_123_456_789] * 2
    assert all(t.parent == "base_link" and t.child == "link1" for _, t in decoded)
    np.testing.assert_array_equal(decoded[1][1].rotation_xyzw, [0.0, 0.6, 0.0, 0.8])
    big_endian = TYPESTORE.serialize_cdr(
        TYPESTORE.deserialize_cdr(encode_tf_message(5, transforms), TF_MESSAGE_TYPE),
        TF_MESSAGE_TYPE,
        little_endian=False,
    )
    assert [t.translation.tolist() for _, t in decode_tf_message(big_endian)] == [[0.1, -0.2, 0.3]] * 2
