"""robot_state's markers and live /tf (manip_kin.ros.nodes.visuals, manip_kin.viz.markers).

tf2_msgs is not installed here, so the live /tf path is exercised with a stand-in type:
the publishers are created with ``std_msgs/msg/String`` as the DDS type, and what goes on
the wire are the TFMessage CDR bytes robot_state encodes; the test takes them raw and
decodes them with rosbags as ``tf2_msgs/msg/TFMessage``. Only the type name registered
in DDS is a stand-in; rate, stamps, frame ids and values are the node's own.
"""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from node_harness import Harness
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform, quat_to_matrix, rpy_to_matrix
from manip_kin.recording import tf_message
from manip_kin.ros.nodes.robot_state import RobotStateNode
from manip_kin.ros.wire.messages import make_pose_stamped, pose_to_matrix
from manip_kin.viz import markers

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def test_limit_colours_green_free_red_on_limit_blend_between():
    colours = markers.limit_colours([0.0, 0.95, 1.0, -0.99, 5.0], [-1, -1, -1, -1, -np.inf], [1, 1, 1, 1, np.inf])
    np.testing.assert_array_equal(colours[0], markers.FREE_COLOUR)
    np.testing.assert_array_equal(colours[2], markers.LIMIT_COLOUR)
    np.testing.assert_array_equal(colours[4], markers.FREE_COLOUR)  # continuous joint
    # 0.05 from the upper limit inside a 0.2 band: a quarter of the way from red to amber.
    np.testing.assert_allclose(colours[1], 0.25 * markers.WARN_COLOUR + 0.75 * markers.LIMIT_COLOUR)
    np.testing.assert_allclose(colours[3], 0.05 * markers.WARN_COLOUR + 0.95 * markers.LIMIT_COLOUR)


def test_tool_trail_keeps_the_last_seconds_at_the_spacing():
    trail = markers.ToolTrail(duration_s=1.0, spacing_s=0.1)
    for k in range(300):  # 3 s at 100 Hz
        trail.add(k * 10_000_000, (k, 0.0, 0.0))
    kept = trail.positions()[:, 0]
    assert kept[-1] == 290 and np.all(np.diff(kept) == 10) and len(kept) == 11
    trail.add(5, (1.0, 2.0, 3.0))  # time went backwards: a new trail
    np.testing.assert_array_equal(trail.positions(), [[1.0, 2.0, 3.0]])


def test_markers_show_the_goal_and_path_that_were_sent(harness):
    genova7 = load_robot("genova7")
    q0 = genova7.start_configuration()
    q0[1] = genova7.upper[1]  # joint2 on its upper limit
    node = harness.start(
        RobotStateNode, robot="genova7", rate_hz=200.0, markers_rate_hz=20.0, initial_positions=q0.tolist()
    )
    received = harness.collect(MarkerArray, "markers")
    goal_matrix = make_transform(rpy_to_matrix(0.3, -0.4, 1.1), [0.21, -0.65, 0.33])
    goal = make_pose_stamped(goal_matrix, "base_link")
    path = Path()
    path.header.frame_id = "base_link"
    line = np.linspace([0.0, -1.1, 0.2], [0.2, -0.7, 0.3], 7)
    path.poses = [make_pose_stamped(make_transform(None, p), "base_link") for p in line]
    harness.wait_matched("goal_pose", PoseStamped)
    path_pub = harness.node.create_publisher(Path, "planned_path", LATCHED)
    path_pub.publish(path)

    def has_both():
        names = {m.ns for array in received for m in array.markers}
        return {"goal", "planned_path", "joint_limits"} <= names

    assert harness.spin_until(has_both, timeout=10.0, every=lambda: harness.publish("goal_pose", goal), period=0.05)
    latest = {(m.ns, m.id): m for array in received for m in array.markers}  # newest per marker
    latest.update({m.ns: m for m in latest.values() if m.id == 0})
    axes = latest["goal"]
    assert axes.type == Marker.LINE_LIST and axes.header.frame_id == "base_link"
    points = np.array([[p.x, p.y, p.z] for p in axes.points])
    for axis in range(3):  # each segment from the goal origin along the goal's axis
        np.testing.assert_allclose(points[2 * axis], goal_matrix[:3, 3], atol=1e-12)
        direction = (points[2 * axis + 1] - points[2 * axis]) / np.linalg.norm(points[2 * axis + 1] - points[2 * axis])
        np.testing.assert_allclose(direction, goal_matrix[:3, axis], atol=1e-12)
    strip = latest["planned_path"]
    assert strip.type == Marker.LINE_STRIP
    np.testing.assert_allclose([[p.x, p.y, p.z] for p in strip.points], line, atol=1e-15)
    # One sphere per joint on its link frame, coloured by the limit state of the current q.
    spheres = [latest[("joint_limits", i)] for i in range(7)]
    assert [m.header.frame_id for m in spheres] == [f"link{i}" for i in range(1, 8)]
    model = node.model
    expected = markers.limit_colours(node.plant.q, model.lower, model.upper)
    got = np.array([[m.color.r, m.color.g, m.color.b, m.color.a] for m in spheres])
    np.testing.assert_allclose(got, expected, atol=1e-6)  # float32 colour channels
    np.testing.assert_allclose(got[1], markers.LIMIT_COLOUR, atol=1e-6)  # joint2 on its limit: red
    assert pose_to_matrix(goal.pose)[0, 3] == pytest.approx(0.21)


def test_live_tf_with_a_stand_in_type_composes_to_the_tool_pose(harness, monkeypatch):
    monkeypatch.setattr(tf_message, "tf_message_class", lambda: String)
    raw_tf: list[bytes] = []
    raw_static: list[bytes] = []
    harness.node.create_subscription(String, "/tf", raw_tf.append, 100, raw=True)
    harness.node.create_subscription(String, "/tf_static", raw_static.append, LATCHED, raw=True)
    states = harness.collect(JointState, "/joint_states")
    node = harness.start(RobotStateNode, robot="irb120", rate_hz=200.0, tf_rate_hz=25.0, frame_prefix="arm/")
    assert node.visuals.tf_live and "publishing /tf" in node.visuals.tf_log
    assert harness.spin_until(lambda: len(raw_tf) >= 10 and raw_static, timeout=10.0)
    typestore = get_typestore(Stores.ROS2_JAZZY)
    static = typestore.deserialize_cdr(raw_static[0], "tf2_msgs/msg/TFMessage")
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [("arm/link6", "arm/ee")]
    model = load_robot("irb120")
    q_by_stamp = {(s.header.stamp.sec, s.header.stamp.nanosec): np.array(s.position) for s in states}
    stamps = []
    for data in raw_tf:
        message = typestore.deserialize_cdr(data, "tf2_msgs/msg/TFMessage")
        assert len(message.transforms) == model.dof
        stamp = (message.transforms[0].header.stamp.sec, message.transforms[0].header.stamp.nanosec)
        stamps.append(stamp[0] * 10**9 + stamp[1])
        pose = np.eye(4)
        for t in message.transforms:  # a chain: base → link1 → … → link6, in order
            r, p = t.transform.rotation, t.transform.translation
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = quat_to_matrix([r.x, r.y, r.z, r.w]), [p.x, p.y, p.z]
            pose = pose @ step
        assert message.transforms[0].header.frame_id == "arm/base_link"
        if stamp in q_by_stamp:  # the joint state of the same cycle, seen by this test
            np.testing.assert_allclose(pose, frame_pose(model, q_by_stamp[stamp], model.dof), atol=1e-12)
    assert any((s // 10**9, s % 10**9) in q_by_stamp for s in stamps), "no TF stamp matched a joint state the test saw"
    assert min(np.diff(stamps)) >= 40_000_000  # at most 25 Hz by stamp


def test_goals_the_controller_would_refuse_are_not_drawn_and_break_nothing(harness):
    node = harness.start(RobotStateNode, robot="irb120", rate_hz=200.0, markers_rate_hz=50.0)
    received = harness.collect(MarkerArray, "markers")
    good = make_pose_stamped(make_transform(rpy_to_matrix(0.1, 0.2, 0.3), [0.3, 0.1, 0.4]), "base_link")
    harness.wait_matched("goal_pose", PoseStamped)

    def goal_markers():
        return [m for array in received for m in array.markers if m.ns == "goal"]

    assert harness.spin_until(goal_markers, timeout=10.0, every=lambda: harness.publish("goal_pose", good))
    for position, quaternion in (
        ((1e300, 1e308, 0.0), (0.0, 0.0, 0.0, 0.0)),
        ((float("nan"), 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        ((0.3, 0.1, 0.4), (1e300, 0.0, 0.0, 1.0)),
    ):
        bad = PoseStamped()
        bad.header.frame_id = "base_link"
        (bad.pose.position.x, bad.pose.position.y, bad.pose.position.z) = position
        o = bad.pose.orientation
        o.x, o.y, o.z, o.w = quaternion
        harness.publish("goal_pose", bad)
    count = len(goal_markers())
    assert harness.spin_until(lambda: len(goal_markers()) >= count + 5, timeout=10.0)
    for marker in goal_markers()[count:]:
        np.testing.assert_allclose([marker.points[0].x, marker.points[0].y, marker.points[0].z], [0.3, 0.1, 0.4])
    assert node.loop.stats().errors == 0
