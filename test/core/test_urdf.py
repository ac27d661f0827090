"""URDF loading and export, checked against FK computed independently in this file.

The reference FK here walks the XML itself (ElementTree) and multiplies
``origin(xyz, rpy) · motion(axis, q)`` with its own rotation matrices and Rodrigues
formula; it shares no code with :mod:`manip_kin.core.rotations` or :mod:`manip_kin.core.kinematics`.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from robot_data_files import example_robot_data_urdf

from manip_kin.core.kinematics import frame_pose, frame_poses
from manip_kin.core.model import Joint, JointType, RobotModel
from manip_kin.core.urdf import load_urdf, load_urdf_string, model_to_urdf
from manip_kin.errors import ModelFileError

DATA = Path(__file__).resolve().parents[1] / "data"
SMALL_ARM = DATA / "small_arm.urdf"
PANDA = "panda_description/urdf/panda.urdf"
UR5 = "ur_description/urdf/ur5_robot.urdf"


# --- independent reference FK ----------------------------------------------------------------


def _rx(a):
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def _ry(a):
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def _rz(a):
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def _rodrigues(axis, angle):
    """Rotation by ``angle`` about unit ``axis``: I + sin K + (1 - cos) K²."""
    kx, ky, kz = axis
    k = np.array([[0, -kz, ky], [kz, 0, -kx], [-ky, kx, 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _homogeneous(rotation=None, translation=(0, 0, 0)):
    t = np.eye(4)
    t[:3, :3] = np.eye(3) if rotation is None else rotation
    t[:3, 3] = translation
    return t


def _origin(xyz, rpy):
    roll, pitch, yaw = rpy
    return _homogeneous(_rz(yaw) @ _ry(pitch) @ _rx(roll), xyz)


def naive_link_poses(xml_text: str, positions: dict[str, float]) -> dict[str, np.ndarray]:
    """Pose in the root link of every link of a URDF tree; joints not in ``positions`` are at 0."""
    robot = ET.fromstring(xml_text)
    children: dict[str, list[ET.Element]] = {}
    child_links = set()
    for joint in robot.findall("joint"):
        children.setdefault(joint.find("parent").get("link"), []).append(joint)
        child_links.add(joint.find("child").get("link"))
    (root,) = [link.get("name") for link in robot.findall("link") if link.get("name") not in child_links]
    poses = {root: np.eye(4)}
    stack = [root]
    while stack:
        parent = stack.pop()
        for joint in children.get(parent, []):
            origin = joint.find("origin")
            xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()] if origin is not None else [0, 0, 0]
            rpy = [float(v) for v in origin.get("rpy", "0 0 0").split()] if origin is not None else [0, 0, 0]
            axis_element = joint.find("axis")
            axis = np.array([1.0, 0, 0])  # the URDF default
            if axis_element is not None:
                axis = np.array([float(v) for v in axis_element.get("xyz").split()])
            axis = axis / np.linalg.norm(axis)
            q = positions.get(joint.get("name"), 0.0)
            motion = np.eye(4)
            if joint.get("type") in ("revolute", "continuous"):
                motion = _homogeneous(_rodrigues(axis, q))
            elif joint.get("type") == "prismatic":
                motion = _homogeneous(translation=axis * q)
            child = joint.find("child").get("link")
            poses[child] = poses[parent] @ _origin(xyz, rpy) @ motion
            stack.append(child)
    return poses


def assert_model_matches_naive(model: RobotModel, xml_text: str, q, tip_link: str, atol=1e-12):
    """Every joint frame (by link name) and ee (at ``tip_link``) agree with the naive FK."""
    reference = naive_link_poses(xml_text, dict(zip(model.joint_names, q)))
    base_inverse = np.linalg.inv(reference[model.base_frame])
    frames = frame_poses(model, q)
    for index, joint in enumerate(model.joints, start=1):
        expected = base_inverse @ reference[joint.link_name]
        np.testing.assert_allclose(frames[index], expected, atol=atol, err_msg=joint.link_name)
    np.testing.assert_allclose(frames[model.dof + 1], base_inverse @ reference[tip_link], atol=atol)


def random_q(model: RobotModel, rng) -> np.ndarray:
    return model.random_configuration(rng)


# --- the hand-written arm --------------------------------------------------------------------


def hand_built_small_arm() -> RobotModel:
    """test/data/small_arm.urdf built joint by joint, fixed joints folded by hand."""
    mount = _origin([0.1, -0.2, 0.05], [0, 0, 0.3])
    bracket = _origin([0.02, 0, 0.1], [0.1, 0.2, 0.3])
    tail = _origin([0, 0, 0.08], [0, 0, -0.785]) @ _origin([0.01, 0, 0.1], [0.2, 0, 0])
    joints = (
        Joint(
            "j1",
            JointType.REVOLUTE,
            mount @ _origin([0, 0, 0.15], [0, 0, 0]),
            np.array([0, 0, 1.0]),
            -2.5,
            2.5,
            1.5,
            link_name="link1",
        ),
        Joint(
            "j2",
            JointType.REVOLUTE,
            bracket @ _origin([0, 0.03, 0.02], [0.5, 0, 0]),
            np.array([0, 1.0, 0]),
            -1.9,
            1.2,
            1.25,
            link_name="link2",
        ),
        Joint(
            "j3",
            JointType.PRISMATIC,
            _origin([0.3, 0, 0], [0, 0, 0]),
            np.array([1, 1, 0]) / math.sqrt(2),
            0.0,
            0.25,
            0.5,
            link_name="link3",
        ),
        Joint(
            "j4",
            JointType.REVOLUTE,
            _origin([0.05, 0.01, -0.02], [-0.4, 0.7, 1.1]),
            np.array([1.0, 0, 0]),
            -math.inf,
            math.inf,
            3.0,
            link_name="link4",
        ),
        Joint(
            "j5",
            JointType.REVOLUTE,
            _origin([0.12, 0, 0], [3.0, -1.2, 0.4]),
            np.array([0.2, -0.3, 0.9]) / np.linalg.norm([0.2, -0.3, 0.9]),
            -3.0,
            3.0,
            2.5,
            link_name="link5",
        ),
    )
    return RobotModel(name="small_arm", joints=joints, ee_offset=tail, base_frame="world")


@pytest.fixture(scope="module")
def small_arm() -> RobotModel:
    return load_urdf(SMALL_ARM)


def test_small_arm_structure(small_arm):
    assert small_arm.name == "small_arm"
    assert small_arm.base_frame == "world"
    assert small_arm.source == str(SMALL_ARM)
    assert small_arm.joint_names == ["j1", "j2", "j3", "j4", "j5"]
    revolute, prismatic = JointType.REVOLUTE, JointType.PRISMATIC
    assert [j.type for j in small_arm.joints] == [revolute, revolute, prismatic, revolute, revolute]
    assert [j.link_name for j in small_arm.joints] == ["link1", "link2", "link3", "link4", "link5"]
    np.testing.assert_allclose(small_arm.lower, [-2.5, -1.9, 0.0, -math.inf, -3.0])
    np.testing.assert_allclose(small_arm.upper, [2.5, 1.2, 0.25, math.inf, 3.0])
    np.testing.assert_allclose(small_arm.velocity_limits, [1.5, 1.25, 0.5, 3.0, 2.5])
    np.testing.assert_allclose(small_arm.joints[2].axis, np.array([1, 1, 0]) / math.sqrt(2))
    np.testing.assert_allclose(small_arm.joints[3].axis, [1, 0, 0])  # URDF default axis


def test_small_arm_matches_hand_built_and_naive_fk(small_arm):
    hand_built = hand_built_small_arm()
    xml_text = SMALL_ARM.read_text()
    rng = np.random.default_rng(7)
    for q in [np.zeros(5)] + [random_q(small_arm, rng) for _ in range(25)]:
        np.testing.assert_allclose(frame_poses(small_arm, q), frame_poses(hand_built, q), atol=1e-12)
        assert_model_matches_naive(small_arm, xml_text, q, tip_link="tcp")


def test_small_arm_default_tip_skips_decorative_branch_and_ends_at_tcp(small_arm):
    # link2 has two children; only j3 leads on to movable joints, so the walk goes on to tcp.
    pose = naive_link_poses(SMALL_ARM.read_text(), {})
    np.testing.assert_allclose(frame_pose(small_arm, np.zeros(5), "ee"), pose["tcp"], atol=1e-12)


def test_small_arm_partial_chains(small_arm):
    xml_text = SMALL_ARM.read_text()
    middle = load_urdf_string(xml_text, source="inline", base_link="link1", tip_link="link4")
    assert middle.joint_names == ["j2", "j3", "j4"]
    assert middle.base_frame == "link1"
    rng = np.random.default_rng(3)
    for _ in range(10):
        assert_model_matches_naive(middle, xml_text, random_q(middle, rng), tip_link="link4")
    with_tool = load_urdf(SMALL_ARM, tip_link="link5", tool_link="tcp")
    q = random_q(with_tool, rng)
    np.testing.assert_allclose(frame_pose(with_tool, q, "tool"), frame_pose(small_arm, q, "ee"), atol=1e-12)
    np.testing.assert_allclose(frame_pose(with_tool, q, "ee"), frame_pose(small_arm, q, "link5"), atol=1e-12)


# --- example-robot-data ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def panda_path() -> Path:
    return example_robot_data_urdf(PANDA)


def _file_limits(path: Path) -> dict[str, dict[str, float]]:
    robot = ET.parse(path).getroot()
    return {
        joint.get("name"): {key: float(value) for key, value in joint.find("limit").attrib.items()}
        for joint in robot.findall("joint")
        if joint.find("limit") is not None
    }


def test_example_robot_data_urdf_locates_and_reports_missing_files(panda_path):
    assert panda_path.is_file() and panda_path.name == "panda.urdf"
    with pytest.raises(FileNotFoundError, match="no_such_robot"):
        example_robot_data_urdf("no_such_robot/urdf/x.urdf")


def test_panda_loads_with_seven_joints_and_file_limits(panda_path):
    panda = load_urdf(panda_path)
    assert panda.dof == 7
    assert panda.joint_names == [f"panda_joint{i}" for i in range(1, 8)]
    assert panda.base_frame == "panda_link0"
    limits = _file_limits(panda_path)
    for joint in panda.joints:
        assert joint.lower == limits[joint.name]["lower"]
        assert joint.upper == limits[joint.name]["upper"]
        assert joint.velocity_limit == limits[joint.name]["velocity"]
    assert (panda.joints[3].lower, panda.joints[3].upper) == (-3.0718, -0.0698)


def test_panda_default_tip_is_the_hand(panda_path):
    panda = load_urdf(panda_path)
    reference = naive_link_poses(panda_path.read_text(), {})
    np.testing.assert_allclose(frame_pose(panda, np.zeros(7), "ee"), reference["panda_hand"], atol=1e-12)


@pytest.mark.parametrize("tip_link", [None, "panda_hand_tcp", "panda_link8", "panda_leftfinger"])
def test_panda_fk_matches_naive(panda_path, tip_link):
    panda = load_urdf(panda_path, tip_link=tip_link)
    xml_text = panda_path.read_text()
    rng = np.random.default_rng(11)
    for q in [np.zeros(panda.dof)] + [random_q(panda, rng) for _ in range(20)]:
        assert_model_matches_naive(panda, xml_text, q, tip_link=tip_link or "panda_hand")


def test_panda_finger_chain_adds_prismatic_joint(panda_path):
    panda = load_urdf(panda_path, tip_link="panda_leftfinger")
    assert panda.dof == 8
    assert panda.joints[-1].type is JointType.PRISMATIC
    np.testing.assert_allclose(panda.joints[-1].axis, [0, 1, 0])


def test_panda_mimic_finger_is_rejected_naming_the_joint(panda_path):
    with pytest.raises(ModelFileError) as caught:
        load_urdf(panda_path, tip_link="panda_rightfinger")
    assert caught.value.field == "joint[panda_finger_joint2]/mimic"
    assert str(panda_path) in str(caught.value)


def test_ur5_loads_as_six_dof():
    path = example_robot_data_urdf(UR5)
    ur5 = load_urdf(path)
    assert ur5.dof == 6
    assert ur5.joint_names == [
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ]
    # world -> base_link branches into the arm and the fixed "base" frame; the walk
    # follows the arm and stops at wrist_3_link, where ee_link and tool0 branch.
    assert ur5.base_frame == "world"
    assert ur5.joints[-1].link_name == "wrist_3_link"
    np.testing.assert_array_equal(ur5.ee_offset, np.eye(4))
    flange = load_urdf(path, base_link="base_link", tip_link="tool0")
    rng = np.random.default_rng(5)
    for q in [np.zeros(6)] + [random_q(flange, rng) for _ in range(10)]:
        assert_model_matches_naive(flange, path.read_text(), q, tip_link="tool0")


# --- export and round trip -------------------------------------------------------------------


def _dh(d, theta, a, alpha):
    return _homogeneous(_rz(theta), [0, 0, d]) @ _homogeneous(_rx(alpha), [a, 0, 0])


def dh_like_model() -> RobotModel:
    """A DH-style model (frame i at the end of link i via child_offset), with a tool."""
    joints = (
        Joint(
            "theta1", JointType.REVOLUTE, _dh(0.4, 0, 0, math.pi / 2), child_offset=_dh(0, 0, 0.3, 0), link_name="arm1"
        ),
        Joint(
            "d2",
            JointType.PRISMATIC,
            np.eye(4),
            lower=-0.5,
            upper=0.5,
            velocity_limit=0.5,
            child_offset=_dh(0.2, math.pi / 2, 0, math.pi / 2),
            link_name="arm2",
        ),
        Joint("theta3", JointType.REVOLUTE, np.eye(4), child_offset=_dh(0.1, 0.3, 0.05, -0.7)),
    )
    return RobotModel(
        name="dh_like",
        joints=joints,
        ee_offset=_origin([0, 0, 0.02], [0, 0, 0.1]),
        tool=_origin([0.3, 0.1, 0], [math.pi / 6, 0, math.pi / 10]),
        base_frame="base_link",
    )


def joint_list_model() -> RobotModel:
    """Origins with rotations (one a hair off gimbal lock), non-z axes, a continuous joint."""
    joints = (
        Joint("a", JointType.REVOLUTE, _origin([0, 0, 0.1], [0, 0, 0]), lower=-math.inf, upper=math.inf),
        Joint(
            "b",
            JointType.REVOLUTE,
            _origin([0.1, 0, 0.2], [0.3, math.pi / 2 - 1e-10, -0.8]),
            axis=np.array([0, 1.0, 0]),
        ),
        Joint(
            "c",
            JointType.PRISMATIC,
            _origin([0, 0.05, 0.3], [0, math.pi / 2, 0]),
            axis=np.array([0.6, 0, 0.8]),
            lower=0.0,
            upper=0.3,
        ),
        Joint("d", JointType.REVOLUTE, _origin([0.2, 0, 0], [1.0, -0.5, 2.0]), axis=np.array([1.0, 0, 0])),
    )
    return RobotModel(name="joint_list", joints=joints, tool=_origin([0, 0, 0.1], [0, 0.2, 0]))


def _bundled_models() -> list:
    from manip_kin.core.robots import bundled_robot_names

    return [pytest.param(name, id=name) for name in bundled_robot_names()]


def _reload(model: RobotModel) -> RobotModel:
    return load_urdf_string(model_to_urdf(model), tip_link="ee", tool_link="tool" if model.has_tool else None)


def assert_round_trip(model: RobotModel, configurations):
    text = model_to_urdf(model)
    again = _reload(model)
    assert again.joint_names == model.joint_names
    assert again.base_frame == model.base_frame
    assert again.has_tool == model.has_tool
    assert [j.type for j in again.joints] == [j.type for j in model.joints]
    np.testing.assert_array_equal(again.velocity_limits, model.velocity_limits)
    np.testing.assert_array_equal(again.lower, model.lower)
    np.testing.assert_array_equal(again.upper, model.upper)
    for q in configurations:
        original = frame_poses(model, q)
        reloaded = frame_poses(again, q)
        n = model.dof
        np.testing.assert_allclose(reloaded[n + 1 :], original[n + 1 :], atol=1e-12)  # ee, tool
        for i, joint in enumerate(model.joints, start=1):
            # URDF puts a link on its joint: a DH frame comes back as the moving joint frame.
            moving = original[i] @ np.linalg.inv(joint.child_offset)
            np.testing.assert_allclose(reloaded[i], moving, atol=1e-12, err_msg=joint.name)
        # The exported links themselves sit at the model's frames (what RViz draws).
        links = naive_link_poses(text, dict(zip(model.joint_names, q)))
        for i, joint in enumerate(model.joints, start=1):
            np.testing.assert_allclose(links[joint.link_name or f"link{i}"], original[i], atol=1e-12)
        np.testing.assert_allclose(links["ee"], original[n + 1], atol=1e-12)
        if model.has_tool:
            np.testing.assert_allclose(links["tool"], original[n + 2], atol=1e-12)


@pytest.mark.parametrize("build", [dh_like_model, joint_list_model, hand_built_small_arm])
def test_round_trip_hand_built_models(build):
    model = build()
    rng = np.random.default_rng(19)
    assert_round_trip(model, [np.zeros(model.dof)] + [random_q(model, rng) for _ in range(10)])


@pytest.mark.parametrize("name", _bundled_models())
def test_round_trip_bundled_robots(name):
    from manip_kin.core.robots import load_robot

    model = load_robot(name)
    rng = np.random.default_rng(23)
    assert_round_trip(model, [model.start_configuration()] + [random_q(model, rng) for _ in range(10)])


def test_round_trip_panda(panda_path):
    panda = load_urdf(panda_path, tip_link="panda_hand_tcp")
    rng = np.random.default_rng(29)
    assert_round_trip(panda, [random_q(panda, rng) for _ in range(10)])


_angles = st.floats(-math.pi, math.pi, allow_nan=False)
_near_gimbal = st.sampled_from([0.0, 1e-13, 1e-11, 1e-9, 3e-9, 1e-6]).map(lambda eps: math.pi / 2 - eps)


@settings(max_examples=60, deadline=None)
@given(
    roll=_angles,
    yaw=_angles,
    pitch=st.one_of(_angles.map(lambda a: a / 2), _near_gimbal),
    sign=st.sampled_from([1.0, -1.0]),
    q=st.lists(_angles, min_size=2, max_size=2),
)
def test_round_trip_origin_rotations_including_gimbal_lock(roll, pitch, yaw, sign, q):
    origin = _origin([0.1, -0.2, 0.3], [roll, sign * pitch, yaw])
    model = RobotModel(
        name="r",
        joints=(Joint("j1", JointType.REVOLUTE, origin), Joint("j2", JointType.REVOLUTE, origin)),
        ee_offset=origin,
    )
    assert_round_trip(model, [np.array(q)])


def test_export_names_and_joint_types():
    model = dh_like_model()
    robot = ET.fromstring(model_to_urdf(model))
    joints = {j.get("name"): j for j in robot.findall("joint")}
    assert {"theta1", "d2", "theta3", "ee_joint", "tool_joint"} <= set(joints)
    assert joints["theta1"].get("type") == "revolute"
    assert joints["d2"].get("type") == "prismatic"
    assert joints["theta1_offset"].get("type") == "fixed"
    assert joints["theta1_offset"].find("parent").get("link") == "arm1_joint_frame"
    assert joints["theta1_offset"].find("child").get("link") == "arm1"
    limit = joints["d2"].find("limit").attrib
    assert {"lower", "upper", "velocity", "effort"} <= set(limit)
    assert (float(limit["lower"]), float(limit["upper"]), float(limit["velocity"])) == (-0.5, 0.5, 0.5)
    continuous = ET.fromstring(model_to_urdf(joint_list_model())).find("joint[@name='a']")
    assert continuous.get("type") == "continuous"
    links = [link.get("name") for link in robot.findall("link")]
    assert len(links) == len(set(links))
    assert {"base_link", "arm1", "arm2", "link3", "ee", "tool"} <= set(links)


def test_export_visuals_draw_every_segment_and_joint():
    model = joint_list_model()
    robot = ET.fromstring(model_to_urdf(model))
    links = {link.get("name"): link for link in robot.findall("link")}
    for joint in robot.findall("joint"):
        parent = links[joint.find("parent").get("link")]
        child = links[joint.find("child").get("link")]
        end = np.array([float(v) for v in joint.find("origin").get("xyz").split()])
        cylinders = []
        for visual in parent.findall("visual"):
            cylinder = visual.find("geometry/cylinder")
            if cylinder is None:
                continue
            origin = visual.find("origin")
            xyz = np.array([float(v) for v in origin.get("xyz").split()])
            pose = _origin(xyz, [float(v) for v in origin.get("rpy").split()])
            half = pose[:3, 2] * float(cylinder.get("length")) / 2
            cylinders.append((xyz - half, xyz + half))
        if np.linalg.norm(end) > 1e-6:
            drawn = [np.allclose(a, 0, atol=1e-12) and np.allclose(b, end, atol=1e-12) for a, b in cylinders]
            assert any(drawn), joint.get("name")
        if joint.get("type") != "fixed":
            assert child.find("visual/geometry/sphere") is not None


# --- errors ----------------------------------------------------------------------------------

_TWO_JOINTS = """<robot name="t">
  <link name="base"/><link name="a"/><link name="b"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1"/></joint>
  <joint name="j2" type="{type}"><parent link="a"/><child link="b"/>
    <origin xyz="{xyz}"/><axis xyz="0 1 0"/><limit {limit}/>{extra}</joint>
</robot>"""


def _two_joints(type="revolute", xyz="0 0 0.2", extra="", limit='lower="-1" upper="1" velocity="1"'):
    """A base and two revolute joints; the arguments change the second joint, j2."""
    return _TWO_JOINTS.format(type=type, xyz=xyz, extra=extra, limit=limit)


_ERROR_CASES = {
    # id: (URDF text, load_urdf keyword arguments, field named in the error, words in the message)
    "malformed": ("<robot><link name='a'></robot>", {}, "line 1, column 25", "malformed XML: mismatched tag"),
    "not-a-robot": ("<model/>", {}, "robot", "<robot>"),
    "unknown-tip": (_two_joints(), {"tip_link": "hand"}, "tip_link", "unknown link 'hand'"),
    "unknown-base": (_two_joints(), {"base_link": "nowhere"}, "base_link", "unknown link 'nowhere'"),
    "tip-above-base": (_two_joints(), {"base_link": "a", "tip_link": "base"}, "tip_link", "not below"),
    "floating": (_two_joints(type="floating"), {}, "joint[j2]@type", "floating joints are not supported"),
    "planar": (_two_joints(type="planar"), {}, "joint[j2]@type", "planar joints are not supported"),
    "unknown-type": (_two_joints(type="hinge"), {}, "joint[j2]@type", "valid: revolute"),
    "mimic": (_two_joints(extra="<mimic joint='j1'/>"), {}, "joint[j2]/mimic", "mimic joints"),
    "non-numeric-xyz": (
        _two_joints(xyz="0 zero 0.2"),
        {},
        "joint[j2]/origin@xyz",
        "'0 zero 0.2' is not numeric",
    ),
    "short-xyz": (_two_joints(xyz="0 0"), {}, "joint[j2]/origin@xyz", "valid: 3 numbers"),
    "xacro": (_two_joints(xyz="${l} 0 0"), {}, "joint[j2]/origin@xyz", "run xacro"),
    "missing-link": (
        _two_joints().replace('<child link="b"/>', '<child link="c"/>'),
        {},
        "joint[j2]/child@link",
        "'c' is not a <link>",
    ),
    "zero-axis": (
        _two_joints().replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'),
        {},
        "joint[j2]/axis@xyz",
        "zero length",
    ),
    "no-movable-joint": (
        _two_joints(type="fixed").replace('type="revolute"', 'type="fixed"'),
        {},
        "tip_link",
        "no movable joint",
    ),
    "two-roots": (
        _two_joints().replace("</robot>", "<link name='island'/></robot>"),
        {},
        "base_link",
        "several root links",
    ),
    "negative-velocity": (
        _two_joints(limit='lower="-1" upper="1" velocity="-1"'),
        {},
        "joint[j2]/limit@velocity",
        "valid: a speed >= 0",
    ),
    "inverted-limits": (
        _two_joints(limit='lower="1" upper="-1" velocity="1"'),
        {},
        "joint[j2]/limit",
        "lower 1.0 > upper -1.0",
    ),
    "non-numeric-limit": (
        _two_joints(limit='lower="-1" upper="one" velocity="1"'),
        {},
        "joint[j2]/limit@upper",
        "'one' is not numeric",
    ),
}


@pytest.mark.parametrize(("text", "kwargs", "field", "words"), list(_ERROR_CASES.values()), ids=list(_ERROR_CASES))
def test_errors_name_file_and_field(tmp_path, text, kwargs, field, words):
    path = tmp_path / "broken_arm.urdf"
    path.write_text(text)
    with pytest.raises(ModelFileError) as caught:
        load_urdf(path, **kwargs)
    message = str(caught.value)
    assert caught.value.field == field
    assert str(path) in message
    assert f"'{field}'" in message
    assert words in message
    # The same text given as a string names the given source instead of a path.
    with pytest.raises(ModelFileError, match="^/robot_description: field"):
        load_urdf_string(text, source="/robot_description", **kwargs)


def test_missing_file_is_a_model_file_error(tmp_path):
    with pytest.raises(ModelFileError, match="nope.urdf.*cannot read"):
        load_urdf(tmp_path / "nope.urdf")


def test_errors_off_the_chain_do_not_block_the_arm(panda_path):
    # The mimic finger is below the default tip, so the arm itself loads.
    assert load_urdf(panda_path).dof == 7
