"""``cartesian_controller``'s inputs: joint states, pose goals with their feed-forward twists, and
joint references; taken once a cycle in the loop thread, checked, and kept as the newest of each.

Joint states arrive every cycle and are decoded from their bytes
(:class:`~manip_kin.ros.wire.cdr.JointStateDecoder`); a goal pose wakes the loop and is read fast
(:func:`~manip_kin.ros.wire.cdr.decode_pose_stamped`). A rejected message is counted and logged
(throttled), and for a goal or a reference its reason and stamp are kept for the status (a CLI
waits on them); the previous goal stays. The twists and jogs of servoing are
:mod:`manip_kin.ros.nodes.servo_inputs`.
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from sensor_msgs.msg import JointState

from manip_kin.control.state_machines import ControllerSupervisor, GoalKind
from manip_kin.control.state_prediction import PLAUSIBLE_RATE_FACTOR
from manip_kin.control.streamed_goal import StreamedGoal
from manip_kin.core.bounds import InputBounds
from manip_kin.errors import Problem
from manip_kin.ros.runtime.polling import PolledSubscription
from manip_kin.ros.wire.cdr import JointStateDecoder, decode_pose_stamped
from manip_kin.ros.wire.joint_messages import JointReferenceReader
from manip_kin.ros.wire.messages import pose_stamped_to_matrix, stamp_key, stamp_to_ns, twist_to_arrays
from manip_kin.ros.wire.topics import latest_state_qos
from manip_kin.ros.wire.validation import InvalidMessageError, pose_problem, twist_problem


class ControllerInputs:
    """The newest joint state, goal, goal twist and joint reference of one controller node.

    Args:
        node: the node the subscriptions are made on.
        model: the robot model (see :meth:`switch_model`).
        base_frame: the frame goals and twists must be given in.
        max_goal_offset: the furthest [s] a streamed goal is moved (see :class:`StreamedGoal`).
        warn: ``warn(key, text)``, a throttled log.
    """

    def __init__(self, node, model, base_frame: str, max_goal_offset: float, warn):
        self.base_frame = base_frame
        self.max_goal_offset = max_goal_offset
        self._warn = warn
        #: Largest deviation of a goal's quaternion from unit length (a parameter; live).
        self.quaternion_tolerance = 0.0
        self.joint_state_sub = PolledSubscription(node, JointState, "joint_states", latest_state_qos(10))
        self.goal_sub = PolledSubscription(node, PoseStamped, "goal_pose", 10)
        self._twist_sub = PolledSubscription(node, TwistStamped, "goal_twist", 10)
        self._reference_sub = PolledSubscription(node, JointState, "joint_reference", 10)
        self.q: np.ndarray | None = None
        self.state_velocities: np.ndarray | None = None
        self.state_stamp_ns = 0
        self.goal: np.ndarray | None = None
        self.twist: tuple[np.ndarray, np.ndarray] | None = None
        self.reference: tuple[np.ndarray, np.ndarray] | None = None
        self.reference_stamp_ns = 0
        self.rejected_goals = 0
        self.rejected_references = 0
        self.rejected_twists = 0
        self.rejected_joint_states = 0
        self.last_rejection = ""
        self.rejected_stamp = ""
        self.switch_model(model)

    def switch_model(self, model) -> None:
        """Check and decode the inputs for ``model`` (at start, and on a new robot description)."""
        bounds = InputBounds.of(model)
        self._joint_states = JointStateDecoder(model.joint_names, bounds.position_lower, bounds.position_upper)
        # As lists: the prediction computes on plain floats every cycle.
        self.prediction_bounds = (
            model.lower.tolist(),
            model.upper.tolist(),
            (PLAUSIBLE_RATE_FACTOR * model.velocity_limits).tolist(),
        )
        self._references = JointReferenceReader(model)
        self.bounds = bounds
        # The goal and twist for the predicted state's instant (see the node's law_state): moved
        # at most the prediction's reach, at speeds a goal twist may have.
        self.streamed = StreamedGoal(self.max_goal_offset, bounds.max_twist_linear, bounds.max_twist_angular)

    def take(self, now_ns: int, supervisor: ControllerSupervisor) -> tuple[list[tuple[int, GoalKind]], bool]:
        """Take what came since the last cycle; ``supervisor`` hears of the joint states and twists.

        Returns:
            ``(stamp [ns], kind)`` of the newest valid pose goal and joint reference taken, and
            whether a goal or reference was rejected (its reason is then to be reported at once).
        """
        rejected = False
        # Joint states arrive every cycle: decoded from their bytes (see JointStateDecoder).
        while (data := self.joint_state_sub.take(raw=True)) is not None:
            try:
                sample = self._joint_states.sample(data)
                self.q, self.state_velocities, self.state_stamp_ns = sample
                supervisor.joint_state_received(now_ns)
            except InvalidMessageError as error:
                self.rejected_joint_states += 1
                self._warn(
                    "joint_state:" + error.kind,
                    f"rejected {self.joint_state_sub.subscription.topic_name}: {error}",
                )
        pose_stamp = reference_stamp = None
        while (data := self.goal_sub.take(raw=True)) is not None:
            msg = None
            try:
                msg = decode_pose_stamped(data, "goal pose")  # a goal wakes the loop: read it fast
                problem = pose_problem(
                    msg, self.base_frame, "goal pose", self.quaternion_tolerance, self.bounds.max_target_distance
                )
            except InvalidMessageError as error:
                problem = Problem.of(error)
            if problem is not None:
                self.rejected_goals += 1
                rejected = self._rejected(problem, msg)
                self._warn(
                    "goal:" + problem.kind,
                    f"rejected {self.goal_sub.subscription.topic_name}: {problem}; keeping the previous goal",
                )
                continue
            self.goal = pose_stamped_to_matrix(msg)
            pose_stamp = msg.header.stamp
            self.streamed.pose_received(stamp_to_ns(pose_stamp), self.goal)
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
            self.twist = (angular, linear)
            self.streamed.twist_received(stamp_to_ns(msg.header.stamp), angular, linear)
            supervisor.twist_received(now_ns, bool(angular.any() or linear.any()))
        while (msg := self._reference_sub.take()) is not None:
            try:
                self.reference = self._references.read(msg)
            except InvalidMessageError as error:
                self.rejected_references += 1
                rejected = self._rejected(str(error), msg)
                self._warn(
                    "reference:" + error.kind,
                    f"rejected {self._reference_sub.subscription.topic_name}: {error}; keeping the previous goal",
                )
                continue
            reference_stamp = msg.header.stamp
            self.reference_stamp_ns = stamp_to_ns(reference_stamp)
        taken = [
            (stamp_to_ns(stamp), kind)
            for stamp, kind in ((pose_stamp, GoalKind.POSE), (reference_stamp, GoalKind.JOINT))
            if stamp is not None
        ]
        return taken, rejected

    def _rejected(self, reason: str, msg) -> bool:
        """Keep a rejected goal's reason and stamp for the status (a CLI waits on them)."""
        self.last_rejection = reason[:300]
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        self.rejected_stamp = stamp_key(stamp) if stamp is not None else ""
        return True
