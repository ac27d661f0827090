"""One model, loudly: two latched publishers of different URDFs, the parameter that picks one, a
later description that is logged and does not replace the model, and the switch on request.

The publishers are plain rclpy nodes with their own names (``/arm_a``, ``/arm_b``) in the
harness's context, each with a transient-local ``robot_description`` publisher.
"""

import dataclasses

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import PoseStamped
from node_harness import Harness
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot, with_velocity_limits
from manip_kin.core.urdf import model_to_urdf
from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.nodes.robot_description import publisher_matches
from manip_kin.ros.nodes.trajectory_generator import TrajectoryGeneratorNode
from manip_kin.ros.wire.messages import make_joint_state, make_pose_stamped

GENOVA = load_robot("genova7")
IRB = load_robot("irb120")
RPP = load_robot("rpp")
SLOW_IRB = dataclasses.replace(with_velocity_limits(IRB, IRB.velocity_limits * 0.5), name="irb120_slow")
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


class Publishers:
    """Latched ``robot_description`` publishers, one rclpy node each."""

    def __init__(self, harness):
        self.harness = harness
        self.nodes = {}
        self.publishers = {}

    def publish(self, name: str, model, namespace: str = "/") -> None:
        if name not in self.nodes:
            node = rclpy.create_node(name, namespace=namespace, context=self.harness.context)
            self.nodes[name] = node
            self.publishers[name] = node.create_publisher(String, "/robot_description", LATCHED)
        self.publishers[name].publish(String(data=model_to_urdf(model)))

    def close(self):
        for node in self.nodes.values():
            node.destroy_node()


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


@pytest.fixture
def publishers(harness):
    p = Publishers(harness)
    yield p
    p.close()


def _reload(harness, node_name="cartesian_controller"):
    client = harness.node.create_client(Trigger, f"/{node_name}/reload_robot_description")
    assert client.wait_for_service(5.0)
    future = client.call_async(Trigger.Request())
    assert harness.spin_until(future.done, 10)
    return future.result()


def _warnings(text: str, publisher: str) -> int:
    return text.count(f"a different robot description on /robot_description from {publisher} ")


def test_publisher_names_match_fully_qualified_relative_or_bare():
    assert publisher_matches("/arm_b", "/arm_b") and publisher_matches("arm_b", "/arm_b")
    assert publisher_matches("arm_b", "/left/arm_b") and publisher_matches("left/arm_b", "/left/arm_b")
    assert not publisher_matches("/arm_b", "/left/arm_b") and not publisher_matches("arm", "/arm_b")


def test_two_publishers_of_different_urdfs_are_refused_with_both_names(harness, publishers):
    publishers.publish("arm_a", GENOVA)
    publishers.publish("arm_b", IRB, namespace="/cell")
    with pytest.raises(InvalidArgumentError) as error:
        harness.start(CartesianControllerNode, rate_hz=100.0)
    message = str(error.value)
    assert "/arm_a (robot 'genova7'" in message and "/cell/arm_b (robot 'irb120'" in message, message
    assert "set parameter robot_description_publisher" in message and len(message) < 600


def test_the_same_urdf_from_two_publishers_is_taken(harness, publishers):
    publishers.publish("arm_a", IRB)
    publishers.publish("rsp", IRB)  # robot_state and a robot_state_publisher of the same arm
    node = harness.start(CartesianControllerNode, rate_hz=100.0)
    assert node.model.joint_names == IRB.joint_names


@pytest.mark.parametrize(("wanted", "robot"), [("arm_b", IRB), ("/arm_b", IRB), ("arm_a", GENOVA)])
def test_the_parameter_picks_the_named_publisher(harness, publishers, wanted, robot):
    publishers.publish("arm_a", GENOVA)
    publishers.publish("arm_b", IRB)
    node = harness.start(TrajectoryGeneratorNode, rate_hz=100.0, robot_description_publisher=wanted)
    assert node.model.name == robot.name and node.model.joint_names == robot.joint_names


def test_a_later_description_is_logged_once_the_model_stays_and_the_switch_works(harness, publishers, capfd):
    publishers.publish("arm_a", GENOVA)
    publishers.publish("arm_b", IRB)
    node = harness.start(CartesianControllerNode, rate_hz=100.0, robot_description_publisher="arm_b")
    harness.executor.add_node(node)  # its timer and services
    model = node.model
    harness.spin_for(1.2)
    logged = capfd.readouterr().err
    # The other arm's description differs from the running one: said once, with why it matters.
    assert _warnings(logged, "/arm_a") == 1, logged
    assert "its joints (joint1, joint2, joint3, joint4, joint5, joint6, joint7) differ" in logged
    assert "the node then holds the arm at rest" in logged
    assert _warnings(logged, "/arm_b") == 0

    # The running publisher sends a new description (the same joints, half the speed): logged once.
    publishers.publish("arm_b", SLOW_IRB)
    harness.spin_for(1.2)
    publishers.publish("arm_b", SLOW_IRB)  # the same again: nothing new to say
    harness.spin_for(1.2)
    logged = capfd.readouterr().err
    assert _warnings(logged, "/arm_b") == 1 and "(same joints)" in logged, logged
    assert "keeping the running model 'irb120'" in logged and "reload_robot_description" in logged
    assert node.model is model and node.controller.model is model  # not replaced by itself

    reply = _reload(harness)
    assert reply.success and "switched from 'irb120' to 'irb120_slow'" in reply.message, reply.message
    np.testing.assert_allclose(node.model.velocity_limits, IRB.velocity_limits * 0.5)
    assert node.controller.model is node.model
    assert _reload(harness).message.startswith("already running /arm_b")

    # A description with other joints cannot replace the running model in place.
    publishers.publish("arm_b", GENOVA)
    harness.spin_for(0.7)
    reply = _reload(harness)
    assert not reply.success and "has other joints" in reply.message and "restart the node" in reply.message
    assert node.model.name == "irb120_slow"


def test_joint_states_of_another_arm_bring_the_commands_to_rest(harness, publishers):
    publishers.publish("arm_b", IRB)
    commands = harness.collect(Float64MultiArray, "/joint_velocity_commands")
    node = harness.start(CartesianControllerNode, rate_hz=100.0)
    harness.wait_matched("/joint_states", JointState)
    harness.wait_matched("/goal_pose", PoseStamped)
    q0 = np.zeros(IRB.dof)
    goal = frame_pose(IRB, q0 + 0.1)
    harness.publish("/goal_pose", make_pose_stamped(goal, IRB.base_frame))
    arm = {"names": IRB.joint_names, "q": q0}

    def stream():
        harness.publish("/joint_states", make_joint_state(arm["names"], arm["q"]))

    assert harness.spin_until(lambda: commands and np.any(commands[-1].data), 5, every=stream)
    # Another arm's joint states (the robot_description changed under the controller).
    arm.update(names=RPP.joint_names, q=np.zeros(RPP.dof))
    assert harness.spin_until(lambda: node.state == "stale input", 5, every=stream)
    assert harness.spin_until(lambda: commands and not np.any(commands[-1].data), 5, every=stream)
    assert node.inputs.rejected_joint_states > 0


def test_without_publisher_gids_different_urdfs_are_still_refused(harness, publishers, monkeypatch):
    from manip_kin.ros.runtime import publisher_take

    monkeypatch.setattr(publisher_take, "_RCL", "rcl not found (test)")  # the public fallback
    publishers.publish("arm_a", GENOVA)
    publishers.publish("arm_b", IRB)
    with pytest.raises(InvalidArgumentError) as error:
        harness.start(CartesianControllerNode, rate_hz=100.0, robot_description_publisher="arm_b")
    message = str(error.value)
    assert "2 different robot descriptions" in message and "/arm_a, /arm_b" in message, message
    assert "cannot tell which node sent which (rcl not found (test))" in message


def test_the_generator_switches_on_request_to_the_same_joints(harness, publishers):
    publishers.publish("arm_b", IRB)
    node = harness.start(TrajectoryGeneratorNode, rate_hz=100.0)
    harness.executor.add_node(node)
    publishers.publish("arm_b", SLOW_IRB)
    harness.spin_for(0.3)
    assert node.model.name == "irb120"  # not replaced until asked
    reply = _reload(harness, "trajectory_generator")
    assert reply.success and "to 'irb120_slow'" in reply.message, reply.message
    np.testing.assert_allclose(node.model.velocity_limits, IRB.velocity_limits * 0.5)
    assert node.bounds.max_twist_linear < type(node.bounds).of(IRB).max_twist_linear
