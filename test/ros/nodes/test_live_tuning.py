"""Live tuning through the standard parameter services (what ``ros2 param set`` calls).

The nodes run in-process with their parameter services served by the harness executor; the
test talks to them with ``rclpy.parameter_client.AsyncParameterClient``. Each accepted value
must change what the running node does, not only what ``get`` returns.
"""

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from node_harness import Harness, without_acceleration_limits
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.nodes.trajectory_generator import TrajectoryGeneratorNode
from manip_kin.ros.wire.messages import make_joint_state, make_pose_stamped

GENOVA = load_robot("genova7")
Q0 = GENOVA.start_configuration()
# Close enough that no joint reaches its velocity limit: the rates are linear in the gains.
GOAL = frame_pose(GENOVA, GENOVA.clip_to_limits(Q0 + np.array([0.02, -0.02, 0.02, 0.02, -0.02, 0.005, 0.02])))
RATE = 100.0


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


class Parameters:
    """Set and get through the parameter services of node ``name``, spinning the harness."""

    def __init__(self, harness, name):
        self.harness = harness
        self.client = AsyncParameterClient(harness.node, name)
        assert harness.spin_until(lambda: self.client.services_are_ready(), 10)

    def _wait(self, future, every=None):
        assert self.harness.spin_until(future.done, 10, every=every)
        return future.result()

    def set(self, every=None, **values):
        """The SetParametersResult of each value (one request per value)."""
        results = []
        for name, value in values.items():
            response = self._wait(self.client.set_parameters([Parameter(name, value=value)]), every)
            results.append(response.results[0])
        return results[0] if len(results) == 1 else results

    def get(self, name, every=None):
        response = self._wait(self.client.get_parameters([name]), every)
        return parameter_value_to_python(response.values[0])


def _start_controller(harness, **params):
    commands = harness.collect(Float64MultiArray, "/joint_velocity_commands")
    node = harness.start(
        CartesianControllerNode, robot="genova7", rate_hz=RATE, gain_linear=1.0, gain_angular=1.0, **params
    )
    harness.executor.add_node(node)  # serve its parameter services
    harness.wait_matched("/joint_states", JointState)
    harness.wait_matched("/goal_pose", PoseStamped)
    stream = lambda: harness.publish("/joint_states", make_joint_state(GENOVA.joint_names, Q0))  # noqa: E731
    return node, commands, stream


def _expected(gain):
    config = ControllerConfig(gain_linear=gain, gain_angular=gain)
    return CartesianController(GENOVA, config).step(Q0, GOAL, None, 1.0 / RATE).qdot


def _commands_equal(commands, expected):
    return lambda: commands and np.allclose(commands[-1].data, expected, rtol=1e-9, atol=1e-12)


def test_controller_gains_set_at_run_time_change_the_commands(harness):
    node, commands, stream = _start_controller(harness)
    params = Parameters(harness, "cartesian_controller")
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    at_one = _expected(1.0)
    assert harness.spin_until(_commands_equal(commands, at_one), 5, every=stream)
    assert np.max(np.abs(at_one) / GENOVA.velocity_limits) < 0.5  # not velocity-limited

    result = params.set(every=stream, gain_linear=2.5, gain_angular=2.5)
    assert all(r.successful for r in result), result
    assert params.get("gain_linear", every=stream) == 2.5
    at_two_and_half = _expected(2.5)
    np.testing.assert_allclose(at_two_and_half, 2.5 * at_one, rtol=1e-9)  # the law is linear in the gains here
    assert harness.spin_until(_commands_equal(commands, at_two_and_half), 5, every=stream)
    assert node.controller.config.gain_linear == 2.5


@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("gain_linear", -1.0, "gain_linear = -1; valid: 0 to 1000 1/s"),
        ("gain_angular", float("nan"), "valid: a finite number"),
        ("singular_threshold", 0.0, "valid: 1e-06 to 10"),
        ("position_tolerance", "tight", "wrong type"),
        ("goal_timeout", -0.5, "valid: 0 to 86400 s"),
        ("rate_hz", 50.0, "read-only"),
        ("robot", "irb120", "read-only"),
        ("tip_link", "ee", "read-only"),
    ],
)
def test_invalid_or_structural_values_are_refused_with_the_reason(harness, name, value, words):
    node, commands, stream = _start_controller(harness)
    params = Parameters(harness, "cartesian_controller")
    before = params.get(name, every=stream)
    controller = node.controller
    result = params.set(every=stream, **{name: value})
    assert not result.successful and words in result.reason, result.reason
    assert params.get(name, every=stream) == before
    assert node.controller is controller  # the running core object was not replaced


def test_controller_tolerances_and_timeouts_apply_at_once(harness):
    node, commands, stream = _start_controller(harness, position_tolerance=1e-6, orientation_tolerance=1e-6)
    params = Parameters(harness, "cartesian_controller")
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    assert harness.spin_until(lambda: node.state == "tracking", 5, every=stream)
    # The joint state stream holds q at Q0: with wide tolerances the same error counts as converged.
    assert all(r.successful for r in params.set(every=stream, position_tolerance=0.5, orientation_tolerance=0.5))
    assert harness.spin_until(lambda: node.state == "converged", 5, every=stream)
    # A goal timeout set now expires the held goal: stale input, zero commands.
    assert params.set(every=stream, goal_timeout=0.05).successful
    assert harness.spin_until(lambda: node.state == "stale input", 5, every=stream)
    assert harness.spin_until(lambda: commands and not any(commands[-1].data), 5, every=stream)


def test_generator_limits_set_at_run_time_time_the_next_line(harness):
    model = load_robot("irb120")
    q0 = np.zeros(6)
    start = frame_pose(model, q0)
    target = start.copy()
    target[:3, 3] += [0.0, 0.12, -0.05]  # 0.13 m, no rotation
    # A constant line runs only without joint acceleration limits (it is a velocity step).
    node = harness.start(
        TrajectoryGeneratorNode,
        robot="irb120",
        rate_hz=RATE,
        time_scaling="constant",
        **without_acceleration_limits(model.joint_names),
    )
    harness.executor.add_node(node)
    for topic, msg_type in (("/line_target", PoseStamped), ("/joint_states", JointState)):
        harness.wait_matched(topic, msg_type)

    def stream():
        now = harness.node.get_clock().now().to_msg()
        harness.publish("/joint_states", make_joint_state(model.joint_names, q0, stamp=now))

    params = Parameters(harness, "trajectory_generator")
    durations = []
    for speed in (0.25, 0.1):
        result = params.set(every=stream, max_linear_velocity=speed)
        assert result.successful
        harness.spin_for(0.05, every=stream)
        harness.publish("/line_target", make_pose_stamped(target, "base_link"))
        assert harness.spin_until(lambda: node.state == "streaming", 5, every=stream)
        durations.append(node.supervisor.motion.duration)
        assert harness.spin_until(lambda: node.state == "holding", 10, every=stream)
    length = float(np.linalg.norm([0.0, 0.12, -0.05]))
    # Constant speed: duration = length / speed.
    np.testing.assert_allclose(durations, [length / 0.25, length / 0.1], rtol=1e-9)
    refused = params.set(every=stream, max_linear_acceleration=0.0)
    assert not refused.successful and "max_linear_acceleration" in refused.reason
    refused = params.set(every=stream, time_scaling="bang-bang")
    assert not refused.successful and "trapezoidal" in refused.reason
    assert node.limits.max_linear_velocity == 0.1 and node.time_scaling == "constant"


def test_hostile_values_through_the_parameter_services_are_refused_briefly_and_the_node_runs_on(harness):
    node, commands, stream = _start_controller(harness)
    params = Parameters(harness, "cartesian_controller")
    harness.publish("/goal_pose", make_pose_stamped(GOAL, "base_link"))
    assert harness.spin_until(lambda: node.state == "tracking", 5, every=stream)
    controller = node.controller
    for name, value in (
        ("damping_max", 1e200),  # used to raise OverflowError in the service: no answer, exit 1
        ("singular_threshold", 1e308),
        ("diagnostics_rate_hz", 1e-300),  # used to kill the loop: int(1e9 / rate) overflowed
        ("gain_linear", 1e308),  # used to make the commands NaN
        ("gain_angular", "1.5"),  # a string is not a number
        ("gain_linear", [0.5] * 100_000),  # used to echo the whole array (500 kB)
        ("gain_linear", True),
    ):
        result = params.set(every=stream, **{name: value})
        assert not result.successful, (name, value)
        assert f"parameter {name} = " in result.reason and "valid: " in result.reason, result.reason
        assert len(result.reason) < 200, result.reason
    assert node.controller is controller and node.controller.config.gain_linear == 1.0
    cycles = node.loop.stats().cycles
    count = len(commands)
    harness.spin_for(0.3, every=stream)
    assert node.loop.stats().cycles > cycles and node.loop_error() == ""
    assert len(commands) > count and all(np.all(np.isfinite(c.data)) for c in commands)
    assert params.set(every=stream, gain_linear=2.0).successful  # the services still work


def test_generator_refuses_hostile_planning_values_and_plans_on(harness):
    node = harness.start(TrajectoryGeneratorNode, robot="irb120", rate_hz=RATE)
    harness.executor.add_node(node)
    params = Parameters(harness, "trajectory_generator")
    for name, value in (
        ("path_points", "50"),
        ("path_points", 10**12),  # used to be accepted: MemoryError on the next line
        ("max_linear_velocity", 1e-300),  # an infinite line duration
        ("diagnostics_rate_hz", 1e-300),
    ):
        result = params.set(**{name: value})
        assert not result.successful and f"parameter {name} = " in result.reason, result.reason
        assert len(result.reason) < 200, result.reason
    assert node._path_points == 50 and node.loop_error() == ""
    assert params.set(path_points=10000).successful and node._path_points == 10000


@pytest.mark.parametrize(("name", "value"), [("gain_linear", "1.5"), ("damping_max", 1e200), ("rate_hz", 1e-300)])
def test_a_hostile_value_at_start_is_one_bounded_input_error(harness, name, value):
    with pytest.raises(InvalidArgumentError, match=f"parameter {name} = .*; valid: ") as error:
        harness.start(CartesianControllerNode, robot="genova7", **{name: value})
    assert len(str(error.value)) < 200
