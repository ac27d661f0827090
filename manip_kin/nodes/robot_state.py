"""``robot_state``: a simulated arm that integrates joint-rate commands and publishes its state.

The node holds one :class:`JointIntegrator` (plain numpy) and, every cycle of its
:class:`~manip_kin.nodes.rate_loop.RateLoop`, takes the latest command, integrates it
and publishes ``joint_states``, ``ee_pose``, ``tool_pose``, ``ee_twist`` and
``tool_twist``. ``robot_description`` is published once, transient local.
"""

from __future__ import annotations

import sys
import time
from operator import mul

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from manip_kin.bounds import InputBounds
from manip_kin.errors import InvalidArgumentError, JointCountError
from manip_kin.joint_integration import integrate_joint_rates
from manip_kin.kinematics import compiled_kinematics
from manip_kin.model import RobotModel
from manip_kin.nodes import conversions as conv
from manip_kin.nodes.params import (
    REALTIME_PRIORITY,
    SCHEDULER_SLICE,
    LiveParameters,
    ParamSpec,
    declare_parameters,
    diagnostics_rate,
    loop_rate,
    period_ns,
    usage_text,
)
from manip_kin.nodes.rate_loop import LoopingNode, PolledSubscription, ThrottledLog, stats_key_values
from manip_kin.nodes.robot_model import load_node_model, model_parameters
from manip_kin.nodes.runner import run_node
from manip_kin.nodes.topics import STREAM_DEPTH, latest_state_qos
from manip_kin.nodes.visuals import RobotVisuals
from manip_kin.robots import bundled_robot_names
from manip_kin.urdf import model_to_urdf

NODE_NAME = "robot_state"

PARAMETERS = (
    *model_parameters("genova7"),
    ParamSpec(
        "initial_positions",
        "float_list",
        None,
        "joint positions at start, model joint order",
        "rad | m",
        minimum=-1e4,  # far beyond any joint's range (the limits are checked too); keeps FK finite
        maximum=1e4,
        default_text="the robot's scenario start, else zeros clipped into the limits",
    ),
    loop_rate("integration and publishing rate"),
    # 1 ms (a period at 1 kHz) to a minute.
    ParamSpec(
        "command_timeout",
        "float",
        0.1,
        "a command older than this counts as zero velocity",
        "s",
        minimum=1e-3,
        maximum=60.0,
        tunable=True,
    ),
    ParamSpec(
        "base_frame",
        "str",
        None,
        "frame id of the published poses and twists",
        default_text="the robot's base frame (base_link)",
    ),
    diagnostics_rate(2.0, "rate of the loop statistics on /diagnostics (0: off)", off=True),
    ParamSpec("frame_prefix", "str", "", "prepended to every TF frame id (as robot_state_publisher's)"),
    # Visuals: a viewer needs /tf at 0.1 Hz at least and gets nothing from more than one
    # per cycle of a 1 kHz loop; markers (10 Hz by default) likewise; a trail of two minutes
    # at its 20 ms spacing is 6000 points.
    ParamSpec("tf_rate_hz", "float", 50.0, "rate of /tf (where tf2_msgs is installed)", "Hz", minimum=0.1, maximum=1e3),
    ParamSpec(
        "markers_rate_hz",
        "float",
        10.0,
        "rate of the markers topic (0: off)",
        "Hz",
        minimum=0.1,
        maximum=1e3,
        zero_is_off=True,
    ),
    ParamSpec("trail_duration", "float", 5.0, "length of the tool trail marker", "s", minimum=0.02, maximum=120.0),
    REALTIME_PRIORITY,
    SCHEDULER_SLICE,
)

USAGE = usage_text(
    NODE_NAME,
    "Simulated arm: integrates the latest joint velocity command at rate_hz within the joint\n"
    "position and velocity limits (a command above a velocity limit is scaled down as a whole,\n"
    "keeping its direction) and publishes the joint state, the end-effector and tool poses and\n"
    "twists every cycle. A command older than command_timeout counts as zero; a command with the\n"
    "wrong length or a non-finite value is rejected with a log line.",
    PARAMETERS,
    subscribes=[
        ("joint_velocity_commands", "std_msgs/Float64MultiArray", "joint rates [rad/s | m/s], model joint order")
    ],
    publishes=[
        ("joint_states", "sensor_msgs/JointState", "name, position, velocity, stamped"),
        ("ee_pose", "geometry_msgs/PoseStamped", "end effector in the base frame"),
        ("tool_pose", "geometry_msgs/PoseStamped", "tool (end effector if no tool) in the base frame"),
        ("ee_twist", "geometry_msgs/TwistStamped", "end-effector velocity w.r.t. base, in base"),
        ("tool_twist", "geometry_msgs/TwistStamped", "tool velocity w.r.t. base, in base"),
        ("robot_description", "std_msgs/String", "URDF of the model, once, transient local"),
        ("/tf, /tf_static", "tf2_msgs/TFMessage", "link transforms, where tf2_msgs is installed"),
        ("markers", "visualization_msgs/MarkerArray", "goal axes, planned path, tool trail, joint limits"),
        ("/diagnostics", "diagnostic_msgs/DiagnosticArray", "loop rate and timing, command state"),
    ],
    example=f"{NODE_NAME} --ros-args -p robot:=genova7 -p rate_hz:=1000  (robots: {', '.join(bundled_robot_names())})",
)


class JointIntegrator:
    """Joint positions integrated from velocity commands within the limits (plain Python floats).

    The cycle runs on float lists and the model's unrolled kinematics: at this size a
    numpy call costs more than the arithmetic it saves. Arrays are offered as properties
    for callers outside the loop.

    Args:
        model: the robot.
        q0: start positions, shape (n,), inside the limits.

    Attributes:
        q_values: current positions [rad | m], n floats.
        qdot_values: velocity of the last step [rad/s | m/s], n floats: the commanded rate
            after limiting, zero for a joint stopped at a position limit.
        ee_values, tool_values: end-effector and tool poses in base, 16 row-major floats.
        ee_twist_values, tool_twist_values: ``(wx, wy, wz, vx, vy, vz)`` w.r.t. base in base
            [rad/s, m/s].
        velocity_scale: factor (<= 1) the last command was scaled by to respect the velocity limits.
    """

    def __init__(self, model: RobotModel, q0: np.ndarray):
        self.model = model
        n = model.dof
        self._n = n
        self.q_values = [float(v) for v in q0]
        self.qdot_values = [0.0] * n
        self._lower = model.lower.tolist()
        self._upper = model.upper.tolist()
        self._inverse_velocity_limits = (1.0 / model.velocity_limits).tolist()
        self._tool_chain = compiled_kinematics(model, model.frame_index(model.default_frame), True)
        self._ee_chain = compiled_kinematics(model, model.dof + 1, False) if model.has_tool else None
        self.velocity_scale = 1.0
        self._update_kinematics()

    def step(self, command: np.ndarray | None, dt: float) -> None:
        """Advance by ``dt`` seconds with joint rates ``command`` (None: zero), shape (n,)."""
        n = self._n
        if command is None or not dt >= 1e-9:  # below the clock's resolution: no step (1/dt would overflow)
            if self.velocity_scale == 1.0 and not any(self.qdot_values):
                return  # at rest and still at rest: poses unchanged, twists zero
            self.qdot_values = [0.0] * n
            self.velocity_scale = 1.0
        else:
            self.q_values, self.qdot_values, self.velocity_scale, _ = integrate_joint_rates(
                self.q_values, command.tolist(), dt, self._lower, self._upper, self._inverse_velocity_limits
            )
        self._update_kinematics()

    def _update_kinematics(self) -> None:
        n = self._n
        values = self._tool_chain(self.q_values)
        tool = values[:16]
        qdot = self.qdot_values
        # Twist of the tool (ee when no tool) = J q̇, J rows [angular; linear] after the pose.
        twist = [sum(map(mul, values[16 + r * n : 16 + (r + 1) * n], qdot)) for r in range(6)]
        self.tool_values = tool
        self.tool_twist_values = twist
        if self._ee_chain is None:
            self.ee_values = tool
            self.ee_twist_values = twist
            return
        ee = self._ee_chain(self.q_values)
        self.ee_values = ee
        # Same rigid body: v_ee = v_tool + ω × (p_ee - p_tool).
        wx, wy, wz, vx, vy, vz = twist
        rx, ry, rz = ee[3] - tool[3], ee[7] - tool[7], ee[11] - tool[11]
        self.ee_twist_values = [wx, wy, wz, vx + wy * rz - wz * ry, vy + wz * rx - wx * rz, vz + wx * ry - wy * rx]

    # --- arrays for callers outside the loop ---------------------------------------------------

    @property
    def q(self) -> np.ndarray:
        """Current positions, shape (n,)."""
        return np.array(self.q_values)

    @property
    def qdot(self) -> np.ndarray:
        """Velocity of the last step, shape (n,)."""
        return np.array(self.qdot_values)

    @property
    def ee(self) -> np.ndarray:
        """End-effector pose in base, shape (4, 4)."""
        return np.array(self.ee_values).reshape(4, 4)

    @property
    def tool(self) -> np.ndarray:
        """Tool pose in base (the end effector when there is no tool), shape (4, 4)."""
        return np.array(self.tool_values).reshape(4, 4)

    @property
    def ee_twist(self) -> tuple[np.ndarray, np.ndarray]:
        """``(angular, linear)`` of the end effector, each shape (3,)."""
        return np.array(self.ee_twist_values[:3]), np.array(self.ee_twist_values[3:])

    @property
    def tool_twist(self) -> tuple[np.ndarray, np.ndarray]:
        """``(angular, linear)`` of the tool, each shape (3,)."""
        return np.array(self.tool_twist_values[:3]), np.array(self.tool_twist_values[3:])

    @property
    def at_limit(self) -> np.ndarray:
        """Joints on a position limit, shape (n,) bool."""
        q = self.q_values
        return np.array([q[i] <= self._lower[i] or q[i] >= self._upper[i] for i in range(self._n)])


def initial_positions(model: RobotModel, values) -> np.ndarray:
    """The ``initial_positions`` parameter checked against the model (default: start configuration)."""
    if values is None or len(values) == 0:
        return model.start_configuration()
    if len(values) != model.dof:
        raise JointCountError("parameter initial_positions", len(values), model.dof)
    q = model.check_q(values, "initial_positions")
    if not model.within_limits(q):
        raise InvalidArgumentError(
            f"parameter initial_positions {np.round(q, 4).tolist()} is outside the joint limits "
            f"lower {np.round(model.lower, 4).tolist()}, upper {np.round(model.upper, 4).tolist()}"
        )
    return q


class RobotStateNode(LoopingNode):
    """ROS handles around one :class:`JointIntegrator`."""

    def __init__(self, **node_kwargs):
        super().__init__(NODE_NAME, **node_kwargs)
        params = declare_parameters(self, PARAMETERS)
        self.model = load_node_model(self, params)
        self.integrator = JointIntegrator(self.model, initial_positions(self.model, params["initial_positions"]))
        self.base_frame = params["base_frame"] or self.model.base_frame
        self.rate_hz = params["rate_hz"]
        self._set_parameters(params)
        LiveParameters(self, PARAMETERS, self._set_parameters)

        self._max_command = InputBounds.of(self.model).max_command
        self._command_sub = PolledSubscription(self, Float64MultiArray, "joint_velocity_commands", latest_state_qos(10))
        self._joint_state_pub = self.create_publisher(JointState, "joint_states", STREAM_DEPTH)
        self._ee_pose_pub = self.create_publisher(PoseStamped, "ee_pose", STREAM_DEPTH)
        self._tool_pose_pub = self.create_publisher(PoseStamped, "tool_pose", STREAM_DEPTH)
        self._ee_twist_pub = self.create_publisher(TwistStamped, "ee_twist", STREAM_DEPTH)
        self._tool_twist_pub = self.create_publisher(TwistStamped, "tool_twist", STREAM_DEPTH)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        latched = QoSProfile(
            depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
        )
        self._description_pub = self.create_publisher(String, "robot_description", latched)

        # Messages go out pre-serialised (see conversions.PoseStampedCdr): half the publish cost.
        self._joint_state_cdr = conv.JointStateCdr(self.model.joint_names)
        self._pose_cdr = conv.PoseStampedCdr(self.base_frame)
        self._twist_cdr = conv.TwistStampedCdr(self.base_frame)

        self._command: np.ndarray | None = None
        self._command_time_ns = 0
        self._last_cycle_ns = 0
        self._last_diagnostics_ns = 0
        self.rejected_commands = 0
        self._warn = ThrottledLog(self.get_logger().warning, 1.0)

        urdf_text = self._publish_description()
        self.visuals = RobotVisuals(
            self,
            self.model,
            urdf_text,
            params["frame_prefix"],
            params["tf_rate_hz"],
            params["markers_rate_hz"],
            params["trail_duration"],
        )
        self.visuals.publish_static(time.time_ns())
        self.get_logger().info(self.visuals.tf_log)
        self.get_logger().info(
            f"robot {self.model.name} ({self.model.dof} joints) at {self.rate_hz:g} Hz, "
            f"q0 = {np.round(self.integrator.q, 4).tolist()}, frame {self.base_frame!r}"
        )
        self.start_loop(self.rate_hz, self._cycle, params["realtime_priority"], params["scheduler_slice"])

    def _set_parameters(self, params: dict) -> None:
        """The tunable parameters in ``params`` (at start, and on a live change: the next cycle uses them)."""
        if "command_timeout" in params:
            self.command_timeout_ns = int(params["command_timeout"] * 1e9)
        if "diagnostics_rate_hz" in params:
            rate = params["diagnostics_rate_hz"]
            self._diagnostics_period_ns = period_ns(rate)

    def _publish_description(self) -> str:
        urdf_text = model_to_urdf(self.model)
        self._description_pub.publish(String(data=urdf_text))
        return urdf_text

    def _take_commands(self, now_ns: int) -> None:
        dof = self.model.dof
        while (data := self._command_sub.take(raw=True)) is not None:
            values = conv.decode_float64_array(data)
            problem = conv.command_problem(values, dof, max_abs=self._max_command)
            if problem is not None:
                self.rejected_commands += 1
                self._warn(
                    conv.problem_kind(problem),
                    f"rejected {self._command_sub.subscription.topic_name}: {problem}; keeping the previous command",
                )
                continue
            self._command = values
            self._command_time_ns = now_ns

    def publish_safe_output(self) -> None:
        """After a failed cycle: hold position (drop the command; the state again, at zero velocity)."""
        self._command = None
        integrator = self.integrator
        stamp_ns = self.ros_time_ns()
        self._joint_state_pub.publish(
            self._joint_state_cdr.encode_values(stamp_ns, integrator.q_values, [0.0] * self.model.dof)
        )

    def _cycle(self, now_ns: int) -> None:
        self._take_commands(now_ns)
        dt = (now_ns - self._last_cycle_ns) * 1e-9 if self._last_cycle_ns else 0.0
        # After a stall, integrate at most a few periods: a simulated arm does not jump.
        dt = min(dt, 3.0 / self.rate_hz)
        self._last_cycle_ns = now_ns
        command = self._command
        if command is not None and now_ns - self._command_time_ns > self.command_timeout_ns:
            command = None
        integrator = self.integrator
        integrator.step(command, dt)

        # System time is ROS time unless use_sim_time (checked once at start).
        stamp_ns = self.ros_time_ns()
        self._joint_state_pub.publish(
            self._joint_state_cdr.encode_values(stamp_ns, integrator.q_values, integrator.qdot_values)
        )
        self._ee_pose_pub.publish(self._pose_cdr.encode_values(stamp_ns, integrator.ee_values))
        self._tool_pose_pub.publish(self._pose_cdr.encode_values(stamp_ns, integrator.tool_values))
        self._ee_twist_pub.publish(self._twist_cdr.encode_values(stamp_ns, integrator.ee_twist_values))
        self._tool_twist_pub.publish(self._twist_cdr.encode_values(stamp_ns, integrator.tool_twist_values))
        self.visuals.cycle(now_ns, stamp_ns, integrator.q_values, integrator.tool_values)

        if self._diagnostics_period_ns and now_ns - self._last_diagnostics_ns >= self._diagnostics_period_ns:
            self._last_diagnostics_ns = now_ns
            self._publish_diagnostics(conv.ns_to_stamp(stamp_ns), now_ns, command is not None)

    def _publish_diagnostics(self, stamp, now_ns: int, command_fresh: bool) -> None:
        integrator = self.integrator
        if self._command is None:
            command_state = "none yet"
        else:
            command_state = "fresh" if command_fresh else "stale (counted as zero)"
        limited = [self.model.joint_names[i] for i in np.flatnonzero(integrator.at_limit)]
        values = [
            ("robot", self.model.name),
            ("command", command_state),
            ("command_age_s", f"{(now_ns - self._command_time_ns) * 1e-9:.4f}" if self._command is not None else "inf"),
            ("rejected_commands", str(self.rejected_commands)),
            ("joints_at_limit", ",".join(limited)),
            ("velocity_scale", f"{integrator.velocity_scale:.4f}"),
            ("loop_error", self.loop_error()),
        ] + stats_key_values(self.loop.stats())
        level = self.diagnostic_level("warn" if limited or self.rejected_commands else "ok")
        status = conv.make_diagnostic_status(self.status_name, level, command_state, self.model.name, values)
        self._diagnostics_pub.publish(conv.make_diagnostic_array(stamp, [status]))


def main(argv=None) -> int:
    """Entry point of the ``robot_state`` executable."""
    return run_node(RobotStateNode, USAGE, argv, on_shutdown=lambda node: node.stop())


if __name__ == "__main__":
    sys.exit(main())
