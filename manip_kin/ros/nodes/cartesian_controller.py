"""``cartesian_controller``: pose goals, joint references, twists and jogs to joint-rate commands.

The node holds one :class:`~manip_kin.control.resolved_rate.CartesianController` (or, with collision
avoidance or a posture, the QP law), one :class:`~manip_kin.control.state_machines.ControllerSupervisor`
and one :class:`~manip_kin.control.command_filter.CommandFilter`; every cycle of its
:class:`~manip_kin.ros.runtime.rate_loop.RateLoop` it takes the newest joint state and commands, runs
one control step for the newest command of any kind (a pose goal with its feed-forward twist,
a joint reference, ``twist_command``, ``joint_jog``) and publishes the filter's next command on
``joint_velocity_commands``: within the joint limits, always. ``~/stop`` and ``~/pause`` and
every way the node ends bring the commands to rest (:meth:`CartesianControllerNode.halt`).
``/diagnostics`` carries the state (see :data:`STATES`), the errors and the loop timing,
at ``diagnostics_rate_hz`` and at once when the state changes.
"""

from __future__ import annotations

import sys
import time
from collections import deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from manip_kin.control.command_filter import CommandFilter
from manip_kin.control.joint_tracking import JointTrackingOutput, joint_tracking_step
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig, ControlOutput
from manip_kin.control.servo import SingularityScaling
from manip_kin.control.state_machines import (
    HALTED_STATES,
    SERVO_KINDS,
    ControllerState,
    ControllerSupervisor,
    ControllerSupervisorConfig,
    GoalKind,
)
from manip_kin.control.state_prediction import (
    MAX_STATE_AGE_PERIODS,
    PLAUSIBLE_RATE_FACTOR,
    predict_positions,
    prediction_horizon,
)
from manip_kin.control.streamed_goal import StreamedGoal, reference_at
from manip_kin.core.bounds import InputBounds
from manip_kin.core.kinematics import frame_pose
from manip_kin.errors import ManipKinError, Problem
from manip_kin.ros.nodes.cartesian_controller_interface import NODE_NAME, PARAMETERS, STATES, USAGE  # noqa: F401 - re-exported
from manip_kin.ros.nodes.collision_inputs import CollisionInputs
from manip_kin.ros.nodes.joint_limit_params import joint_limit_parameters, joint_limits_from_params
from manip_kin.ros.nodes.robot_description import joints_problem
from manip_kin.ros.nodes.robot_model import load_node_model
from manip_kin.ros.nodes.servo_inputs import ServoInputs
from manip_kin.ros.runtime.declared_params import LiveParameters, declare_parameters
from manip_kin.ros.runtime.looping_node import LoopingNode
from manip_kin.ros.runtime.params import period_ns
from manip_kin.ros.runtime.polling import PolledSubscription
from manip_kin.ros.runtime.rate_loop import stats_key_values
from manip_kin.ros.runtime.runner import run_node
from manip_kin.ros.runtime.throttled_log import ThrottledLog
from manip_kin.ros.wire.cdr import Float64ArrayCdr, JointStateDecoder, decode_pose_stamped
from manip_kin.ros.wire.diagnostics import make_diagnostic_array, make_diagnostic_status
from manip_kin.ros.wire.joint_messages import JointReferenceReader
from manip_kin.ros.wire.messages import ns_to_stamp, pose_stamped_to_matrix, stamp_key, stamp_to_ns, twist_to_arrays
from manip_kin.ros.wire.topics import STREAM_DEPTH, latest_state_qos
from manip_kin.ros.wire.validation import InvalidMessageError, pose_problem, twist_problem


class CartesianControllerNode(LoopingNode):
    """ROS handles around one :class:`~manip_kin.control.resolved_rate.CartesianController` and its
    :class:`~manip_kin.control.state_machines.ControllerSupervisor` (states, timeouts, convergence)."""

    def __init__(self, **node_kwargs):
        super().__init__(NODE_NAME, **node_kwargs)
        params = declare_parameters(self, PARAMETERS)
        self.model = load_node_model(self, params, self._switch_model)
        limit_specs = joint_limit_parameters(self.model)
        params.update(declare_parameters(self, limit_specs))
        self._params = params
        self.rate_hz = params["rate_hz"]
        self.dt = 1.0 / self.rate_hz
        self.base_frame = params["base_frame"] or self.model.base_frame
        self.collision = CollisionInputs(self, params, ThrottledLog(self.get_logger().warning, 1.0))
        self._configure(params)
        config = self.controller.config
        self.supervisor = ControllerSupervisor(
            self._supervisor_config(params, self.controller), self.model.joint_names, self._diagnostics_period_ns
        )
        LiveParameters(self, PARAMETERS + limit_specs, self._set_parameters)
        # Service callbacks only queue the request; the loop acts on it (deque: thread-safe).
        self._requests: deque[tuple[str, bool]] = deque()
        self.create_service(Trigger, "~/stop", self._on_stop)
        self.create_service(SetBool, "~/pause", self._on_pause)
        self._halting = False
        self.halted = False
        self.last_rejection = ""
        self.rejected_stamp = ""
        self._report_now = False
        self._goal_stream_gap_ns = int(5e9 / self.rate_hz)  # goals closer than 5 periods: a stream
        self._goal_arrival_ns = 0

        self._joint_state_sub = PolledSubscription(self, JointState, "joint_states", latest_state_qos(10))
        self._goal_sub = PolledSubscription(self, PoseStamped, "goal_pose", 10)
        self._twist_sub = PolledSubscription(self, TwistStamped, "goal_twist", 10)
        self._reference_sub = PolledSubscription(self, JointState, "joint_reference", 10)
        self._references = JointReferenceReader(self.model)
        self.servo = ServoInputs(self, ThrottledLog(self.get_logger().warning, 1.0))
        self.servo.configure(self.model, self._singularity)
        self._command_pub = self.create_publisher(Float64MultiArray, "joint_velocity_commands", STREAM_DEPTH)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._command_cdr = Float64ArrayCdr(self.model.dof)
        self._zeros = np.zeros(self.model.dof)
        self.bounds = InputBounds.of(self.model)
        self._joint_states = JointStateDecoder(
            self.model.joint_names, self.bounds.position_lower, self.bounds.position_upper
        )

        self.q: np.ndarray | None = None
        self._state_velocities: np.ndarray | None = None
        self._state_stamp_ns = 0
        # As lists: the prediction computes on plain floats every cycle.
        self._prediction_bounds = (
            self.model.lower.tolist(),
            self.model.upper.tolist(),
            (PLAUSIBLE_RATE_FACTOR * self.model.velocity_limits).tolist(),
        )
        self.goal: np.ndarray | None = None
        self.goal_stamp = ""
        self._reference_stamp_ns = 0
        self._twist: tuple[np.ndarray, np.ndarray] | None = None
        # The goal and twist for the predicted state's instant (see law_state).
        self._streamed = self._streamed_goal(self.bounds)
        self.reference: tuple[np.ndarray, np.ndarray] | None = None
        self.output: ControlOutput | None = None
        self.joint_output: JointTrackingOutput | None = None
        self.rejected_goals = 0
        self.rejected_references = 0
        self.rejected_twists = 0
        self.rejected_joint_states = 0
        self._warn = ThrottledLog(self.get_logger().warning, 1.0)

        self.get_logger().info(
            f"robot {self.model.name}: controlling frame {self.model.frame_name(self.controller.frame_index)!r} "
            f"at {self.rate_hz:g} Hz, gains {config.gain_angular:g}/{config.gain_linear:g} 1/s, "
            f"goals in frame {self.base_frame!r}, task {self.controller.task.name}, {self._limits_text()}"
        )
        self._state_log = ThrottledLog(self.get_logger().info, 0.0)
        self._logged_state = self.state
        self._logged_kind = None
        # A new goal runs a cycle at once instead of waiting for the next tick.
        self.start_loop(
            self.rate_hz, self._cycle, params["realtime_priority"], params["scheduler_slice"], wake_on=(self._goal_sub,)
        )

    @property
    def state(self) -> ControllerState:
        """The current state (see :class:`~manip_kin.control.state_machines.ControllerState`)."""
        return self.supervisor.state

    @property
    def detail(self) -> str:
        """One line on the current state."""
        return self.supervisor.detail

    # --- parameters ----------------------------------------------------------------------------

    def _configure(self, params: dict) -> None:
        """Build the core objects from ``params``: at start, and on a live change.

        Everything is built and checked before anything is replaced, so a refused change
        leaves the node as it was. The loop thread reads ``self.controller`` once per cycle:
        swapping it is atomic.

        Raises:
            ManipKinError: a configuration the controller or its supervisor cannot use.
        """
        config = ControllerConfig(
            gain_angular=params["gain_angular"],
            gain_linear=params["gain_linear"],
            frame=params["frame"] or None,
            task=params["task"] or None,
            damping_max=params["damping_max"],
            singular_threshold=params["singular_threshold"],
            respect_velocity_limits=params["respect_velocity_limits"],
            respect_position_limits=params["respect_position_limits"],
        )
        controller = CartesianController(self.model, config)
        law = self.collision.configure(self.model, params, controller, self.dt)  # the QP, or controller
        supervisor_config = self._supervisor_config(params, controller)
        diagnostics_period_ns = period_ns(params["diagnostics_rate_hz"])
        limits = joint_limits_from_params(self.model, params)
        if hasattr(self, "supervisor"):
            self.supervisor.reconfigure(supervisor_config, diagnostics_period_ns)
        limit_velocity = params["respect_velocity_limits"]
        if hasattr(self, "command_filter"):
            self.command_filter.configure(limits, limit_velocity)
        else:
            self.command_filter = CommandFilter(limits, self.model.lower, self.model.upper, self.dt, limit_velocity)
        self.stop_time = params["stop_time"]
        self._singularity = SingularityScaling(params["singularity_slowdown_start"], params["singularity_hard_stop"])
        if hasattr(self, "servo"):
            self.servo.configure(self.model, self._singularity)
        # The law keeps q + q̇·horizon within the position limits: with the horizon of a stop
        # from full speed, a joint nears a limit as slowly as the filter lets it stop, so the
        # law (not only the filter's braking) knows the joint is held and redistributes the task.
        full_stop = limits.stopping_time(np.where(np.isfinite(limits.velocity), limits.velocity, 0.0))
        self.limit_horizon = max(self.dt, full_stop)
        self.controller, self.law = controller, law
        self.position_tolerance = params["position_tolerance"]
        self.orientation_tolerance = params["orientation_tolerance"]
        self._quaternion_tolerance = params["quaternion_tolerance"]
        self.gain_joint = params["gain_joint"]
        self.predict_state = params["predict_state"]
        self.command_latency = params["command_latency"]
        self.joint_tolerance = params["joint_tolerance"]
        self._diagnostics_period_ns = diagnostics_period_ns

    @staticmethod
    def _supervisor_config(params: dict, controller: CartesianController) -> ControllerSupervisorConfig:
        return ControllerSupervisorConfig(
            joint_state_timeout=params["joint_state_timeout"],
            goal_timeout=params["goal_timeout"],
            goal_twist_timeout=params["goal_twist_timeout"],
            position_tolerance=params["position_tolerance"],
            orientation_tolerance=params["orientation_tolerance"],
            joint_tolerance=params["joint_tolerance"],
            task=controller.task,
            progress_window=params["progress_window"],
            command_timeout=params["command_timeout"],
        )

    def _set_parameters(self, updates: dict) -> str | None:
        """Live change of tunable parameters: None once in use, else why not (nothing changes)."""
        params = {**self._params, **updates}
        try:
            self._configure(params)
        except ManipKinError as error:
            return str(error)
        self._params = params
        return None

    def _switch_model(self, model) -> str | None:
        """``~/reload_robot_description``: control ``model`` from the next cycle (the same joints,
        e.g. new limits or geometry), or why not (nothing changes)."""
        problem = joints_problem(self.model, model) or self.collision.switch_problem()
        if problem:
            return problem
        previous = self.model
        self.model = model
        try:
            self._configure(self._params)
        except ManipKinError as error:
            self.model = previous
            return f"cannot control the new model {model.name!r} as configured: {error}"
        bounds = InputBounds.of(model)
        self._joint_states = JointStateDecoder(model.joint_names, bounds.position_lower, bounds.position_upper)
        self._prediction_bounds = (
            model.lower.tolist(),
            model.upper.tolist(),
            (PLAUSIBLE_RATE_FACTOR * model.velocity_limits).tolist(),
        )
        self._references = JointReferenceReader(model)
        self.bounds = bounds
        self._streamed = self._streamed_goal(bounds)
        return None

    def _streamed_goal(self, bounds: InputBounds) -> StreamedGoal:
        """A goal stream moved at most the prediction's reach, at speeds a goal twist may have."""
        return StreamedGoal(self.max_goal_offset, bounds.max_twist_linear, bounds.max_twist_angular)

    @property
    def max_goal_offset(self) -> float:
        """The furthest [s] a streamed goal is moved to the predicted state's instant."""
        return MAX_STATE_AGE_PERIODS * self.dt

    # --- inputs --------------------------------------------------------------------------------

    def _take_inputs(self, now_ns: int) -> None:
        # Joint states arrive every cycle: decoded from their bytes (see JointStateDecoder).
        while (data := self._joint_state_sub.take(raw=True)) is not None:
            try:
                sample = self._joint_states.sample(data)
                self.q, self._state_velocities, self._state_stamp_ns = sample
                self.supervisor.joint_state_received(now_ns)
            except InvalidMessageError as error:
                self.rejected_joint_states += 1
                self._warn(
                    "joint_state:" + error.kind,
                    f"rejected {self._joint_state_sub.subscription.topic_name}: {error}",
                )
        pose_stamp = reference_stamp = None
        while (data := self._goal_sub.take(raw=True)) is not None:
            msg = None
            try:
                msg = decode_pose_stamped(data, "goal pose")  # a goal wakes the loop: read it fast
                problem = pose_problem(
                    msg, self.base_frame, "goal pose", self._quaternion_tolerance, self.bounds.max_target_distance
                )
            except InvalidMessageError as error:
                problem = Problem.of(error)
            if problem is not None:
                self.rejected_goals += 1
                self._rejected(problem, msg)
                self._warn(
                    "goal:" + problem.kind,
                    f"rejected {self._goal_sub.subscription.topic_name}: {problem}; keeping the previous goal",
                )
                continue
            self.goal = pose_stamped_to_matrix(msg)
            pose_stamp = msg.header.stamp
            self._streamed.pose_received(stamp_to_ns(pose_stamp), self.goal)
        while (msg := self._twist_sub.take()) is not None:
            problem = twist_problem(
                msg, self.base_frame, "goal twist", self.bounds.max_twist_linear, self.bounds.max_twist_angular
            )
            if problem is not None:
                self.rejected_twists += 1
                self._warn(
                    "twist:" + problem.kind,
                    f"rejected {self._twist_sub.subscription.topic_name}: {problem}; feed-forward not used",
                )
                continue
            angular, linear = twist_to_arrays(msg.twist)
            self._twist = (angular, linear)
            self._streamed.twist_received(stamp_to_ns(msg.header.stamp), angular, linear)
            self.supervisor.twist_received(now_ns, bool(angular.any() or linear.any()))
        while (msg := self._reference_sub.take()) is not None:
            try:
                self.reference = self._references.read(msg)
            except InvalidMessageError as error:
                self.rejected_references += 1
                self._rejected(str(error), msg)
                self._warn(
                    "reference:" + error.kind,
                    f"rejected {self._reference_sub.subscription.topic_name}: {error}; keeping the previous goal",
                )
                continue
            reference_stamp = msg.header.stamp
            self._reference_stamp_ns = stamp_to_ns(reference_stamp)
        # The latest command of any kind wins; when several came in one cycle, the latest stamp.
        taken = [
            (stamp_to_ns(stamp), kind)
            for stamp, kind in ((pose_stamp, GoalKind.POSE), (reference_stamp, GoalKind.JOINT))
            if stamp is not None
        ]
        taken += self.servo.take()
        if not taken:
            return
        stamp_ns, kind = max(taken, key=lambda item: item[0])
        previous = self.supervisor.goal_kind
        if kind in SERVO_KINDS:
            if kind is not previous:
                self.servo.started(kind)
            self.supervisor.goal_received(now_ns, kind)
            return  # a stream of velocities: no goal stamp, no report of each
        quiet_before = now_ns - self._goal_arrival_ns > self._goal_stream_gap_ns
        self.goal_stamp = stamp_key(ns_to_stamp(stamp_ns))
        if kind is GoalKind.POSE:
            self.supervisor.goal_received(now_ns, GoalKind.POSE)
        else:
            self.supervisor.goal_received(now_ns, GoalKind.JOINT, bool(self.reference[1].any()))
        self._goal_arrival_ns = now_ns
        # A goal after a quiet spell (not a line's stream): say at once that it was taken.
        self._report_now = self._report_now or quiet_before
        if quiet_before:
            self.collision.restart()

    def _rejected(self, reason: str, msg) -> None:
        """Keep a rejected goal's reason and stamp for the status (a CLI waits on them)."""
        self.last_rejection = reason[:300]
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        self.rejected_stamp = stamp_key(stamp) if stamp is not None else ""
        self._report_now = True

    def _take_requests(self) -> None:
        """Act on the queued ``~/stop`` and ``~/pause`` requests (in the loop thread)."""
        while self._requests:
            kind, value = self._requests.popleft()
            if kind == "stop":
                self.supervisor.stop_requested()
            else:
                self.supervisor.pause_requested(value)
            self._report_now = True

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._requests.append(("stop", True))
        response.success = True
        response.message = "stopping: the commands come to rest within the limits; the goal is dropped"
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self._requests.append(("pause", bool(request.data)))
        response.success = True
        response.message = "pausing: holding still, the goal kept" if request.data else "resuming the goal"
        return response

    # --- the cycle -------------------------------------------------------------------------------

    def publish_safe_output(self) -> None:
        """After a failed cycle: the next command of the way to rest (within the limits)."""
        if not self._halting:
            self._command_pub.publish(self._command_cdr.encode(self.command_filter.update(self._zeros)))

    def law_state(self) -> tuple[np.ndarray, int | None]:
        """The joint positions the law runs on: the reported ones, or with ``predict_state``
        those predicted for the period the next command drives (:mod:`manip_kin.control.state_prediction`);
        and the instant they are for on the ROS clock [ns], which the goal is moved to (None:
        the state as reported, the goal as it came)."""
        if not self.predict_state:
            return self.q, None
        lower, upper, max_rate = self._prediction_bounds
        horizon = prediction_horizon(
            self._state_velocities,
            (self.ros_time_ns() - self._state_stamp_ns) * 1e-9,
            self.dt,
            self.command_latency,
            max_rate,
        )
        if horizon is None:
            return self.q, None
        q = predict_positions(self.q, self._state_velocities, horizon, lower, upper)
        return q, self._state_stamp_ns + int(horizon * 1e9)

    def _cycle(self, now_ns: int) -> None:
        if self._halting:  # halt() owns the command stream now
            return
        self._take_inputs(now_ns)
        self.collision.take()
        self._take_requests()
        supervisor = self.supervisor
        target = self._zeros
        q = None
        if supervisor.gate(now_ns):
            try:
                q, instant_ns = self.law_state()
                kind = supervisor.goal_kind
                if kind is GoalKind.JOINT:
                    target = self._joint_step(now_ns, q, instant_ns)
                elif kind is GoalKind.TWIST:
                    self.output, target = self.servo.twist_step(self.law, q, now_ns, self.dt, self.limit_horizon)
                    limited = set(self.output.limited_joints) | set(self.command_filter.braking_joints)
                    supervisor.servo_step_done(sorted(limited), self.output.singular, self.servo.scale)
                elif kind is GoalKind.JOG:
                    config = self.controller.config
                    self.joint_output = self.servo.jog_step(
                        q, now_ns, self.dt, self.limit_horizon, self.gain_joint, config, self.collision.joint_law
                    )
                    target = self.joint_output.qdot
                    supervisor.servo_step_done(self.joint_output.limited_joints, False, 1.0)
                else:
                    twist_fresh = supervisor.feed_forward_fresh(now_ns)
                    goal, twist = self.goal, self._twist if twist_fresh else None
                    if twist is not None and instant_ns is not None:
                        goal, twist = self._streamed.at(instant_ns)
                    output = self.law.step(q, goal, twist, self.limit_horizon)
                    self.output = output
                    target = output.qdot
                    supervisor.pose_step_done(output, twist_fresh, now_ns, self.command_filter.braking_joints)
                    supervisor.collision_blocked(self.collision.pose_step_done(output, now_ns))
            except ManipKinError as error:
                target = self._zeros
                supervisor.step_failed(error)
                self._warn("step", f"control step failed, coming to rest: {error}")
        elif supervisor.state is not ControllerState.STALE_INPUT:
            q = self.q  # halted with a fresh state: still brake before the position limits
        self._command_pub.publish(self._command_cdr.encode(self.command_filter.update(target, q)))
        if self.waiter is not None:
            # Wake on a goal after a quiet spell (a new goal: react at once); not while goals
            # stream in every cycle (a line), which keeps the loop on its own schedule.
            self.waiter.enabled = now_ns - self._goal_arrival_ns > self._goal_stream_gap_ns
        if supervisor.state != self._logged_state or supervisor.goal_kind != self._logged_kind:
            self._log_state_change()
        if supervisor.report_due(now_ns) or self._report_now:
            self._report_now = False
            self._publish_diagnostics(now_ns)

    def _log_state_change(self) -> None:
        """One INFO line per change of the command type, and per change into or out of a
        halted or unreachable state."""
        supervisor = self.supervisor
        state, kind = supervisor.state, supervisor.goal_kind
        previous, self._logged_state = self._logged_state, state
        previous_kind, self._logged_kind = self._logged_kind, kind
        halted = HALTED_STATES
        if kind != previous_kind:
            self._state_log(
                f"kind:{kind}", f"command {previous_kind or 'none'} -> {kind or 'none'}: {supervisor.detail}"
            )
        elif state in halted or previous in halted:
            self._state_log(f"state:{state}", f"{previous} -> {state}: {supervisor.detail}")

    def _limits_text(self) -> str:
        limits = self.command_filter.limits
        if not limits.limits_acceleration:
            return "no acceleration limits"
        return (
            f"acceleration limits {np.round(limits.acceleration, 3).tolist()}, "
            f"jerk limits {np.round(limits.jerk, 1).tolist()} (rad|m, s)"
        )

    def halt(self) -> None:
        """Stop the loop and bring the commands to rest within the limits, for at most
        ``stop_time``; the last command is an exact zero. For every way the node ends (a
        signal, a loop that gave up, shutdown); idempotent."""
        if self.halted:
            return
        self._halting = True
        if hasattr(self, "loop"):
            self.loop.stop()
        if not self.context.ok():
            self.halted = True
            return
        deadline = time.monotonic() + self.stop_time
        next_ns = time.monotonic_ns()
        period_ns = int(self.dt * 1e9)
        try:
            while not self.command_filter.at_rest and time.monotonic() < deadline:
                self._command_pub.publish(self._command_cdr.encode(self.command_filter.update(self._zeros)))
                next_ns += period_ns
                time.sleep(max(0.0, (next_ns - time.monotonic_ns()) * 1e-9))
            if not self.command_filter.at_rest:
                self._warn("stop_time", f"stop_time {self.stop_time:g} s ran out before the commands were at rest")
            self.command_filter.reset()
            self._command_pub.publish(self._command_cdr.encode(self._zeros))
        except Exception as error:  # noqa: BLE001 - the context went down meanwhile: nothing left to send
            self._warn("halt", f"could not finish the halt: {type(error).__name__}: {error}")
        self.halted = True

    def stop(self) -> None:
        """Halt (see :meth:`halt`), then stop the loop thread."""
        self.halt()
        super().stop()

    def _joint_step(self, now_ns: int, q: np.ndarray, instant_ns: int | None) -> np.ndarray:
        """One step of the joint tracking law from ``q``; the reference velocity is used while it
        is fresh (as the goal twist: a stalled stream must not carry the arm on), and then moves
        the reference to the instant ``q`` is for (see :meth:`law_state`)."""
        q_reference, qdot_reference = self.reference
        fresh = self.supervisor.goal_fresh(now_ns)
        if fresh and instant_ns is not None:
            q_reference = reference_at(
                q_reference, qdot_reference, self._reference_stamp_ns, instant_ns, self.max_goal_offset
            )
        qdot_reference = qdot_reference if fresh else None
        law = self.collision.joint_law
        if law is None:
            output = joint_tracking_step(
                self.model,
                q,
                q_reference,
                qdot_reference,
                self.gain_joint,
                self.limit_horizon,
                self.controller.config.respect_position_limits,
                self.controller.config.respect_velocity_limits,
            )
        else:  # collision avoidance: the same law, as a QP within the collision limit
            output = law.joint_step(q, q_reference, qdot_reference, self.gain_joint)
        self.joint_output = output
        self.supervisor.joint_step_done(output, fresh, now_ns)
        if law is not None:
            self.supervisor.collision_blocked(self.collision.joint_step_done(output, now_ns))
        return output.qdot

    def _publish_diagnostics(self, now_ns: int) -> None:
        supervisor = self.supervisor
        # Blocked: the errors where the arm was held off, for the outcome's words.
        held_off = supervisor.state is ControllerState.BLOCKED
        joint_space = supervisor.goal_kind in (GoalKind.JOINT, GoalKind.JOG)
        if supervisor.goal_kind is GoalKind.JOINT:
            values = self._joint_values((supervisor.active or held_off) and self.joint_output is not None)
        else:
            values = self._pose_values((supervisor.active or held_off) and self.output is not None)
        values += [
            ("goal_kind", supervisor.goal_kind or ""),
            # When the goal was first within the tolerances (ROS clock): what --wait calls "settled".
            ("converged_stamp", self.stamp_key_of(supervisor.converged_ns) if supervisor.converged_ns else ""),
            ("task", self.controller.task.name),
            ("position_tolerance", f"{self.position_tolerance:g}"),
            ("orientation_tolerance", f"{self.orientation_tolerance:g}"),
            ("joint_tolerance", f"{self.joint_tolerance:g}"),
            ("rejected_goals", str(self.rejected_goals)),
            ("rejected_twists", str(self.rejected_twists)),
            ("rejected_joint_states", str(self.rejected_joint_states)),
            ("rejected_references", str(self.rejected_references)),
            ("rejected_stamp", self.rejected_stamp),
            ("last_rejection", self.last_rejection),
            ("base_frame", self.base_frame),
            ("controlled_frame", self.model.frame_name(self.controller.frame_index)),
            ("servo_scale", f"{self.servo.scale:.4f}"),
            ("servo_sigma_min", f"{self.servo.sigma_min:.4g}"),
            ("rejected_servo_commands", str(self.servo.rejected)),
            ("command_filter", self.command_filter.result),
            ("braking_joints", ",".join(self.model.joint_names[i] for i in self.command_filter.braking_joints)),
            ("unreachable_errors", " ".join(f"{v:.6g}" for v in supervisor.unreachable_errors or ())),
            ("loop_error", self.loop_error()),
            *self.collision.report(self.get_clock().now().to_msg(), self.joint_output if joint_space else self.output),
        ] + stats_key_values(self.loop.stats())
        level = self.diagnostic_level(self.supervisor.level)
        status = make_diagnostic_status(self.status_name, level, self.state, self.model.name, values)
        self._diagnostics_pub.publish(make_diagnostic_array(self.get_clock().now().to_msg(), [status]))

    def _pose_values(self, active: bool) -> list[tuple[str, str]]:
        output = self.output
        return [
            ("state", self.state),
            ("detail", self.detail),
            ("goal_stamp", self.goal_stamp),
            ("goal_xyz", " ".join(f"{v:.6f}" for v in self.goal[:3, 3]) if self.goal is not None else ""),
            ("position_error", f"{output.position_error_norm:.9f}" if active else ""),
            ("orientation_error", f"{output.orientation_error_norm:.9f}" if active else ""),
            ("joint_error", ""),
            ("manipulability", f"{output.manipulability:.6g}" if active else ""),
            ("damping", f"{output.damping:.6g}" if active else ""),
            ("velocity_scale", f"{output.velocity_scale:.4f}" if active else ""),
            ("limited_joints", ",".join(self.model.joint_names[i] for i in output.limited_joints) if active else ""),
        ]

    def _joint_values(self, active: bool) -> list[tuple[str, str]]:
        """Status values while following a joint reference; the pose errors are those of the
        controlled frame w.r.t. where the reference puts it (at the diagnostics rate only)."""
        output = self.joint_output
        goal = frame_pose(self.model, self.reference[0], self.controller.frame_index)
        position_error = orientation_error = ""
        if active:
            orientation, position = self.controller.error(self.q, goal)
            position_error = f"{np.linalg.norm(position):.9f}"
            orientation_error = f"{np.linalg.norm(orientation):.9f}"
        return [
            ("state", self.state),
            ("detail", self.detail),
            ("goal_stamp", self.goal_stamp),
            ("goal_xyz", " ".join(f"{v:.6f}" for v in goal[:3, 3])),
            ("goal_q", " ".join(f"{v:.6f}" for v in self.reference[0])),
            ("position_error", position_error),
            ("orientation_error", orientation_error),
            ("joint_error", f"{np.max(np.abs(output.joint_error)):.9f}" if active else ""),
            ("manipulability", ""),
            ("damping", ""),
            ("velocity_scale", f"{output.velocity_scale:.4f}" if active else ""),
            ("limited_joints", ",".join(self.model.joint_names[i] for i in output.limited_joints) if active else ""),
        ]


def main(argv=None) -> int:
    """Entry point of the ``cartesian_controller`` executable."""
    return run_node(
        CartesianControllerNode, USAGE, argv, on_shutdown=lambda node: node.stop(), halt=lambda node: node.halt()
    )


if __name__ == "__main__":
    sys.exit(main())
