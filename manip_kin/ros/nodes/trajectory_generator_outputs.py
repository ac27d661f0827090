"""What ``trajectory_generator`` streams: the running motion's samples, as ``goal_pose`` and
``goal_twist`` (a line) or ``joint_reference`` (a joint trajectory), pre-serialised (see
:mod:`manip_kin.ros.wire.cdr`); the last one held at rest when a stream stops; and a motion's
path on ``planned_path`` (latched).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Path
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from manip_kin.motion.joint_trajectory import JointTrajectoryPlan
from manip_kin.ros.wire.cdr import JointStateCdr, PoseStampedCdr, TwistStampedCdr
from manip_kin.ros.wire.messages import make_pose_stamped
from manip_kin.ros.wire.topics import STREAM_DEPTH


class MotionStream:
    """The generator's publishers, in ``base_frame``, for the joints ``joint_names``."""

    def __init__(self, node, base_frame: str, joint_names):
        self.node = node
        self.base_frame = base_frame
        self._goal_pub = node.create_publisher(PoseStamped, "goal_pose", STREAM_DEPTH)
        self._twist_pub = node.create_publisher(TwistStamped, "goal_twist", STREAM_DEPTH)
        self._reference_pub = node.create_publisher(JointState, "joint_reference", STREAM_DEPTH)
        latched = QoSProfile(
            depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
        )
        self._path_pub = node.create_publisher(Path, "planned_path", latched)
        self._goal_cdr = PoseStampedCdr(base_frame)
        self._twist_cdr = TwistStampedCdr(base_frame)
        self._reference_cdr = JointStateCdr(joint_names)
        self._last_goal_pose: np.ndarray | None = None
        self._last_reference: np.ndarray | None = None

    def publish(self, motion, t: float, stamp_ns: int) -> None:
        """The sample of ``motion`` at ``t`` [s] into it, stamped ``stamp_ns`` (the instant it is for)."""
        if isinstance(motion, JointTrajectoryPlan):
            q, qdot = motion.sample(t)
            self._reference_pub.publish(self._reference_cdr.encode(stamp_ns, q, qdot))
            self._last_reference = q
        else:
            pose, (angular, linear) = motion.sample(t)
            self._goal_pub.publish(self._goal_cdr.encode(stamp_ns, pose))
            self._last_goal_pose = pose
            self._twist_pub.publish(self._twist_cdr.encode(stamp_ns, angular, linear))

    def hold(self, motion) -> None:
        """The last sample of ``motion``'s kind sent again at rest, stamped now (a stopped stream)."""
        if isinstance(motion, JointTrajectoryPlan):
            if self._last_reference is not None:
                stamp_ns = self.node.get_clock().now().nanoseconds
                zeros = np.zeros_like(self._last_reference)
                self._reference_pub.publish(self._reference_cdr.encode(stamp_ns, self._last_reference, zeros))
        elif self._last_goal_pose is not None:
            stamp_ns = self.node.get_clock().now().nanoseconds
            self._goal_pub.publish(self._goal_cdr.encode(stamp_ns, self._last_goal_pose))
            self._twist_pub.publish(self._twist_cdr.encode(stamp_ns, np.zeros(3), np.zeros(3)))

    def publish_path(self, poses) -> None:
        """``poses`` (4x4, base frame) on ``planned_path``, stamped now."""
        path = Path()
        stamp = self.node.get_clock().now().to_msg()
        path.header.stamp = stamp
        path.header.frame_id = self.base_frame
        path.poses = [make_pose_stamped(pose, self.base_frame, stamp) for pose in poses]
        self._path_pub.publish(path)
