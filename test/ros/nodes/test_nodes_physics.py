"""robot_state on the MuJoCo plant: efforts, a box on collision_objects as a contact on /diagnostics, the
controller reaching a goal on physics, and robot_description as the URDF file given."""

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from node_harness import Harness, statuses
from robot_data_files import PANDA, example_robot_data_urdf
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.nodes.robot_state import RobotStateNode
from manip_kin.ros.wire.messages import make_pose_stamped

MODEL = load_robot("genova7")
Q0 = MODEL.start_configuration()


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def _values(status):
    return {kv.key: kv.value for kv in status.values}


def _box_marker(position, size=0.1):
    marker = Marker(ns="cell", id=7, type=Marker.CUBE, action=Marker.ADD)
    marker.header.frame_id = "base_link"
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = (float(v) for v in position)
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = size
    return MarkerArray(markers=[marker])


def test_a_box_on_collision_objects_shows_as_contact_force_on_diagnostics(harness):
    states = harness.collect(JointState, "/joint_states")
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    harness.start(
        RobotStateNode,
        robot="genova7",
        rate_hz=250.0,
        plant="mujoco",
        diagnostics_rate_hz=20.0,
        effort_limits=[40.0] * 7,
    )
    harness.wait_matched("/collision_objects", MarkerArray)
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    assert harness.spin_until(lambda: states, 5)
    assert len(states[-1].effort) == 7  # the servo torques
    turned = Q0.copy()
    turned[0] += 0.4
    harness.publish("/collision_objects", _box_marker(frame_pose(MODEL, turned, MODEL.dof)[:3, 3]))
    command = np.zeros(7)
    command[0] = 0.5

    def push():
        harness.publish("/joint_velocity_commands", Float64MultiArray(data=command.tolist()))

    def touching():
        return [s for s in statuses(diagnostics, "robot_state") if float(_values(s).get("contact_force_max", 0)) > 1.0]

    assert harness.spin_until(touching, 8, every=push), [_values(s) for s in statuses(diagnostics, "robot_state")[-1:]]
    status = touching()[-1]
    values = _values(status)
    assert values["plant"] == "mujoco" and values["obstacles"] == "1"
    assert values["contact_pair"].endswith("| cell/7") and int(values["contact_events"]) >= 1
    assert status.level == status.WARN and "contact" in status.message
    assert states[-1].position[0] < turned[0]  # held at the box


def test_the_controller_reaches_a_goal_on_the_physics_plant(harness):
    controller_rate = 250.0
    states = harness.collect(JointState, "/joint_states")
    harness.start(RobotStateNode, robot="genova7", rate_hz=500.0, plant="mujoco")
    node = harness.start(CartesianControllerNode, robot="genova7", rate_hz=controller_rate, joint_state_timeout=1.0)
    goal = frame_pose(MODEL, Q0)
    goal[:3, 3] += [0.03, 0.0, 0.03]
    harness.wait_matched("/goal_pose", make_pose_stamped(goal, "base_link").__class__)
    harness.publish("/goal_pose", make_pose_stamped(goal, "base_link"))
    # 4.2 cm at the default gain 0.8/s: the default tolerance 1e-4 m after ln(0.042/1e-4)/0.8 ≈ 7.5 s on a
    # perfect integrator; the servo's lag (5 ms) and its gravity sag (which the loop corrects) add little.
    assert harness.spin_until(lambda: node.state == "converged", 15), node.state
    # On physics: the drives carry the arm (gravity torques on the shoulder and elbow, genova7's joints 2 and 4).
    assert len(states[-1].effort) == 7 and abs(states[-1].effort[1]) > 1.0 and abs(states[-1].effort[3]) > 1.0


def test_robot_description_is_the_urdf_file_as_given(harness):
    path = example_robot_data_urdf(PANDA)
    text = path.read_text()
    descriptions = harness.collect(String, "/robot_description", latched=True)
    harness.start(RobotStateNode, robot=str(path), rate_hz=100.0)
    assert harness.spin_until(lambda: descriptions, 5)
    assert descriptions[-1].data == text  # panda_hand stays panda_hand, the fingers stay


def test_robot_description_names_the_chain_when_tip_link_chose_it(harness):
    path = example_robot_data_urdf(PANDA)
    descriptions = harness.collect(String, "/robot_description", latched=True)
    harness.start(RobotStateNode, robot=str(path), rate_hz=100.0, tip_link="panda_link8")
    assert harness.spin_until(lambda: descriptions, 5)
    from manip_kin.core.urdf import load_urdf_string

    published = descriptions[-1].data
    assert published.replace('  <manip_kin_chain tip_link="panda_link8"/>\n', "") == path.read_text()
    # A controller reading it without link names gets robot_state's chain (tip panda_link8, not panda_hand).
    np.testing.assert_allclose(
        load_urdf_string(published).ee_offset, load_robot(str(path), tip_link="panda_link8").ee_offset
    )
