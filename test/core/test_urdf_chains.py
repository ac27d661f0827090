"""Any URDF arm: the chain picked by base/tip/tool link, URDFs without velocity limits, through the CLI.

Expected poses are computed here from the URDF's numbers with plain rotation matrices,
never with manip_kin's own kinematics.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from robot_data_files import UR5, example_robot_data_urdf

from manip_kin.cli import main
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import bundled_robot_names, load_robot, with_velocity_limits
from manip_kin.core.urdf import joints_without_velocity_limit, load_urdf, load_urdf_string, model_to_urdf
from manip_kin.errors import InvalidArgumentError, ModelFileError
from manip_kin.ros.wire.validation import InvalidMessageError, JointStateMapper

TWO_ARMS = Path(__file__).resolve().parents[1] / "data" / "two_arms.urdf"


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def two_arm_tip(side: str, yaw: float, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and rotation of ``<side>_tip`` in ``torso`` from the URDF's numbers."""
    shoulder = np.array([0.0, 0.2 if side == "left" else -0.2, 0.1])
    rotation = _rz(yaw) @ _ry(pitch)
    position = shoulder + _rz(yaw) @ (np.array([0.0, 0.0, 0.3]) + _ry(pitch) @ np.array([0.25, 0.0, 0.0]))
    return position, rotation


def run_cli(capsys, argv) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# --- chain selection ----------------------------------------------------------------------------


def test_branching_tree_has_no_default_tip_and_the_error_names_the_candidates():
    with pytest.raises(ModelFileError) as caught:
        load_urdf(TWO_ARMS)
    message = str(caught.value)
    assert caught.value.field == "tip_link"
    assert "'left_tip'" in message and "'right_tip'" in message and "tip_link" in message and "--tip-link" in message
    assert "torso_marker" not in message  # a decorative fixed frame is no candidate


@pytest.mark.parametrize("side", ["left", "right"])
def test_tip_link_selects_one_arm_of_a_branching_tree(side):
    model = load_urdf(TWO_ARMS, tip_link=f"{side}_tip")
    assert model.joint_names == [f"{side}_yaw", f"{side}_pitch"] and model.base_frame == "torso"
    for yaw, pitch in [(0.0, 0.0), (0.7, -0.4), (-1.9, 1.3)]:
        position, rotation = two_arm_tip(side, yaw, pitch)
        pose = frame_pose(model, [yaw, pitch])
        np.testing.assert_allclose(pose[:3, 3], position, atol=1e-12)
        np.testing.assert_allclose(pose[:3, :3], rotation, atol=1e-12)


def test_base_and_tool_links_select_the_rest_of_the_chain():
    # From the shoulder link on, the left arm is one joint; the tip is a tool below left_upper.
    model = load_urdf(TWO_ARMS, base_link="left_shoulder", tip_link="left_upper", tool_link="left_tip")
    assert model.joint_names == ["left_pitch"] and model.has_tool
    pose = frame_pose(model, [0.5], "tool")
    np.testing.assert_allclose(pose[:3, 3], [0.0, 0.0, 0.3] + _ry(0.5) @ [0.25, 0.0, 0.0], atol=1e-12)
    with pytest.raises(ModelFileError, match="not below link 'left_shoulder'"):
        load_urdf(TWO_ARMS, base_link="left_shoulder", tip_link="right_tip")
    with pytest.raises(ModelFileError, match="unknown link 'left_hand'"):
        load_urdf(TWO_ARMS, tip_link="left_hand")  # a joint name, not a link


def test_ur5_default_chain_and_tool0():
    path = example_robot_data_urdf(UR5)
    default = load_urdf(path)
    assert default.dof == 6 and default.base_frame == "world"
    flange = load_urdf(path, base_link="base_link", tip_link="tool0")
    assert flange.joint_names == default.joint_names and flange.base_frame == "base_link"
    # tool0 is wrist_3_link turned by rpy (-pi/2, 0, 0) and moved 0.0823 m along its y axis.
    q = np.array([0.3, -1.1, 1.4, -0.6, 1.2, 0.4])
    wrist = frame_pose(default, q)  # default tip: wrist_3_link; world == base_link here
    np.testing.assert_allclose(frame_pose(flange, q)[:3, 3], wrist[:3, 3] + wrist[:3, :3] @ [0, 0.0823, 0], atol=1e-9)


# --- velocity limits -----------------------------------------------------------------------------


def test_missing_or_zero_velocity_limit_means_no_limit():
    model = load_urdf(TWO_ARMS, tip_link="right_tip")
    assert joints_without_velocity_limit(model) == ["right_yaw", "right_pitch"]
    assert np.all(np.isinf(model.velocity_limits))
    # Written back as velocity="0" (what many URDFs say for "not given"), read as no limit again.
    again = load_urdf_string(model_to_urdf(model), tip_link="ee")
    assert joints_without_velocity_limit(again) == ["right_yaw", "right_pitch"]
    # The control law runs without limits: the same rates as with limits too large to matter.
    goal = frame_pose(model, [0.4, 0.3])
    config = ControllerConfig(gain_linear=2.0, gain_angular=0.0, task="position")
    unlimited = CartesianController(model, config).step(np.zeros(2), goal, None, 0.002)
    huge = CartesianController(with_velocity_limits(model, [1e9, 1e9]), config).step(np.zeros(2), goal, None, 0.002)
    assert np.all(np.isfinite(unlimited.qdot)) and np.linalg.norm(unlimited.qdot) > 0.1
    np.testing.assert_allclose(unlimited.qdot, huge.qdot, rtol=1e-12)
    assert unlimited.velocity_scale == 1.0
    # velocity_limits supplies them: the same goal now saturates at 0.05 rad/s.
    slow = CartesianController(with_velocity_limits(model, [0.05, 0.05]), config).step(np.zeros(2), goal, None, 0.002)
    assert np.max(np.abs(slow.qdot)) == pytest.approx(0.05, rel=1e-12)


@pytest.mark.parametrize("limits", [[1.0], [1.0, 0.0], [1.0, math.nan]])
def test_velocity_limits_must_be_one_positive_speed_per_joint(limits):
    model = load_urdf(TWO_ARMS, tip_link="right_tip")
    with pytest.raises(InvalidArgumentError, match="velocity_limits"):
        with_velocity_limits(model, limits)


# --- joint states with more or fewer joints than the chain ------------------------------------------


def test_joint_states_extra_joints_ignored_missing_joint_named():
    from sensor_msgs.msg import JointState

    mapper = JointStateMapper(["left_yaw", "left_pitch"])
    msg = JointState(name=["gripper", "left_pitch", "right_yaw", "left_yaw"], position=[0.04, 0.2, 9.0, -0.3])
    np.testing.assert_array_equal(mapper.positions(msg), [-0.3, 0.2])
    with pytest.raises(InvalidMessageError, match="left_pitch"):
        mapper.positions(JointState(name=["left_yaw", "gripper"], position=[0.0, 0.0]))


# --- the CLI ------------------------------------------------------------------------------------


@pytest.mark.parametrize("robot", bundled_robot_names())
def test_cli_fk_of_every_bundled_robot_and_links_refused_for_yaml(capsys, robot):
    model = load_robot(robot)
    q = model.clip_to_limits(model.start_configuration() + 0.1)
    code, out, _ = run_cli(capsys, ["fk", "--robot", robot, "--q", *map(repr, q.tolist()), "--json"])
    assert code == 0
    np.testing.assert_allclose(json.loads(out)["matrix"], frame_pose(model, q), atol=1e-12)
    code, out, err = run_cli(capsys, ["fk", "--robot", robot, "--tip-link", "link2"])
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "tip_link='link2'" in err and "not a URDF" in err


def test_cli_selects_the_arm_of_a_branching_urdf(capsys):
    yaw, pitch = 0.6, -0.8
    position, rotation = two_arm_tip("left", yaw, pitch)
    argv = ["fk", "--robot", str(TWO_ARMS), "--tip-link", "left_tip", "--q", str(yaw), str(pitch), "--json"]
    code, out, _ = run_cli(capsys, argv)
    assert code == 0
    pose = np.array(json.loads(out)["matrix"])
    np.testing.assert_allclose(pose[:3, 3], position, atol=1e-12)
    np.testing.assert_allclose(pose[:3, :3], rotation, atol=1e-12)
    # Without --tip-link: one line, exit 2, the candidates and the flag to use.
    code, out, err = run_cli(capsys, ["fk", "--robot", str(TWO_ARMS), "--json"])
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "left_tip" in err and "right_tip" in err and "--tip-link" in err
    # jacobian and ik take the same flags; ik finds the configuration of that tip position.
    code, out, _ = run_cli(
        capsys, ["jacobian", "--robot", str(TWO_ARMS), "--tip-link", "left_tip", "--q", "0", "0", "--json"]
    )
    linear = np.array(json.loads(out)["linear"])
    np.testing.assert_allclose(linear[:, 0], [-0.0, 0.25, 0.0], atol=1e-12)  # z × (0.25, 0, 0.3) about the shoulder
    argv = ["ik", "--robot", str(TWO_ARMS), "--tip-link", "left_tip", "--xyz", *map(repr, position.tolist())]
    code, out, _ = run_cli(capsys, [*argv, "--task", "position", "--json"])
    assert code == 0
    found_position, _ = two_arm_tip("left", *json.loads(out)["q"])
    np.testing.assert_allclose(found_position, position, atol=1e-6)


def test_cli_warns_once_about_joints_without_velocity_limit(capsys):
    code, _, err = run_cli(capsys, ["fk", "--robot", str(TWO_ARMS), "--tip-link", "right_tip", "--q", "0", "0"])
    assert code == 0
    warnings = [line for line in err.splitlines() if "no velocity limit" in line]
    assert len(warnings) == 1 and "right_yaw, right_pitch" in warnings[0]


@pytest.mark.parametrize("robot", bundled_robot_names())
def test_exported_description_reads_back_with_its_own_chain_without_link_names(robot):
    # What cartesian_controller does with robot_state's robot_description: no link parameters.
    model = load_robot(robot)
    again = load_urdf_string(model_to_urdf(model))
    assert again.joint_names == model.joint_names and again.has_tool == model.has_tool
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = model.random_configuration(rng)
        for frame in ("ee", "tool") if model.has_tool else ("ee",):
            np.testing.assert_allclose(frame_pose(again, q, frame), frame_pose(model, q, frame), atol=1e-12)
    # Link names given explicitly win over the export's own chain.
    if model.has_tool:
        assert not load_urdf_string(model_to_urdf(model), tip_link="ee").has_tool


def test_every_command_taking_robot_takes_the_link_options():
    from manip_kin.cli import build_parser

    commands = build_parser()._subparsers._group_actions[0].choices
    with_robot = {name for name, parser in commands.items() if "--robot" in parser._option_string_actions}
    assert {"fk", "jacobian", "ik", "simulate", "move"} <= with_robot
    for name in with_robot:
        options = commands[name]._option_string_actions
        assert {"--base-link", "--tip-link", "--tool-link"} <= set(options), name


def test_cli_move_passes_the_link_options_to_the_model(capsys):
    # Refused before anything is sent: link names for a robot YAML.
    code, out, err = run_cli(capsys, ["move", "--robot", "scara", "--tip-link", "link2", "--q", "0", "0", "0", "0"])
    assert code == 2 and "tip_link='link2'" in err and "not a URDF" in err


def _arm_with_gripper(gripper_joint: str, gripper_link: str, below: str = "") -> str:
    return f"""<robot name="z">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="stator"/><link name="{gripper_link}"/>{below}
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" velocity="1"/></joint>
  <joint name="stator_mount" type="fixed"><parent link="l2"/><child link="stator"/><origin xyz="0.05 0 0"/></joint>
  <joint name="{gripper_joint}" type="revolute"><parent link="stator"/><child link="{gripper_link}"/>
    <origin xyz="0.05 0 0"/><axis xyz="0 1 0"/><limit lower="-1.5" upper="0" velocity="3"/></joint>
</robot>"""


@pytest.mark.parametrize("joint, link", [("jointGripper", "gripperMover"), ("j3", "left_finger"), ("jaw", "m")])
def test_default_chain_leaves_a_leaf_gripper_joint_out(joint, link):
    model = load_urdf_string(_arm_with_gripper(joint, link))
    assert model.joint_names == ["j1", "j2"]
    # The tip is the gripper's parent link: ee 0.05 m beyond l2, at the stator.
    np.testing.assert_allclose(frame_pose(model, [0.0, 0.0])[:3, 3], [0.05, 0.0, 0.3], atol=1e-12)
    assert load_urdf_string(_arm_with_gripper(joint, link), tip_link=link).joint_names == ["j1", "j2", joint]


def test_a_joint_named_like_a_gripper_stays_when_something_moves_below_it():
    below = '<link name="l4"/><joint name="j4" type="revolute"><parent link="gripperMover"/><child link="l4"/><limit lower="-1" upper="1" velocity="1"/></joint>'
    assert load_urdf_string(_arm_with_gripper("jointGripper", "gripperMover", below)).dof == 4
    # Not named like a gripper: a plain last joint stays.
    assert load_urdf_string(_arm_with_gripper("j3", "l3")).joint_names == ["j1", "j2", "j3"]


def test_robots_describes_a_urdf_file_with_its_chain(capsys, tmp_path):
    path = tmp_path / "z1_like.urdf"
    path.write_text(_arm_with_gripper("jointGripper", "gripperMover"))
    assert main(["robots", "--robot", str(path), "--json"]) == 0
    (robot,) = json.loads(capsys.readouterr().out)["robots"].values()
    assert robot["chain"] == ["base", "l1", "l2", "ee"] and robot["dof"] == 2
    assert robot["joints"][1] == {
        "name": "j2",
        "type": "revolute",
        "lower": -1.0,
        "upper": 1.0,
        "velocity": 1.0,
        "unit": "rad",
        "link": "l2",
    }
    assert main(["robots", "--robot", str(path), "--tip-link", "gripperMover"]) == 0
    text = capsys.readouterr().out
    assert "chain: base -> l1 -> l2 -> gripperMover -> ee" in text and "jointGripper" in text


def test_robots_json_has_null_for_infinite_limits(capsys, tmp_path):
    path = tmp_path / "c.urdf"
    path.write_text(
        '<robot name="c"><link name="a"/><link name="b"/><joint name="j" type="continuous">'
        '<parent link="a"/><child link="b"/></joint></robot>'
    )
    assert main(["robots", "--robot", str(path), "--json"]) == 0
    joint = json.loads(capsys.readouterr().out)["robots"]["c"]["joints"][0]
    assert (joint["lower"], joint["upper"], joint["velocity"]) == (None, None, None)
