"""robot_state's picture of the arm: ``/tf``, ``/tf_static`` and the ``markers`` topic.

:class:`RobotVisuals` is driven by the node's loop with each cycle's joint positions and
tool pose. TF is computed by :mod:`manip_kin.core.tf_tree` from the URDF the node publishes on
``robot_description`` and encoded by :mod:`manip_kin.recording.tf_message` (the same
bytes the recorder writes when it synthesises TF), then published on publishers of type
``tf2_msgs/msg/TFMessage`` wherever that Python type imports (a ROS install). Without it
(PyPI-only machines) /tf is not published live; the recorder writes it into recordings.

Markers (``visualization_msgs/MarkerArray``, namespaces): ``goal`` the latest goal pose as
axes (LINE_LIST), ``planned_path`` the latest planned path (LINE_STRIP), ``tool_trail``
the tool positions of the last ``trail_duration`` seconds (LINE_STRIP), ``joint_limits``
a sphere per movable joint at its link, green when free, amber to red near a limit.
Each namespace goes out in its own MarkerArray, one per loop cycle, so that no cycle
builds them all.
"""

from __future__ import annotations

from geometry_msgs.msg import Point, PoseStamped
from nav_msgs.msg import Path
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.core.bounds import InputBounds
from manip_kin.core.model import RobotModel
from manip_kin.core.tf_tree import LinkTree, StampDecimator, moving_transforms, static_transforms
from manip_kin.recording import tf_message
from manip_kin.recording.tf_message import TF_STATIC_TOPIC, TF_TOPIC, encode_tf_message
from manip_kin.ros.runtime.polling import PolledSubscription
from manip_kin.ros.wire.messages import ns_to_stamp, pose_to_matrix
from manip_kin.ros.wire.topics import latest_state_qos
from manip_kin.ros.wire.validation import pose_problem
from manip_kin.viz import markers as core

MARKERS_DEPTH = 100

GOAL_AXIS_LENGTH = 0.1  # [m]
LINE_WIDTH = 0.006  # [m]
JOINT_SPHERE_DIAMETER = 0.08  # [m]
TRAIL_SPACING_S = 0.05
PATH_COLOUR = (0.1, 0.8, 0.9, 1.0)
TRAIL_COLOUR = (0.9, 0.3, 0.9, 1.0)
MARKER_GROUPS = ("goal", "planned_path", "tool_trail", "joint_limits")  # marker namespaces

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


def _colour(rgba) -> ColorRGBA:
    r, g, b, a = (float(v) for v in rgba)
    return ColorRGBA(r=r, g=g, b=b, a=a)


def _points(xyz) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in xyz]


class RobotVisuals:
    """TF and markers of one robot_state node.

    Args:
        node: the node (publishers and subscriptions are created on it).
        model: the robot.
        urdf_text: the URDF published on ``robot_description`` (frame ids are its link names).
        frame_prefix: prepended to every TF frame id.
        tf_rate_hz: highest /tf rate [Hz].
        markers_rate_hz: rate of ``markers`` [Hz]; 0 turns markers off.
        trail_duration_s: length of the tool trail [s].
    """

    def __init__(
        self,
        node,
        model: RobotModel,
        urdf_text: str,
        frame_prefix: str,
        tf_rate_hz: float,
        markers_rate_hz: float,
        trail_duration_s: float,
    ):
        self.model = model
        self.tree = LinkTree.from_urdf(urdf_text, "robot_description")
        self.frame_prefix = frame_prefix
        self.root_frame = frame_prefix + self.tree.root
        self._joint_names = model.joint_names
        children = {j.name: j.child for j in self.tree.movable}
        self._joint_frames = [frame_prefix + children.get(name, self.tree.root) for name in self._joint_names]
        self._tf_decimator = StampDecimator(tf_rate_hz)
        self._tf_pub = None
        self.tf_live = False
        tf_class = tf_message.tf_message_class()
        if tf_class is not None:
            self._tf_pub = node.create_publisher(tf_class, TF_TOPIC, 100)
            self._static_pub = node.create_publisher(tf_class, TF_STATIC_TOPIC, LATCHED)
            self.tf_live = True
            self.tf_log = f"tf2_msgs found: publishing {TF_TOPIC} at up to {tf_rate_hz:g} Hz and {TF_STATIC_TOPIC}"
        else:
            self.tf_log = (
                "tf2_msgs is not installed: /tf and /tf_static are not published live "
                "(the recorder writes them into recordings)"
            )
        self._markers_period_ns = int(1e9 / markers_rate_hz) if markers_rate_hz > 0 else 0
        self._last_markers_ns = 0
        self._pending_groups: list[str] = []
        self._trail = core.ToolTrail(trail_duration_s, TRAIL_SPACING_S)
        self._max_distance = InputBounds.of(model).max_target_distance
        self._goal: PoseStamped | None = None
        self._path: Path | None = None
        if self._markers_period_ns:
            # Several seconds of marker arrays (they go out a namespace per cycle): a recorder
            # that falls behind for a moment loses none (a reliable writer drops the oldest).
            self._markers_pub = node.create_publisher(MarkerArray, "markers", MARKERS_DEPTH)
            self._goal_sub = PolledSubscription(node, PoseStamped, "goal_pose", latest_state_qos(10))
            self._path_sub = PolledSubscription(node, Path, "planned_path", LATCHED)

    def publish_static(self, stamp_ns: int) -> None:
        """``/tf_static`` once (transient local keeps it for late subscribers)."""
        if self.tf_live:
            self._static_pub.publish(encode_tf_message(stamp_ns, static_transforms(self.tree, self.frame_prefix)))

    def cycle(self, now_ns: int, stamp_ns: int, q_values, tool_values) -> None:
        """Publish what is due at this cycle (joint positions and the tool pose of ``stamp_ns``)."""
        if self.tf_live and self._tf_decimator.due(stamp_ns):
            transforms = moving_transforms(self.tree, dict(zip(self._joint_names, q_values)), self.frame_prefix)
            self._tf_pub.publish(encode_tf_message(stamp_ns, transforms))
        if not self._markers_period_ns:
            return
        self._trail.add(stamp_ns, (tool_values[3], tool_values[7], tool_values[11]))
        if now_ns - self._last_markers_ns >= self._markers_period_ns:
            self._last_markers_ns = now_ns
            self._take_inputs()
            self._pending_groups = list(MARKER_GROUPS)
        # One group per cycle: building all of them at once (~1 ms) would stall a 1 kHz loop.
        while self._pending_groups:
            array = self.marker_array(stamp_ns, q_values, (self._pending_groups.pop(0),))
            if array.markers:
                self._markers_pub.publish(array)
                break

    def _usable(self, pose: PoseStamped) -> bool:
        # What the controller would refuse (non-finite, far away, not a unit quaternion) is not drawn;
        # the controller logs the rejection.
        return pose_problem(pose, pose.header.frame_id, max_distance=self._max_distance) is None

    def _take_inputs(self) -> None:
        while (goal := self._goal_sub.take()) is not None:
            if self._usable(goal):
                self._goal = goal
        while (path := self._path_sub.take()) is not None:
            if all(self._usable(pose) for pose in path.poses):
                self._path = path

    def marker_array(self, stamp_ns: int, q_values, groups=MARKER_GROUPS) -> MarkerArray:
        """The markers of ``groups`` (namespaces) for the current goal, path, trail and joint positions."""
        stamp = ns_to_stamp(stamp_ns)
        markers = []

        def marker(namespace: str, marker_id: int, kind: int, frame_id: str) -> Marker:
            m = Marker(ns=namespace, id=marker_id, type=kind, action=Marker.ADD)
            m.header.stamp, m.header.frame_id = stamp, frame_id
            m.pose.orientation.w = 1.0
            m.scale.x = LINE_WIDTH
            markers.append(m)
            return m

        if self._goal is not None and "goal" in groups:
            points, colours = core.axes_segments(pose_to_matrix(self._goal.pose), GOAL_AXIS_LENGTH)
            m = marker("goal", 0, Marker.LINE_LIST, self._goal.header.frame_id)
            m.points, m.colors = _points(points), [_colour(c) for c in colours]
            m.color = _colour(colours[0])
        if self._path is not None and self._path.poses and "planned_path" in groups:
            m = marker("planned_path", 0, Marker.LINE_STRIP, self._path.header.frame_id)
            p = [pose.pose.position for pose in self._path.poses]
            m.points, m.color = _points((q.x, q.y, q.z) for q in p), _colour(PATH_COLOUR)
        trail = self._trail.positions() if "tool_trail" in groups else ()
        if len(trail) >= 2:
            m = marker("tool_trail", 0, Marker.LINE_STRIP, self.root_frame)
            m.points, m.color = _points(trail), _colour(TRAIL_COLOUR)
        if "joint_limits" not in groups:
            return MarkerArray(markers=markers)
        colours = core.limit_colours(q_values, self.model.lower, self.model.upper)
        for i, frame in enumerate(self._joint_frames):
            m = marker("joint_limits", i, Marker.SPHERE, frame)
            m.scale.x = m.scale.y = m.scale.z = JOINT_SPHERE_DIAMETER
            m.color = _colour(colours[i])
        return MarkerArray(markers=markers)
