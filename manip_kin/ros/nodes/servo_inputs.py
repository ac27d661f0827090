"""``twist_command`` and ``joint_jog`` on ``cartesian_controller``: taken, checked, turned into steps.

The callbacks only store the newest message (polled subscriptions, as every input of the
loop); the loop takes them once a cycle (:meth:`ServoInputs.take`), and a valid one becomes
the controller's command when it is the newest of any kind. Then each cycle
:meth:`ServoInputs.twist_step` or :meth:`ServoInputs.jog_step` gives the joint rates (see
:mod:`manip_kin.control.servo`).

* ``twist_command`` (geometry_msgs/TwistStamped): the controlled frame's velocity
  (angular [rad/s], linear [m/s]) expressed in ``frame_id``: the base frame, the controlled
  frame or any link of the chain.
* ``joint_jog`` (sensor_msgs/JointState): ``name`` and ``velocity`` [rad/s | m/s] of any
  subset of the joints (control_msgs/JointJog carries the same; it is not installable here).
"""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import TwistStamped
from sensor_msgs.msg import JointState

from manip_kin.control.joint_tracking import joint_tracking_step
from manip_kin.control.servo import (
    JogReference,
    SingularityScaling,
    TwistReference,
    resolve_frame,
    singularity_scale,
    smallest_singular_value,
)
from manip_kin.control.state_machines import GoalKind
from manip_kin.core.kinematics import frame_pose, pose_and_jacobian_in_base
from manip_kin.errors import Problem, ProblemKind, UnknownFrameError
from manip_kin.ros.runtime.polling import PolledSubscription
from manip_kin.ros.wire.messages import stamp_to_ns, twist_to_arrays
from manip_kin.ros.wire.validation import twist_problem


class ServoInputs:
    """The twist and jog commands of one controller node (its loop thread only)."""

    def __init__(self, node, warn):
        self.node = node
        self._warn = warn
        self._twist_sub = PolledSubscription(node, TwistStamped, "twist_command", 10)
        self._jog_sub = PolledSubscription(node, JointState, "joint_jog", 10)
        self.twist: tuple[np.ndarray, np.ndarray, int] | None = None  # angular, linear, frame index
        self.jog = np.zeros(node.model.dof)
        self.rejected = 0
        self.scale = 1.0
        self.sigma_min = 0.0
        self.configure(node.model, SingularityScaling())

    def configure(self, model, scaling: SingularityScaling) -> None:
        """The model and the singularity thresholds (at start and on a live change)."""
        self.model = model
        self.scaling = scaling
        self._twist_reference = TwistReference()
        self._jog_reference = JogReference(model)
        self._names = {name: i for i, name in enumerate(model.joint_names)}
        self._last_ns: int | None = None

    # --- taking ------------------------------------------------------------------------------

    def take(self) -> list[tuple[int, GoalKind]]:
        """``(stamp [ns], kind)`` of each valid command taken this cycle (the newest of each kind)."""
        taken = []
        while (msg := self._twist_sub.take()) is not None:
            problem = self._twist_problem(msg)
            if problem is not None:
                self._reject("twist", self._twist_sub, problem)
                continue
            taken.append((stamp_to_ns(msg.header.stamp), GoalKind.TWIST))
        while (msg := self._jog_sub.take()) is not None:
            problem = self._jog_problem(msg)
            if problem is not None:
                self._reject("jog", self._jog_sub, problem)
                continue
            taken.append((stamp_to_ns(msg.header.stamp), GoalKind.JOG))
        return taken

    def started(self, kind: GoalKind) -> None:
        """A new stream of ``kind`` begins (the previous command was of another kind)."""
        self._last_ns = None
        if kind is GoalKind.TWIST:
            self._twist_reference.reset()
        else:
            self._jog_reference.reset()

    def _reject(self, what: str, subscription, problem: Problem) -> None:
        self.rejected += 1
        topic = subscription.subscription.topic_name
        self._warn(f"{what}:" + problem.kind, f"rejected {topic}: {problem}; command not used")

    def _twist_problem(self, msg: TwistStamped) -> Problem | None:
        bounds = self.node.inputs.bounds
        problem = twist_problem(
            msg, msg.header.frame_id, "twist command", bounds.max_twist_linear, bounds.max_twist_angular
        )
        if problem is not None:
            return problem
        try:
            index = resolve_frame(self.model, msg.header.frame_id or self.node.base_frame)
        except UnknownFrameError as error:
            return Problem(ProblemKind.FRAME, f"twist command frame_id {msg.header.frame_id!r:.60}: {str(error)[:200]}")
        angular, linear = twist_to_arrays(msg.twist)
        self.twist = (angular, linear, index)
        return None

    def _jog_problem(self, msg: JointState) -> Problem | None:
        names, velocities = list(msg.name), list(msg.velocity)
        if not names or len(names) != len(velocities):
            return Problem(
                ProblemKind.LENGTH,
                f"joint jog has {len(names)} names and {len(velocities)} velocities; valid: one velocity a name",
            )
        rates = np.zeros(self.model.dof)
        for name, value in zip(names, velocities):
            index = self._names.get(name)
            if index is None:
                return Problem(
                    ProblemKind.OTHER,
                    f"joint jog names {name!r:.60}, not a joint of {self.model.name}; valid: {', '.join(self._names)}",
                )
            if not (math.isfinite(value) and abs(value) <= self.model.velocity_limits[index] * 1.0000001):
                limit = self.model.velocity_limits[index]
                return Problem(
                    ProblemKind.SPEED if math.isfinite(value) else ProblemKind.NON_FINITE,
                    f"joint jog velocity {value!r:.30} for {name}; valid: finite, at most {limit:g} in magnitude",
                )
            rates[index] = value
        self.jog = rates
        return None

    # --- steps -------------------------------------------------------------------------------

    def _elapsed(self, now_ns: int, dt: float) -> float:
        """Seconds since the previous servo step (the reference moves with time, not with cycles:
        a loop that runs late or catches up must not change the speed), at most 5 periods."""
        last, self._last_ns = self._last_ns, now_ns
        return dt if last is None else min(max((now_ns - last) * 1e-9, 0.0), 5.0 * dt)

    def twist_step(self, controller, q: np.ndarray, now_ns: int, dt: float, horizon: float):
        """The law's output for the twist command at ``q``, scaled for singularities."""
        dt = self._elapsed(now_ns, dt)
        angular, linear, index = self.twist
        controlled = controller.frame_index
        pose, jacobian = pose_and_jacobian_in_base(self.model, q, controlled)
        if index == 0:
            rotation = np.eye(3)
        elif index == controlled:
            rotation = pose[:3, :3]
        else:
            rotation = frame_pose(self.model, q, index)[:3, :3]
        angular, linear = rotation @ angular, rotation @ linear
        rows = list(controller.task.rows)
        task_jacobian = jacobian[rows]
        direction = task_jacobian.T @ np.concatenate([angular, linear])[rows]
        self.scale, self.sigma_min = singularity_scale(
            self.model, q, direction, controlled, rows, self.scaling, smallest_singular_value(task_jacobian)
        )
        angular, linear = angular * self.scale, linear * self.scale
        goal = self._twist_reference.advance(pose, angular, linear, dt)
        output = controller.step(q, goal, (angular, linear), horizon)
        return output, output.qdot

    def jog_step(self, q: np.ndarray, now_ns: int, dt: float, horizon: float, gain: float, config, law=None):
        """The joint tracking output following the jog at ``q``: through ``law.joint_step`` (the
        collision-limited QP, see :class:`~manip_kin.ros.nodes.collision_inputs.CollisionLaw`), or
        the plain joint law when ``law`` is None."""
        dt = self._elapsed(now_ns, dt)
        reference, rates = self._jog_reference.advance(q, self.jog, dt)
        if law is not None:
            return law.joint_step(q, reference, rates, gain)
        return joint_tracking_step(
            self.model,
            q,
            reference,
            rates,
            gain,
            horizon,
            config.respect_position_limits,
            config.respect_velocity_limits,
        )
