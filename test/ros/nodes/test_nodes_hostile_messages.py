"""Live nodes fed the odd but well-formed messages of issue 8: rejected, logged once, node keeps working.

The burst that once killed the generator (a line target hundreds of orders of magnitude
beyond any reach) and its relatives go to the running nodes; each must be rejected with a
reason naming what was received and what is valid, the previous good state kept, the
outputs finite and within the limits, and the node must still do its job afterwards.
"""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, TwistStamped
from node_harness import Harness, statuses
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.core.bounds import InputBounds
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.nodes.robot_state import RobotStateNode
from manip_kin.ros.nodes.trajectory_generator import TrajectoryGeneratorNode
from manip_kin.ros.wire.messages import make_joint_state, make_pose_stamped, make_twist_stamped, pose_stamped_to_matrix


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def _pose(xyz, quaternion=(0.0, 0.0, 0.0, 1.0)) -> PoseStamped:
    msg = make_pose_stamped(np.eye(4), "base_link")
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = xyz
    o.x, o.y, o.z, o.w = quaternion
    return msg


def test_generator_survives_the_burst_and_follows_a_line_after(harness, capfd):
    model = load_robot("irb120")
    q0 = np.zeros(6)
    goals = harness.collect(PoseStamped, "/goal_pose")
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    node = harness.start(TrajectoryGeneratorNode, robot="irb120", rate_hz=200.0)
    for topic, msg_type in (("/line_target", PoseStamped), ("/joint_states", JointState)):
        harness.wait_matched(topic, msg_type)

    def stream():
        now = harness.node.get_clock().now().to_msg()
        harness.publish("/joint_states", make_joint_state(model.joint_names, q0, stamp=now))

    harness.spin_for(0.1, every=stream)
    burst = [
        _pose((1e300, 0.0, 0.5)),  # the target: time scaling divided by zero
        _pose((1.7e308, -1.7e308, 1.7e308)),
        _pose((0.0, 0.0, 5e-324), (5e-324, 0.0, 0.0, 5e-324)),  # subnormal quaternion
        _pose((0.3, 0.1, 0.5), (0.0, 0.0, 0.0, 0.0)),
        _pose((0.3, 0.1, 0.5), (1e300, 1e300, 0.0, 0.0)),
        _pose((3.0 * InputBounds.of(model).reach_radius, 0.0, 0.0)),
        _pose((math.nan, 0.0, 0.0)),
        _pose((0.0, -math.inf, 0.0)),
    ]
    for msg in burst:
        harness.publish("/line_target", msg)
    assert harness.spin_until(lambda: node.supervisor.rejected_targets == len(burst), 5, every=stream), (
        node.supervisor.last_rejection
    )
    assert node.loop.running and node.loop.stats().errors == 0 and not goals
    # One line per kind of problem (reach, quaternion, finite): throttled, not one per message.
    # The counter rises before the log line is written: read once the loop has moved on.
    expected = ("is 1e+300 m from the base; valid: within", "has length 4.94066e-324; valid: unit length")
    expected += ("NaN or infinity",)
    logged = harness.logged(node, capfd, every=stream)
    assert all(line in logged for line in expected), logged
    assert not any(s.level == DiagnosticStatus.ERROR for s in statuses(diagnostics, "trajectory_generator"))
    # Still follows a valid line.
    target = make_transform(np.eye(3), [0.374, 0.15, 0.55])
    harness.publish("/line_target", make_pose_stamped(target, "base_link"))
    assert harness.spin_until(lambda: node.state == "holding", 10, every=stream)
    # The state flips as the final goal is sent: wait for it to arrive here.
    assert harness.spin_until(
        lambda: goals and np.allclose(pose_stamped_to_matrix(goals[-1]), target, rtol=0.0, atol=1e-9), 5
    )


def test_controller_rejects_absurd_goals_twists_and_joint_states(harness, capfd):
    model = load_robot("genova7")
    q0 = model.start_configuration()
    commands = harness.collect(Float64MultiArray, "/joint_velocity_commands")
    node = harness.start(CartesianControllerNode, robot="genova7", rate_hz=250.0)
    for topic, msg_type in (("/joint_states", JointState), ("/goal_pose", PoseStamped), ("/goal_twist", TwistStamped)):
        harness.wait_matched(topic, msg_type)
    state = {"msg": make_joint_state(model.joint_names, q0)}

    def stream():
        harness.publish("/joint_states", state["msg"])

    good = frame_pose(model, q0)
    good[2, 3] += 0.05
    harness.publish("/goal_pose", make_pose_stamped(good, "base_link"))
    assert harness.spin_until(lambda: commands and any(commands[-1].data), 5, every=stream)
    for msg in (_pose((1e300, 0.0, 0.0)), _pose((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 5e-324))):
        harness.publish("/goal_pose", msg)
    huge = make_twist_stamped([0.0, 0.0, 1e6], [1e300, 0.0, 0.0], "base_link")
    harness.publish("/goal_twist", huge)
    assert harness.spin_until(
        lambda: node.inputs.rejected_goals == 2 and node.inputs.rejected_twists == 1, 5, every=stream
    )
    # Joint states: duplicated names, empty, absurd finite positions (each sent for a while).
    bad_states = [
        make_joint_state([model.joint_names[0]] * 7, q0),
        make_joint_state([], []),
        make_joint_state(model.joint_names, np.full(7, 1e300)),
    ]
    for bad in bad_states:
        state["msg"] = bad
        before = node.inputs.rejected_joint_states
        assert harness.spin_until(lambda before=before: node.inputs.rejected_joint_states > before, 5, every=stream)
    # The counter rises before the node's log line is written: read once the loop has moved on.
    # (the empty one is a name problem like the duplicates: same kind, so its line is held back)
    expected = ("more than once; valid: each joint once", "out of range; valid: [", "too fast; valid: at most")
    logged = harness.logged(node, capfd, every=stream)
    assert all(line in logged for line in expected), logged
    # The previous good goal is kept; commands stayed finite and within the velocity limits.
    np.testing.assert_allclose(node.inputs.goal, good, atol=1e-12)
    data = np.array([c.data for c in commands])
    assert np.all(np.isfinite(data)) and np.all(np.abs(data) <= model.velocity_limits * (1 + 1e-9))
    # The stale joint state (only bad ones since) leads to zeros; a good one resumes tracking.
    state["msg"] = make_joint_state(model.joint_names, q0)
    assert harness.spin_until(lambda: commands and any(commands[-1].data), 5, every=stream)
    assert node.loop.stats().errors == 0


def test_robot_state_rejects_absurd_commands(harness, capfd):
    model = load_robot("genova7")
    states = harness.collect(JointState, "/joint_states")
    node = harness.start(RobotStateNode, robot="genova7", rate_hz=250.0)
    harness.wait_matched("/joint_velocity_commands", Float64MultiArray)
    for data in ([1e300] * 7, [1.7e308, -1.7e308, 0.0, 0.0, 0.0, 0.0, 0.0], [], [5e-324] * 6):
        harness.publish("/joint_velocity_commands", Float64MultiArray(data=data))
    assert harness.spin_until(lambda: node.rejected_commands == 4, 5)
    assert "absurd; valid: |value| <=" in capfd.readouterr().err
    harness.spin_for(0.1)
    positions = np.array([s.position for s in states])
    assert np.all(np.isfinite(positions)) and all(model.within_limits(q) for q in positions)
    np.testing.assert_allclose(positions[-1], model.start_configuration())


def test_generator_refuses_absurd_speed_limits(harness):
    from manip_kin.errors import InvalidArgumentError

    bounds = InputBounds.of(load_robot("irb120"))
    with pytest.raises(InvalidArgumentError, match="max_linear_velocity = 1e\\+30; valid: 0.0001 to 10 m/s"):
        harness.start(TrajectoryGeneratorNode, robot="irb120", max_linear_velocity=1e30)
    # Within the parameter's range (up to 100 rad/s) but beyond twice what this arm can do.
    assert bounds.max_twist_angular < 80.0
    with pytest.raises(InvalidArgumentError, match="max_angular_velocity = 80 is absurd for this arm; valid: <="):
        harness.start(TrajectoryGeneratorNode, robot="irb120", max_angular_velocity=80.0)
    # At the bound itself the node starts.
    node = harness.start(TrajectoryGeneratorNode, robot="irb120", max_angular_velocity=bounds.max_twist_angular)
    assert node.limits.max_angular_velocity == bounds.max_twist_angular
