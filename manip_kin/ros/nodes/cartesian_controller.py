"""``cartesian_controller``: pose goals, joint references, twists and jogs to joint-rate commands.

The node holds one :class:`~manip_kin.control.resolved_rate.CartesianController` (or, with collision
avoidance or a posture, the QP law), one :class:`~manip_kin.control.state_machines.ControllerSupervisor`
and one :class:`~manip_kin.control.command_filter.CommandFilter`; every cycle of its
:class:`~manip_kin.ros.runtime.rate_loop.RateLoop` it takes the newest joint state and commands, runs
one control step for the newest command of any kind (a pose goal with its feed-forward twist,
a joint reference, ``twist_command``, ``joint_jog``) and publishes the filter's next command on
``joint_velocity_commands``: within the joint limits, always. ``~/stop`` and ``~/pause`` and
every way the node ends bring the commands to rest (:meth:`CartesianControllerNode.halt`).
``/diagnostics`` carries the state (see
:data:`~manip_kin.ros.nodes.cartesian_controller_interface.STATES`), the errors and the loop timing,
at ``diagnostics_rate_hz`` and at once when the state changes.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Float64MultiArray

from manip_kin.control.command_filter import CommandFilter, FilterResult
from manip_kin.control.joint_tracking import JointTrackingOutput, joint_tracking_step
from manip_kin.control.resolved_rate import ControlOutput
from manip_kin.control.state_machines import (
    SERVO_KINDS,
    ControllerState,
    ControllerSupervisor,
    GoalKind,
)
from manip_kin.control.state_prediction import (
    MAX_STATE_AGE_PERIODS,
    predict_positions,
    prediction_horizon,
)
from manip_kin.control.streamed_goal import reference_at
from manip_kin.errors import ManipKinError
from manip_kin.ros.nodes.cartesian_controller_inputs import ControllerInputs
from manip_kin.ros.nodes.cartesian_controller_interface import NODE_NAME, USAGE, ControllerParams
from manip_kin.ros.nodes.cartesian_controller_params import controller_setup, controller_supervisor_config
from manip_kin.ros.nodes.cartesian_controller_services import ControllerRequests
from manip_kin.ros.nodes.cartesian_controller_status import StateChangeLog, status_values
from manip_kin.ros.nodes.collision_inputs import CollisionInputs
from manip_kin.ros.nodes.joint_limit_params import joint_limit_parameters
from manip_kin.ros.nodes.robot_description import joints_problem
from manip_kin.ros.nodes.robot_model import load_node_model
from manip_kin.ros.nodes.servo_inputs import ServoInputs
from manip_kin.ros.runtime.declared_params import LiveParameters, declare_group, declare_parameters
from manip_kin.ros.runtime.looping_node import LoopingNode
from manip_kin.ros.runtime.runner import run_node
from manip_kin.ros.runtime.throttled_log import ThrottledLog
from manip_kin.ros.wire.cdr import Float64ArrayCdr
from manip_kin.ros.wire.messages import ns_to_stamp, stamp_key
from manip_kin.ros.wire.topics import STREAM_DEPTH


class CartesianControllerNode(LoopingNode):
    """ROS handles around one :class:`~manip_kin.control.resolved_rate.CartesianController` and its
    :class:`~manip_kin.control.state_machines.ControllerSupervisor` (states, timeouts, convergence)."""

    def __init__(self, **node_kwargs):
        super().__init__(NODE_NAME, **node_kwargs)
        params = declare_parameters(self, ControllerParams)
        self.model = load_node_model(self, params, self._switch_model)
        limit_specs = joint_limit_parameters(self.model)
        params = declare_group(self, params, limit_specs)
        self._params = params
        self.rate_hz = params.rate_hz
        self.dt = 1.0 / self.rate_hz
        self.base_frame = params.base_frame or self.model.base_frame
        self.collision = CollisionInputs(self, params, ThrottledLog(self.get_logger().warning, 1.0))
        self._warn = ThrottledLog(self.get_logger().warning, 1.0)
        self.inputs = ControllerInputs(self, self.model, self.base_frame, self.max_goal_offset, self._warn)
        self._configure(params)
        config = self.controller.config
        self.supervisor = ControllerSupervisor(
            controller_supervisor_config(params, self.controller), self.model.joint_names, self._diagnostics_period_ns
        )
        LiveParameters(self, params, self._set_parameters, limit_specs)
        self.requests = ControllerRequests(self)
        self._halting = False
        self.halted = False
        self._report_now = False
        self._goal_stream_gap_ns = int(5e9 / self.rate_hz)  # goals closer than 5 periods: a stream
        self._goal_arrival_ns = 0
        self._last_cycle_ns = 0  # the last cycle's start [ns, monotonic]: the filter's elapsed time

        self.servo = ServoInputs(self, ThrottledLog(self.get_logger().warning, 1.0))
        self.servo.configure(self.model, self._singularity)
        self._command_pub = self.create_publisher(Float64MultiArray, "joint_velocity_commands", STREAM_DEPTH)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._command_cdr = Float64ArrayCdr(self.model.dof)
        self._zeros = np.zeros(self.model.dof)
        self.goal_stamp = ""
        self.output: ControlOutput | None = None
        self.joint_output: JointTrackingOutput | None = None

        self.get_logger().info(
            f"robot {self.model.name}: controlling frame {self.model.frame_name(self.controller.frame_index)!r} "
            f"at {self.rate_hz:g} Hz, gains {config.gain_angular:g}/{config.gain_linear:g} 1/s, "
            f"goals in frame {self.base_frame!r}, task {self.controller.task.name}, {self._limits_text()}"
        )
        self._state_log = StateChangeLog(ThrottledLog(self.get_logger().info, 0.0), self.state)
        # A new goal runs a cycle at once instead of waiting for the next tick.
        self.start_loop(
            self.rate_hz,
            self._cycle,
            params.realtime_priority,
            params.scheduler_slice,
            wake_on=(self.inputs.goal_sub,),
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

    def _configure(self, params: ControllerParams) -> None:
        """Build the core objects from ``params``: at start, and on a live change.

        Everything is built and checked before anything is replaced, so a refused change
        leaves the node as it was. The loop thread reads ``self.controller`` once per cycle:
        swapping it is atomic.

        Raises:
            ManipKinError: a configuration the controller or its supervisor cannot use.
        """
        setup = controller_setup(self.model, params, self.collision, self.dt)
        if hasattr(self, "supervisor"):
            self.supervisor.reconfigure(setup.supervisor_config, setup.diagnostics_period_ns)
        limit_velocity = params.respect_velocity_limits
        if hasattr(self, "command_filter"):
            self.command_filter.configure(setup.limits, limit_velocity)
        else:
            self.command_filter = CommandFilter(
                setup.limits, self.model.lower, self.model.upper, self.dt, limit_velocity
            )
        self.stop_time = params.stop_time
        self._singularity = setup.singularity
        if hasattr(self, "servo"):
            self.servo.configure(self.model, self._singularity)
        self.limit_horizon = setup.limit_horizon
        self.controller, self.law = setup.controller, setup.law
        self.position_tolerance = params.position_tolerance
        self.orientation_tolerance = params.orientation_tolerance
        self.inputs.quaternion_tolerance = params.quaternion_tolerance
        self.gain_joint = params.gain_joint
        self.predict_state = params.predict_state
        self.command_latency = params.command_latency
        self.joint_tolerance = params.joint_tolerance
        self._diagnostics_period_ns = setup.diagnostics_period_ns

    def _set_parameters(self, params: ControllerParams) -> str | None:
        """Live change of tunable parameters: None once in use, else why not (nothing changes)."""
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
        self.inputs.switch_model(model)
        return None

    @property
    def max_goal_offset(self) -> float:
        """The furthest [s] a streamed goal is moved to the predicted state's instant."""
        return MAX_STATE_AGE_PERIODS * self.dt

    # --- inputs --------------------------------------------------------------------------------

    def _take_inputs(self, now_ns: int) -> None:
        taken, rejected = self.inputs.take(now_ns, self.supervisor)
        self._report_now = self._report_now or rejected
        # The latest command of any kind wins; when several came in one cycle, the latest stamp.
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
            self.supervisor.goal_received(now_ns, GoalKind.JOINT, bool(self.inputs.reference[1].any()))
        self._goal_arrival_ns = now_ns
        # A goal after a quiet spell (not a line's stream): say at once that it was taken.
        self._report_now = self._report_now or quiet_before
        if quiet_before:
            self.collision.restart()

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
        inputs = self.inputs
        if not self.predict_state:
            return inputs.q, None
        lower, upper, max_rate = inputs.prediction_bounds
        horizon = prediction_horizon(
            inputs.state_velocities,
            (self.ros_time_ns() - inputs.state_stamp_ns) * 1e-9,
            self.dt,
            self.command_latency,
            max_rate,
        )
        if horizon is None:
            return inputs.q, None
        q = predict_positions(inputs.q, inputs.state_velocities, horizon, lower, upper)
        return q, inputs.state_stamp_ns + int(horizon * 1e9)

    def _cycle(self, now_ns: int) -> None:
        if self._halting:  # halt() owns the command stream now
            return
        self._take_inputs(now_ns)
        self._report_now = self.collision.take() or self._report_now  # the scene's verdict at once
        self._report_now = self.requests.take(self.supervisor) or self._report_now
        supervisor = self.supervisor
        target = self._zeros
        q = None
        feed_forward = False  # the law follows a moving reference: a late cycle's loss is made up
        if supervisor.gate(now_ns):
            try:
                q, instant_ns = self.law_state()
                kind = supervisor.goal_kind
                if kind is GoalKind.JOINT:
                    target, feed_forward = self._joint_step(now_ns, q, instant_ns)
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
                    goal, twist = self.inputs.goal, self.inputs.twist if twist_fresh else None
                    if twist is not None and instant_ns is not None:
                        goal, twist = self.inputs.streamed.at(instant_ns)
                    output = self.law.step(q, goal, twist, self.limit_horizon)
                    self.output = output
                    target = output.qdot
                    feed_forward = twist is not None
                    command_filter = self.command_filter
                    ramping = command_filter.result is not FilterResult.FOLLOWING  # at rest: from rest
                    supervisor.pose_step_done(output, twist_fresh, now_ns, command_filter.braking_joints, ramping)
                    supervisor.collision_blocked(self.collision.pose_step_done(output, now_ns))
            except ManipKinError as error:
                target = self._zeros
                supervisor.step_failed(error)
                self._warn("step", f"control step failed, coming to rest: {error}")
        elif supervisor.state is not ControllerState.STALE_INPUT:
            q = self.inputs.q  # halted with a fresh state: still brake before the position limits
        elapsed = (now_ns - self._last_cycle_ns) * 1e-9 if self._last_cycle_ns else None
        self._last_cycle_ns = now_ns
        command = self.command_filter.update(target, q, elapsed, feed_forward)
        self._command_pub.publish(self._command_cdr.encode(command))
        if self.waiter is not None:
            # Wake on a goal after a quiet spell (a new goal: react at once); not while goals
            # stream in every cycle (a line), which keeps the loop on its own schedule.
            self.waiter.enabled = now_ns - self._goal_arrival_ns > self._goal_stream_gap_ns
        self._state_log.update(supervisor)
        if supervisor.report_due(now_ns) or self._report_now:
            self._report_now = False
            self._publish_diagnostics(now_ns)

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

    def _joint_step(self, now_ns: int, q: np.ndarray, instant_ns: int | None) -> tuple[np.ndarray, bool]:
        """One step of the joint tracking law from ``q``; the reference velocity is used while it
        is fresh (as the goal twist: a stalled stream must not carry the arm on), and then moves
        the reference to the instant ``q`` is for (see :meth:`law_state`). Returns the joint
        rates and whether they follow a moving reference (a fresh, nonzero reference velocity)."""
        q_reference, qdot_reference = self.inputs.reference
        fresh = self.supervisor.goal_fresh(now_ns)
        if fresh and instant_ns is not None:
            q_reference = reference_at(
                q_reference, qdot_reference, self.inputs.reference_stamp_ns, instant_ns, self.max_goal_offset
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
        return output.qdot, qdot_reference is not None and bool(np.any(qdot_reference))

    def _publish_diagnostics(self, now_ns: int) -> None:
        level = self.diagnostic_level(self.supervisor.level)
        self.publish_status(level, self.state, status_values(self))


def main(argv=None) -> int:
    """Entry point of the ``cartesian_controller`` executable."""
    return run_node(
        CartesianControllerNode, USAGE, argv, on_shutdown=lambda node: node.stop(), halt=lambda node: node.halt()
    )


if __name__ == "__main__":
    sys.exit(main())
