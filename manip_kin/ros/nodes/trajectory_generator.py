"""``trajectory_generator``: streams a straight line to a pose target, or a joint-space trajectory.

On each valid ``line_target`` the node plans a :class:`~manip_kin.motion.lines.LineTrajectory`
from the tool pose of the newest ``joint_states`` (its own FK: any driver's joint states
will do, no robot_state needed), checks the arm can follow it from that configuration
(:func:`~manip_kin.motion.line_reach.check_line_reachable`),
publishes it on ``planned_path`` and then, every cycle of its
:class:`~manip_kin.ros.runtime.rate_loop.RateLoop`, publishes the sampled ``goal_pose`` and
``goal_twist`` until the end. At the end it publishes the final pose once with a zero
twist and stops streaming: the controller holds its last goal, and a goal sent later by
hand (``manip_kin goal``) is not overwritten. A new target pre-empts a running line, from
the current tool pose; a rejected target leaves a running line alone.

On a ``joint_trajectory`` (``trajectory_msgs/JointTrajectory``, as ros2_control's
JointTrajectoryController takes it) it plans a
:class:`~manip_kin.motion.joint_trajectory.JointTrajectoryPlan` from the newest ``joint_states``
and streams ``joint_reference`` (``sensor_msgs/JointState``: positions and velocities by
joint name) the same way, ending with the last point at rest. The latest goal of either
kind wins. The ``task`` (as the controller's) decides what a line must reach: a
position-only task keeps the start orientation and checks the position only.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from manip_kin.control.generator_supervisor import GeneratorState, GeneratorSupervisor
from manip_kin.core.bounds import InputBounds
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.pose_rows import parse_task
from manip_kin.errors import ManipKinError, Problem
from manip_kin.motion.joint_trajectory import plan_joint_trajectory
from manip_kin.motion.line_reach import check_line_reachable
from manip_kin.motion.line_timing import constant_scaling_problem, line_limits_problem
from manip_kin.motion.lines import LineTrajectory
from manip_kin.ros.nodes.joint_limit_params import joint_limit_parameters
from manip_kin.ros.nodes.path_check import PathCheck, joint_path
from manip_kin.ros.nodes.robot_description import joints_problem
from manip_kin.ros.nodes.robot_model import load_node_model
from manip_kin.ros.nodes.trajectory_generator_interface import NODE_NAME, USAGE, GeneratorParams
from manip_kin.ros.nodes.trajectory_generator_outputs import MotionStream
from manip_kin.ros.nodes.trajectory_generator_params import check_limits, generator_settings
from manip_kin.ros.runtime.declared_params import LiveParameters, declare_group, declare_parameters
from manip_kin.ros.runtime.looping_node import LoopingNode
from manip_kin.ros.runtime.params import period_ns
from manip_kin.ros.runtime.polling import PolledSubscription
from manip_kin.ros.runtime.rate_loop import stats_key_values
from manip_kin.ros.runtime.runner import run_node
from manip_kin.ros.runtime.throttled_log import ThrottledLog
from manip_kin.ros.wire.joint_messages import trajectory_points
from manip_kin.ros.wire.messages import ns_to_stamp, pose_stamped_to_matrix, stamp_key, stamp_to_ns
from manip_kin.ros.wire.topics import latest_state_qos
from manip_kin.ros.wire.validation import InvalidMessageError, JointStateMapper, pose_problem


class TrajectoryGeneratorNode(LoopingNode):
    """ROS handles around a :class:`~manip_kin.control.generator_supervisor.GeneratorSupervisor` and the motion it runs."""

    def __init__(self, **node_kwargs):
        super().__init__(NODE_NAME, **node_kwargs)
        params = declare_parameters(self, GeneratorParams)
        self.model = load_node_model(self, params, self._switch_model)
        limit_specs = joint_limit_parameters(self.model)
        params = declare_group(self, params, limit_specs)
        self.base_frame = params.base_frame or self.model.base_frame
        self.rate_hz = params.rate_hz
        self.supervisor = GeneratorSupervisor(period_ns(params.diagnostics_rate_hz))
        self._params = params
        self.bounds = InputBounds.of(self.model)
        self.path_check = PathCheck(self, params, ThrottledLog(self.get_logger().warning, 1.0))
        self._configure(params)
        LiveParameters(self, params, self._set_parameters, limit_specs)

        self._target_sub = PolledSubscription(self, PoseStamped, "line_target", 10)
        self._trajectory_sub = PolledSubscription(self, JointTrajectory, "joint_trajectory", 10)
        # Depth 1 and read only when a target comes or a status is due: the newest state is all
        # a plan (and its age in the status) needs, and not turning 1 kHz of state messages into
        # Python objects keeps this loop cheap.
        self._joint_state_sub = PolledSubscription(self, JointState, "joint_states", latest_state_qos(1))
        self.stream = MotionStream(self, self.base_frame, self.model.joint_names)
        # The service only sets the flag; the loop stops the motion (one writer of the state).
        self._stop_requested = False
        self.create_service(Trigger, "~/stop", self._on_stop)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._mapper = JointStateMapper(self.model.joint_names, self.bounds.position_lower, self.bounds.position_upper)

        self._start_stamp_ns = 0
        self._joint_state_msg: JointState | None = None
        # Lines are planned for the frame robot_state calls the tool (the end effector without one).
        self._start_frame = self.model.frame_index(self.model.default_frame)
        self._warn = ThrottledLog(self.get_logger().warning, 0.5)
        self._error = ThrottledLog(self.get_logger().error, 0.5)

        self.get_logger().info(
            f"robot {self.model.name}: {self.time_scaling} lines at <= {self.limits.max_linear_velocity:g} m/s, "
            f"{self.limits.max_angular_velocity:g} rad/s (task {self.task.name}), {self.joint_time_scaling} "
            f"joint trajectories, streamed at {self.rate_hz:g} Hz"
        )
        self.start_loop(
            self.rate_hz,
            self._cycle,
            params.realtime_priority,
            params.scheduler_slice,
            wake_on=(self._target_sub,),
        )

    @property
    def state(self) -> GeneratorState:
        """The current state (see :class:`~manip_kin.control.generator_supervisor.GeneratorState`)."""
        return self.supervisor.state

    # --- parameters ----------------------------------------------------------------------------

    def _configure(self, params: GeneratorParams) -> None:
        """Limits and checks from ``params`` (at start and on a live change; the next line uses them).

        Raises:
            ManipKinError: limits the planner cannot use.
        """
        settings = generator_settings(self.model, self.bounds, params)
        self.limits, self.joint_limits, self.task = settings.limits, settings.joint_limits, settings.task
        self.time_scaling = settings.time_scaling
        self.joint_time_scaling = settings.joint_time_scaling
        self.check_reach = settings.check_reach
        self._joint_state_timeout_ns = settings.joint_state_timeout_ns
        self._quaternion_tolerance = settings.quaternion_tolerance
        self._path_points = settings.path_points
        self.path_check.safety_distance = settings.collision_safety_distance
        self.supervisor.throttle.period_ns = settings.diagnostics_period_ns

    def _set_parameters(self, params: GeneratorParams) -> str | None:
        """Live change of tunable parameters: None once in use (from the next line on), else why not."""
        try:
            self._configure(params)
        except ManipKinError as error:  # raised before anything changed
            return str(error)
        self._params = params
        return None

    def _switch_model(self, model) -> str | None:
        """``~/reload_robot_description``: plan the next motion with ``model`` (the same joints),
        or why not (nothing changes); a running motion keeps its plan."""
        problem = joints_problem(self.model, model) or (
            "collision_check: the collision geometry was built at start; restart the node for a new URDF"
            if self.path_check.enabled
            else None
        )
        if problem:
            return problem
        bounds = InputBounds.of(model)
        try:
            check_limits(self.limits, bounds)
            task = parse_task(self._params.task or None, model)
            start_frame = model.frame_index(model.default_frame)
        except ManipKinError as error:
            return f"cannot plan for the new model {model.name!r} as configured: {error}"
        self._mapper = JointStateMapper(model.joint_names, bounds.position_lower, bounds.position_upper)
        self.model, self.bounds, self.task, self._start_frame = model, bounds, task, start_frame
        return None

    # --- inputs --------------------------------------------------------------------------------

    def _take_inputs(self, now_ns: int) -> PoseStamped | JointTrajectory | None:
        """Drain the goals; return the newest valid one of either kind (None when there is none).

        When a line target and a trajectory come in the same cycle, the later stamp wins. One
        sent again with the stamp of the motion already taken is dropped (``has_taken``); an
        unstamped one (zero) is always new.
        """

        def taken(msg) -> bool:
            stamp = msg.header.stamp
            return bool(stamp.sec or stamp.nanosec) and self.supervisor.has_taken(stamp_key(stamp))

        target = None
        while (msg := self._target_sub.take()) is not None:
            if taken(msg):
                continue
            problem = pose_problem(
                msg, self.base_frame, "line target", self._quaternion_tolerance, self.bounds.max_target_distance
            )
            if problem is not None:
                self._reject(msg, problem)
                continue
            target = msg
        trajectory = None
        while (msg := self._trajectory_sub.take()) is not None:
            if not taken(msg):
                trajectory = msg  # checked when planned
        if target is None or (
            trajectory is not None and stamp_to_ns(trajectory.header.stamp) >= stamp_to_ns(target.header.stamp)
        ):
            return trajectory
        return target

    def _reject(self, msg: PoseStamped | JointTrajectory, reason: str, kind: str = "invalid") -> None:
        """Refuse ``msg`` for ``reason`` (a :class:`Problem` keys the log line on its kind; any
        other text, a reach or collision reason, on ``other``); ``kind`` is what the status says."""
        kept = self.supervisor.reject(reason, stamp_key(msg.header.stamp), kind)
        topic = self._trajectory_sub if isinstance(msg, JointTrajectory) else self._target_sub
        self._error(
            "target:" + Problem.of(reason).kind,
            f"rejected {topic.subscription.topic_name}: {reason}; {kept}",
        )

    def _newest_joint_state(self) -> tuple[JointState | None, float]:
        """The newest joint state taken so far, and its age by its stamp [ns] (inf: none yet)."""
        while (state := self._joint_state_sub.take()) is not None:
            self._joint_state_msg = state
        state = self._joint_state_msg
        if state is None:
            return None, math.inf
        return state, self.get_clock().now().nanoseconds - stamp_to_ns(state.header.stamp)

    def _current_positions(self, msg: PoseStamped | JointTrajectory) -> np.ndarray | None:
        """The newest joint positions (model order); None (and ``msg`` rejected) when there is no
        usable joint state younger than ``joint_state_timeout``."""
        state, age_ns = self._newest_joint_state()
        topic = self._joint_state_sub.subscription.topic_name
        if state is None or age_ns > self._joint_state_timeout_ns:
            self._reject(msg, f"no current {topic} (is robot_state or the robot's driver running?)")
            return None
        try:
            return self._mapper.positions(state)
        except InvalidMessageError as error:
            self._reject(msg, Problem(error.kind, f"cannot start from the current {topic}: {error}"))
            return None

    # --- planning ----------------------------------------------------------------------------------

    def _plan_trajectory(self, msg: JointTrajectory) -> int | None:
        """Plan a joint trajectory from the current joint state; its start time [ns] when it started."""
        q = self._current_positions(msg)
        if q is None:
            return None
        try:
            names, points = trajectory_points(msg)
            plan = plan_joint_trajectory(self.model, q, names, points, self.joint_time_scaling, self.joint_limits)
            collision = self.path_check.problem(*joint_path(plan), "joint trajectory")
        except ManipKinError as error:
            self._reject(msg, Problem.of(error))
            return None
        if collision:
            self._reject(msg, collision, "unreachable")
            return None
        detail = f"joint trajectory of {plan.point_count} point(s) in {plan.duration:.3f} s"
        times = np.linspace(0.0, plan.duration, self._path_points)
        self.stream.publish_path([frame_pose(self.model, plan.sample(t)[0]) for t in times])
        # It starts once planned and published (that takes a few ms): its first reference is
        # then where the arm is.
        now_ns = self._start_now()
        preempted = self.supervisor.start(plan, "joint trajectory", now_ns, stamp_key(msg.header.stamp), detail)
        self.get_logger().info(
            f"{'pre-empted the running motion; ' if preempted else ''}streaming a {self.joint_time_scaling} "
            f"{detail} from {np.round(q, 4).tolist()} to {np.round(plan.goal, 4).tolist()}"
        )
        return now_ns

    def _start_now(self) -> int:
        """The monotonic time a motion starts at; sets its start on the ROS clock: samples are
        stamped with the time they are for, start + t (a controller moves a sample to the
        instant its command acts at by that stamp)."""
        now_ns = time.monotonic_ns()
        self._start_stamp_ns = self.ros_time_at(now_ns)
        return now_ns

    def _plan(self, target_msg: PoseStamped, now_ns: int) -> bool:
        """Plan a line to ``target_msg``; True when it replaced the running line."""
        q = self._current_positions(target_msg)
        if q is None:
            return False
        start = frame_pose(self.model, q, self._start_frame)
        goal = pose_stamped_to_matrix(target_msg)
        if not self.task.orientation_rows:
            goal[:3, :3] = start[:3, :3]  # orientation free: keep it, and do not time the line by a turn
        try:
            line = LineTrajectory.plan(start, goal, self.time_scaling, self.limits)
            refused = constant_scaling_problem(line, self.joint_limits)
            if refused:
                self._reject(target_msg, refused)
                return False
            if self.check_reach:
                report = check_line_reachable(self.model, line, q, task=self.task)
                if not report.reachable:
                    self._reject(target_msg, report.reason, "unreachable")
                    return False
                collision = self.path_check.problem(report.path, report.progress, "line")
                if collision:
                    self._reject(target_msg, collision, "unreachable")
                    return False
                too_fast = line_limits_problem(self.model, line, report, self.joint_limits)
                if too_fast:
                    self._warn("line:limits", too_fast)
        except ManipKinError as error:
            self._reject(target_msg, Problem.of(error))
            return False
        detail = f"line of {line.length:.4f} m, {line.angle:.4f} rad in {line.duration:.3f} s"
        # The line starts now that it is planned: planning (the reach check) can take longer
        # than a period, and starting it at the cycle's time would skip its first part (a jump).
        preempted = self.supervisor.start(line, "line", self._start_now(), stamp_key(target_msg.header.stamp), detail)
        self.get_logger().info(
            f"{'pre-empted the running motion; ' if preempted else ''}streaming a {self.time_scaling} line "
            f"from {np.round(start[:3, 3], 4).tolist()} to {np.round(goal[:3, 3], 4).tolist()}: {detail}"
        )
        self.stream.publish_path(line.sample_path(self._path_points))
        return True

    # --- the cycle -------------------------------------------------------------------------------

    def publish_safe_output(self) -> None:
        """After a failed cycle: stop streaming and hold the last goal (sent again, at rest)."""
        if not self.supervisor.stop("stopped streaming after a cycle error; holding the last goal"):
            return
        self.stream.hold(self.supervisor.motion)

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._stop_requested = True
        response.success = True
        response.message = "stopping the stream; the last goal sent is held"
        return response

    def _cycle(self, now_ns: int) -> None:
        self.path_check.take()
        target = self._take_inputs(now_ns)
        supervisor = self.supervisor
        if self._stop_requested:
            self._stop_requested = False
            target = None
            if supervisor.stop("stopped on request; holding the last goal sent"):
                self.get_logger().info(f"{supervisor.motion_kind} stopped on request")
        if target is not None:
            started = self._plan_trajectory(target) if isinstance(target, JointTrajectory) else None
            if not isinstance(target, JointTrajectory):
                self._plan(target, now_ns)
            # The loop's clock after planning (see _plan); a trajectory's first sample is its start.
            now_ns = started if started is not None else time.monotonic_ns()
        timing = supervisor.time_into_motion(now_ns)
        if timing is not None:
            t, finished = timing
            stamp_ns = self._start_stamp_ns + int(t * 1e9)
            self.stream.publish(supervisor.motion, t, stamp_ns)
            if finished:
                supervisor.finish(stamp_key(ns_to_stamp(stamp_ns)))
                self.get_logger().info(f"{supervisor.motion_kind} finished after {t:.3f} s; holding its end")
        if supervisor.report_due(now_ns):
            self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        supervisor = self.supervisor
        motion = supervisor.motion
        age_ns = self._newest_joint_state()[1]
        values = [
            ("state", supervisor.state),
            ("detail", supervisor.detail),
            # How old the state a target would start from is now (a target finds none older
            # than joint_state_timeout usable): "inf" before the first joint_states.
            ("joint_state_age_s", f"{age_ns * 1e-9:.3f}" if math.isfinite(age_ns) else "inf"),
            ("target_stamp", supervisor.target_stamp),
            ("final_goal_stamp", supervisor.final_goal_stamp),
            # When the motion's first sample went out (ROS clock); its last one is final_goal_stamp.
            ("started_stamp", self.stamp_key_of(supervisor.started_ns) if supervisor.started_ns else ""),
            ("progress", f"{supervisor.progress:.4f}"),
            ("duration", f"{motion.duration:.4f}" if motion is not None else ""),
            ("length", f"{motion.length:.6f}" if isinstance(motion, LineTrajectory) else ""),
            ("motion", supervisor.motion_kind),
            ("time_scaling", self.time_scaling),
            ("joint_time_scaling", self.joint_time_scaling),
            ("task", self.task.name),
            ("rejected_targets", str(supervisor.rejected_targets)),
            ("rejected_stamp", supervisor.rejected_stamp),
            ("last_rejection", supervisor.last_rejection),
            ("rejection_kind", supervisor.rejection_kind),
            ("loop_error", self.loop_error()),
        ] + stats_key_values(self.loop.stats())
        level = self.diagnostic_level(supervisor.level)
        self.publish_status(level, supervisor.state, values)


def main(argv=None) -> int:
    """Entry point of the ``trajectory_generator`` executable."""
    return run_node(TrajectoryGeneratorNode, USAGE, argv, on_shutdown=lambda node: node.stop())


if __name__ == "__main__":
    sys.exit(main())
