"""A controller driving test/support/fake_hardware.py in a namespace of its own, holding its last command.

Shared by the tests of the controller's command stream (limits, stops, servoing): the arm holds
every command it gets (as ros2_control's JointGroupVelocityController does) and keeps every
command it received, so a stream that jumps would jump the arm, and one that does not end in a
zero would leave it moving.
"""

import itertools
import math
import os

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from fake_hardware import FakeHardware
from geometry_msgs.msg import PoseStamped

from manip_kin.control.joint_limits import JointLimits
from manip_kin.core.robots import load_robot
from manip_kin.core.urdf import model_to_urdf
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.wire.messages import make_pose_stamped, stamp_key

RATE = 250.0
_arms = itertools.count()
SLACK = 1e-6  # relative, on the limits: the stream's values are what ruckig computed, rounded


def start_held_arm(harness, robot: str, q0, arm_command_timeout: float = math.inf, **params):
    """The fake arm and the controller in a namespace of their own: no other test's node can
    add to the command stream the arm records. ``arm_command_timeout`` [s]: how long the arm
    moves on a command (default: forever, as JointGroupVelocityController)."""
    model = load_robot(robot)
    namespace = f"/safety_{os.getpid()}_{next(_arms)}"
    hardware = FakeHardware(
        model_to_urdf(model),
        q0,
        rate_hz=2 * RATE,
        command_timeout=arm_command_timeout,
        command_topic="joint_velocity_commands",
        namespace=namespace,
    )
    diagnostics = harness.collect(DiagnosticArray, "/diagnostics")
    params.setdefault("joint_state_timeout", 0.3)
    node = harness.start(CartesianControllerNode, namespace=namespace, robot=robot, rate_hz=RATE, **params)
    harness.executor.add_node(node)  # serve its ~/stop and ~/pause
    node.test_namespace = namespace
    harness.wait_matched(f"{namespace}/goal_pose", PoseStamped)
    assert harness.spin_until(lambda: node.inputs.q is not None, 5)
    # The arm hears the controller before anything moves: a subscription matched late (a loaded
    # machine) would miss the start of a ramp, and the stream would seem to jump from zero.
    assert harness.spin_until(lambda: hardware.commands_received > 0, 10), "the arm hears no command"
    return model, hardware, node, diagnostics


def send_goal(harness, node, pose, frame="base_link"):
    msg = make_pose_stamped(pose, frame, harness.node.get_clock().now().to_msg())
    harness.publish(f"{node.test_namespace}/goal_pose", msg)
    return stamp_key(msg.header.stamp)


def call_service(harness, srv_type, name, request):
    client = harness.node.create_client(srv_type, name)
    assert client.wait_for_service(timeout_sec=5)
    future = client.call_async(request)
    assert harness.spin_until(future.done, 5)
    return future.result()


def held_speed(hardware) -> float:
    """The largest joint rate the arm moves on now."""
    command = hardware.held_command()
    return 0.0 if command is None else float(np.max(np.abs(command)))


def assert_stream_within(
    commands: np.ndarray, limits: JointLimits, dt: float, from_rest: bool = True, context: str = ""
) -> None:
    """Every command's finite-difference acceleration and jerk within the limits; from rest
    (``from_rest``: the stream is the whole stream), else from its first two commands on.
    ``context`` is added to the failure's message."""
    stream = np.vstack([np.zeros((2, commands.shape[1])), commands]) if from_rest else commands
    acceleration = np.diff(stream, axis=0) / dt
    jerk = np.diff(acceleration, axis=0) / dt
    ratio_a = np.max(np.abs(acceleration) / limits.acceleration, axis=1)
    ratio_j = np.max(np.abs(jerk) / limits.jerk, axis=1)
    worst_a, worst_j = int(np.argmax(ratio_a)), int(np.argmax(ratio_j))
    assert ratio_a[worst_a] <= 1 + SLACK and ratio_j[worst_j] <= 1 + SLACK, (
        f"acceleration {ratio_a[worst_a]:.3g} x its limit at step {worst_a}, jerk {ratio_j[worst_j]:.3g} x at "
        f"step {worst_j}, of {len(stream) - 1} steps{' from rest' if from_rest else ''}{context}"
    )
