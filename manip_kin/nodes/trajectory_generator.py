"""``trajectory_generator``: streams a straight-line goal from the current tool pose to a target.

On each valid ``line_target`` the node plans a :class:`~manip_kin.trajectory.LineTrajectory`
from the newest ``tool_pose``, checks the arm can follow it
(:func:`~manip_kin.trajectory.check_line_reachable` from the newest ``joint_states``),
publishes it on ``planned_path`` and then, every cycle of its
:class:`~manip_kin.nodes.rate_loop.RateLoop`, publishes the sampled ``goal_pose`` and
``goal_twist`` until the end. At the end it publishes the final pose once with a zero
twist and stops streaming: the controller holds its last goal, and a goal sent later by
hand (``manip_kin goal``) is not overwritten. A new target pre-empts a running line, from
the current tool pose; a rejected target leaves a running line alone.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Path
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from manip_kin.bounds import UNBOUNDED, InputBounds
from manip_kin.errors import InvalidArgumentError, ManipKinError
from manip_kin.nodes import conversions as conv
from manip_kin.nodes.params import LiveParameters, ParamSpec, declare_parameters, usage_text
from manip_kin.nodes.rate_loop import LoopingNode, PolledSubscription, ThrottledLog, stats_key_values
from manip_kin.nodes.robot_model import load_node_model, model_parameters
from manip_kin.nodes.runner import run_node
from manip_kin.supervisors import GeneratorState, GeneratorSupervisor
from manip_kin.trajectory import TIME_SCALINGS, LineTrajectory, MotionLimits, check_line_reachable

NODE_NAME = "trajectory_generator"

#: States reported on /diagnostics.
STATES = tuple(state.value for state in GeneratorState)

PARAMETERS = (
    *model_parameters(""),
    ParamSpec("rate_hz", "float", 500.0, "rate of goal_pose and goal_twist while a line runs", "Hz", positive=True),
    ParamSpec(
        "time_scaling", "str", "trapezoidal", "progress along the line over time", choices=TIME_SCALINGS, tunable=True
    ),
    ParamSpec(
        "max_linear_velocity",
        "float",
        0.25,
        "speed limit of the position (the constant speed of 'constant')",
        "m/s",
        positive=True,
        tunable=True,
    ),
    ParamSpec(
        "max_linear_acceleration",
        "float",
        0.5,
        "acceleration limit of the position (not used by 'constant')",
        "m/s^2",
        positive=True,
        tunable=True,
    ),
    ParamSpec(
        "max_angular_velocity",
        "float",
        0.5,
        "angular speed limit of the orientation",
        "rad/s",
        positive=True,
        tunable=True,
    ),
    ParamSpec(
        "max_angular_acceleration",
        "float",
        1.0,
        "angular acceleration limit (not used by 'constant')",
        "rad/s^2",
        positive=True,
        tunable=True,
    ),
    ParamSpec("check_reach", "bool", True, "reject a line the arm cannot follow within its joint limits", tunable=True),
    ParamSpec(
        "base_frame", "str", "", "frame id of targets and published goals ('' = the robot's base frame, base_link)"
    ),
    ParamSpec(
        "tool_pose_timeout",
        "float",
        0.5,
        "a target is rejected when tool_pose is older than this",
        "s",
        positive=True,
        tunable=True,
    ),
    ParamSpec(
        "quaternion_tolerance",
        "float",
        1e-2,
        "a target quaternion whose length differs from 1 by more is rejected",
        positive=True,
        tunable=True,
    ),
    ParamSpec("path_points", "int", 50, "poses in planned_path", positive=True, tunable=True),
    ParamSpec(
        "diagnostics_rate_hz",
        "float",
        5.0,
        "rate of /diagnostics (also sent at once on a state change)",
        "Hz",
        positive=True,
        tunable=True,
    ),
    ParamSpec(
        "realtime_priority",
        "int",
        0,
        "SCHED_FIFO priority 1..99 of the loop thread (0 = normal scheduling; needs root/CAP_SYS_NICE)",
        minimum=0,
    ),
)

USAGE = usage_text(
    NODE_NAME,
    "Straight-line goals: on a line_target pose, plans a line from the current tool_pose\n"
    "(position along the segment, orientation by slerp) timed by time_scaling within the\n"
    "velocity and acceleration limits, checks the arm can follow it from the current\n"
    "joint_states, and streams goal_pose and goal_twist at rate_hz until the end, then\n"
    "publishes the final pose once and holds. A new target pre-empts the running line.\n"
    "Unreachable or malformed targets are rejected with a log line.",
    PARAMETERS,
    subscribes=[
        ("line_target", "geometry_msgs/PoseStamped", "end pose of the line, frame_id = base frame"),
        ("tool_pose", "geometry_msgs/PoseStamped", "current tool pose (start of a line)"),
        ("joint_states", "sensor_msgs/JointState", "current configuration (reach check)"),
    ],
    publishes=[
        ("goal_pose", "geometry_msgs/PoseStamped", "the line's pose at each cycle"),
        ("goal_twist", "geometry_msgs/TwistStamped", "the line's velocity (feed-forward)"),
        ("planned_path", "nav_msgs/Path", "the planned line, transient local"),
        ("/diagnostics", "diagnostic_msgs/DiagnosticArray", "state, progress, target and final goal stamps"),
    ],
    example=f"{NODE_NAME} --ros-args -p robot:=irb120 -p time_scaling:=constant -p max_linear_velocity:=0.4",
)


class TrajectoryGeneratorNode(LoopingNode):
    """ROS handles around a :class:`~manip_kin.supervisors.GeneratorSupervisor` and the motion it runs."""

    def __init__(self, **node_kwargs):
        super().__init__(NODE_NAME, **node_kwargs)
        params = declare_parameters(self, PARAMETERS)
        self.model = load_node_model(self, params)
        self.base_frame = params["base_frame"] or self.model.base_frame
        self.rate_hz = params["rate_hz"]
        self.supervisor = GeneratorSupervisor(int(1e9 / params["diagnostics_rate_hz"]))
        self._params = params
        self.bounds = InputBounds.of(self.model)
        self._configure(params)
        LiveParameters(self, PARAMETERS, self._set_parameters)

        self._target_sub = PolledSubscription(self, PoseStamped, "line_target", 10)
        # Depth 1 and read only when a target comes: the newest state is all a plan needs, and
        # not turning 2 kHz of state messages into Python objects keeps this loop cheap.
        self._tool_pose_sub = PolledSubscription(self, PoseStamped, "tool_pose", 1)
        self._joint_state_sub = PolledSubscription(self, JointState, "joint_states", 1)
        self._goal_pub = self.create_publisher(PoseStamped, "goal_pose", 10)
        self._twist_pub = self.create_publisher(TwistStamped, "goal_twist", 10)
        latched = QoSProfile(
            depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
        )
        self._path_pub = self.create_publisher(Path, "planned_path", latched)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._goal_cdr = conv.PoseStampedCdr(self.base_frame)
        self._twist_cdr = conv.TwistStampedCdr(self.base_frame)
        self._mapper = conv.JointStateMapper(
            self.model.joint_names, self.bounds.position_lower, self.bounds.position_upper
        )
        self._last_goal_pose: np.ndarray | None = None

        self._tool_pose_msg: PoseStamped | None = None
        self._joint_state_msg: JointState | None = None
        self._warn = ThrottledLog(self.get_logger().warning, 0.5)
        self._error = ThrottledLog(self.get_logger().error, 0.5)

        self.get_logger().info(
            f"robot {self.model.name}: {self.time_scaling} lines at <= {self.limits.max_linear_velocity:g} m/s, "
            f"{self.limits.max_angular_velocity:g} rad/s, streamed at {self.rate_hz:g} Hz"
        )
        self.start_loop(self.rate_hz, self._cycle, params["realtime_priority"], wake_on=(self._target_sub,))

    @property
    def state(self) -> GeneratorState:
        """The current state (see :class:`~manip_kin.supervisors.GeneratorState`)."""
        return self.supervisor.state

    @property
    def rejected_targets(self) -> int:
        """Targets rejected since the start."""
        return self.supervisor.rejected_targets

    @property
    def last_rejection(self) -> str:
        """Why the last target was rejected."""
        return self.supervisor.last_rejection

    # --- parameters ----------------------------------------------------------------------------

    def _configure(self, params: dict) -> None:
        """Limits and checks from ``params`` (at start and on a live change; the next line uses them).

        Raises:
            ManipKinError: limits the planner cannot use.
        """
        limits = MotionLimits(
            max_linear_velocity=params["max_linear_velocity"],
            max_linear_acceleration=params["max_linear_acceleration"],
            max_angular_velocity=params["max_angular_velocity"],
            max_angular_acceleration=params["max_angular_acceleration"],
        )
        _check_limits(limits, self.bounds)
        self.limits = limits
        self.time_scaling = params["time_scaling"]
        self.check_reach = params["check_reach"]
        self._tool_pose_timeout_ns = int(params["tool_pose_timeout"] * 1e9)
        self._quaternion_tolerance = params["quaternion_tolerance"]
        self._path_points = max(2, params["path_points"])
        self.supervisor.throttle.period_ns = int(1e9 / params["diagnostics_rate_hz"])

    def _set_parameters(self, updates: dict) -> str | None:
        """Live change of tunable parameters: None once in use (from the next line on), else why not."""
        params = {**self._params, **updates}
        try:
            self._configure(params)
        except ManipKinError as error:  # raised before anything changed
            return str(error)
        self._params = params
        return None

    # --- inputs --------------------------------------------------------------------------------

    def _take_inputs(self, now_ns: int) -> PoseStamped | None:
        """Drain the targets; return the newest valid one (None when there is none)."""
        target = None
        while (msg := self._target_sub.take()) is not None:
            problem = conv.pose_problem(
                msg, self.base_frame, "line target", self._quaternion_tolerance, self.bounds.max_target_distance
            )
            if problem is not None:
                self._reject(msg, problem)
                continue
            target = msg
        return target

    def _reject(self, msg: PoseStamped, reason: str) -> None:
        kept = self.supervisor.reject(reason, conv.stamp_key(msg.header.stamp))
        self._error(
            "target:" + conv.problem_kind(reason),
            f"rejected {self._target_sub.subscription.topic_name}: {reason}; {kept}",
        )

    # --- planning ----------------------------------------------------------------------------------

    def _plan(self, target_msg: PoseStamped, now_ns: int) -> bool:
        """Plan a line to ``target_msg``; True when it replaced the running line."""
        while (msg := self._tool_pose_sub.take()) is not None:
            self._tool_pose_msg = msg
        while (msg := self._joint_state_sub.take()) is not None:
            self._joint_state_msg = msg
        clock_ns = self.get_clock().now().nanoseconds
        if (
            self._tool_pose_msg is None
            or clock_ns - conv.stamp_to_ns(self._tool_pose_msg.header.stamp) > self._tool_pose_timeout_ns
        ):
            self._reject(
                target_msg, f"no current {self._tool_pose_sub.subscription.topic_name} (is robot_state running?)"
            )
            return False
        tool_problem = conv.pose_problem(
            self._tool_pose_msg,
            self.base_frame,
            "tool pose",
            self._quaternion_tolerance,
            self.bounds.max_target_distance,
        )
        if tool_problem is not None:
            self._reject(target_msg, f"cannot start from the current tool pose: {tool_problem}")
            return False
        start = conv.pose_stamped_to_matrix(self._tool_pose_msg)
        goal = conv.pose_stamped_to_matrix(target_msg)
        try:
            line = LineTrajectory.plan(start, goal, self.time_scaling, self.limits)
            if self.check_reach:
                if self._joint_state_msg is None:
                    self._reject(
                        target_msg,
                        f"no {self._joint_state_sub.subscription.topic_name} received yet for the reach check",
                    )
                    return False
                q = self._mapper.positions(self._joint_state_msg)
                report = check_line_reachable(self.model, line, q)
                if not report.reachable:
                    self._reject(target_msg, report.reason)
                    return False
        except ManipKinError as error:
            self._reject(target_msg, str(error))
            return False
        detail = f"line of {line.length:.4f} m, {line.angle:.4f} rad in {line.duration:.3f} s"
        # The line starts now that it is planned: planning (the reach check) can take longer
        # than a period, and starting it at the cycle's time would skip its first part (a jump).
        preempted = self.supervisor.start(
            line, "line", time.monotonic_ns(), conv.stamp_key(target_msg.header.stamp), detail
        )
        self.get_logger().info(
            f"{'pre-empted the running motion; ' if preempted else ''}streaming a {self.time_scaling} line "
            f"from {np.round(start[:3, 3], 4).tolist()} to {np.round(goal[:3, 3], 4).tolist()}: {detail}"
        )
        self._publish_path(line)
        return True

    def _publish_path(self, line: LineTrajectory) -> None:
        path = Path()
        stamp = self.get_clock().now().to_msg()
        path.header.stamp = stamp
        path.header.frame_id = self.base_frame
        path.poses = [
            conv.make_pose_stamped(pose, self.base_frame, stamp) for pose in line.sample_path(self._path_points)
        ]
        self._path_pub.publish(path)

    # --- the cycle -------------------------------------------------------------------------------

    def publish_safe_output(self) -> None:
        """After a failed cycle: stop streaming and hold the last goal (sent again, at zero twist)."""
        if not self.supervisor.stop("stopped streaming after a cycle error; holding the last goal"):
            return
        if self._last_goal_pose is not None:
            stamp_ns = self.get_clock().now().nanoseconds
            self._goal_pub.publish(self._goal_cdr.encode(stamp_ns, self._last_goal_pose))
            self._twist_pub.publish(self._twist_cdr.encode(stamp_ns, np.zeros(3), np.zeros(3)))

    def _cycle(self, now_ns: int) -> None:
        target = self._take_inputs(now_ns)
        supervisor = self.supervisor
        if target is not None:
            self._plan(target, now_ns)
            now_ns = time.monotonic_ns()  # the loop's clock, after planning (see _plan)
        timing = supervisor.time_into_motion(now_ns)
        if timing is not None:
            t, finished = timing
            pose, (angular, linear) = supervisor.motion.sample(t)
            stamp_ns = self.get_clock().now().nanoseconds
            self._goal_pub.publish(self._goal_cdr.encode(stamp_ns, pose))
            self._last_goal_pose = pose
            self._twist_pub.publish(self._twist_cdr.encode(stamp_ns, angular, linear))
            if finished:
                supervisor.finish(conv.stamp_key(conv.ns_to_stamp(stamp_ns)))
                self.get_logger().info(f"line finished after {t:.3f} s; holding the final pose")
        if supervisor.report_due(now_ns):
            self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        supervisor = self.supervisor
        motion = supervisor.motion
        values = [
            ("state", supervisor.state),
            ("detail", supervisor.detail),
            ("target_stamp", supervisor.target_stamp),
            ("final_goal_stamp", supervisor.final_goal_stamp),
            ("progress", f"{supervisor.progress:.4f}"),
            ("duration", f"{motion.duration:.4f}" if motion is not None else ""),
            ("length", f"{motion.length:.6f}" if motion is not None else ""),
            ("time_scaling", self.time_scaling),
            ("rejected_targets", str(supervisor.rejected_targets)),
            ("rejected_stamp", supervisor.rejected_stamp),
            ("last_rejection", supervisor.last_rejection),
            ("loop_error", self.loop_error()),
        ] + stats_key_values(self.loop.stats())
        level = self.diagnostic_level(supervisor.level)
        status = conv.make_diagnostic_status(self.status_name, level, supervisor.state, self.model.name, values)
        self._diagnostics_pub.publish(conv.make_diagnostic_array(self.get_clock().now().to_msg(), [status]))


def _check_limits(limits: MotionLimits, bounds: InputBounds) -> None:
    """Refuse speed limits far beyond what the arm can do (a typo such as 1e30 m/s)."""
    for name, value, valid in (
        ("max_linear_velocity", limits.max_linear_velocity, bounds.max_twist_linear),
        ("max_angular_velocity", limits.max_angular_velocity, bounds.max_twist_angular),
        ("max_linear_acceleration", limits.max_linear_acceleration, UNBOUNDED),
        ("max_angular_acceleration", limits.max_angular_acceleration, UNBOUNDED),
    ):
        if value > valid:
            raise InvalidArgumentError(
                f"parameter {name} = {value:g} is absurd for this arm; valid: <= {valid:.4g} (twice what it can do)"
            )


def main(argv=None) -> int:
    """Entry point of the ``trajectory_generator`` executable."""
    return run_node(TrajectoryGeneratorNode, USAGE, argv, on_shutdown=lambda node: node.stop())


if __name__ == "__main__":
    sys.exit(main())
