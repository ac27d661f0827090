"""live_view: the arm served over the Foxglove WebSocket protocol, read by a real client.

The client is test/foxglove_client/client.mjs: @foxglove/ws-protocol's FoxgloveClient on Node,
decoding with Foxglove's ros2msg parser and CDR reader (npm packages installed by the
``foxglove_client`` fixture, or ``make test``). The node runs in-process (test/support/node_harness.py)
with ``port`` 0 (a free port); the test publishes the robot_description and joint_states.
The values are checked against the FK of manip_kin.core.kinematics, composed here link by link.
"""

from __future__ import annotations

import fcntl
import json
import socket
import struct
import subprocess
import termios
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from live_view_client import ensure_installed, stalled_client, start_client

from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import quat_to_matrix
from manip_kin.recording.tf_message import decode_tf_message
from manip_kin.viz.live_feed import VIEW_TOPICS, Delivery, LiveFeed

MODEL = load_robot("genova7")
Q = np.array([0.3, -0.5, 0.2, -1.1, 0.4, 0.12, 0.6])


@pytest.fixture(scope="module")
def foxglove_client() -> Path:
    """The client's directory with its npm packages installed (``npm ci`` once per machine)."""
    try:
        return ensure_installed()
    except RuntimeError as error:
        pytest.fail(str(error))


# --- the feed, without ROS sockets -------------------------------------------------------------


@given(st.lists(st.integers(min_value=1, max_value=40_000_000), min_size=1, max_size=300))
def test_streams_are_thinned_to_the_rate_and_events_pass_whole(gaps_ns):
    feed = LiveFeed(rate_hz=50.0)
    times = np.cumsum(gaps_ns).tolist()
    sent_stream = [m.log_time_ns for t in times for m in feed.feed("/ee_pose", "x/msg/Y", Delivery.STREAM, b"s", t)]
    sent_events = [m for t in times for m in feed.feed("/markers", "x/msg/Y", Delivery.EVENT, b"e", t)]
    assert len(sent_events) == len(times)
    assert sent_stream[0] == times[0]
    assert all(b - a >= 20_000_000 for a, b in zip(sent_stream, sent_stream[1:], strict=False))
    # None is left out that is a period or more after the last one sent.
    last = sent_stream[0]
    for t in times:
        if t >= last + 20_000_000:
            assert t in sent_stream
        if t in sent_stream:
            last = t
    assert feed.forwarded["/ee_pose"] + feed.thinned.get("/ee_pose", 0) == len(times)


def _cdr(message) -> bytes:
    from rclpy.serialization import serialize_message

    return serialize_message(message)


def _joint_state(q, stamp_ns: int):
    from builtin_interfaces.msg import Time
    from sensor_msgs.msg import JointState

    msg = JointState(name=list(MODEL.joint_names), position=[float(v) for v in q])
    msg.header.stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    return msg


def _description():
    from std_msgs.msg import String

    from manip_kin.core.urdf import model_to_urdf

    return String(data=model_to_urdf(MODEL))


def test_tf_is_made_from_the_joint_states_until_a_node_publishes_it():
    feed = LiveFeed(rate_hz=50.0)
    description = feed.feed("/robot_description", "std_msgs/msg/String", Delivery.LATCHED, _cdr(_description()), 1)
    assert [m.topic for m in description] == ["/robot_description", "/tf_static"]
    assert feed.latched("/tf_static") is description[1] and feed.latched("/robot_description") is description[0]
    out = feed.feed("/joint_states", "sensor_msgs/msg/JointState", Delivery.STREAM, _cdr(_joint_state(Q, 5)), 2)
    assert [m.topic for m in out] == ["/joint_states", "/tf"]
    assert len(decode_tf_message(out[1].data)) == MODEL.dof
    feed.use_live_tf()
    later = feed.feed(
        "/joint_states", "sensor_msgs/msg/JointState", Delivery.STREAM, _cdr(_joint_state(Q, 10**9)), 10**9
    )
    assert [m.topic for m in later] == ["/joint_states"]
    assert feed.tf_source == "live /tf forwarded"


# --- the node and real clients -----------------------------------------------------------------


@pytest.fixture
def live_view():
    from node_harness import Harness
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    from manip_kin.ros.nodes.live_view import LiveViewNode

    harness = Harness()
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    description = harness.node.create_publisher(String, "robot_description", latched)
    description.publish(_description())

    def start(**parameters):
        node = harness.start(LiveViewNode, port=0, **parameters)
        # Discovery under load can take a while: the clients below connect once the node has the URDF.
        assert harness.spin_until(lambda: node._feed.latched("/robot_description") is not None, 20.0)
        return node

    harness.start_view = start
    try:
        yield harness
    finally:
        harness.close()


def _run_client(harness, port: int, seconds: float, topics: str, publish_hz: float = 250.0) -> dict:
    """Run the Node client while the harness publishes joint_states at ``publish_hz``; its JSON."""
    from sensor_msgs.msg import JointState

    publisher = harness.publisher(JointState, "joint_states")

    def publish():
        publisher.publish(_joint_state(Q, harness.node.get_clock().now().nanoseconds))

    process = start_client(port, seconds, topics)
    try:
        harness.spin_until(
            lambda: process.poll() is not None, timeout=seconds + 20, every=publish, period=1 / publish_hz
        )
        out, err = process.communicate(timeout=5)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, f"client exited {process.returncode}: {out[-2000:]} {err[-2000:]}"
    return json.loads(out)


def _transform(entry) -> np.ndarray:
    t, r = entry["transform"]["translation"], entry["transform"]["rotation"]
    matrix = np.eye(4)
    matrix[:3, :3] = quat_to_matrix(np.array([r["x"], r["y"], r["z"], r["w"]]))
    matrix[:3, 3] = [t["x"], t["y"], t["z"]]
    return matrix


def _pose_in(transforms: list, root: str, frame: str) -> np.ndarray:
    """``frame`` in ``root`` by walking child → parent through the decoded TF entries."""
    parent_of = {e["child_frame_id"]: e for e in transforms}
    pose = np.eye(4)
    while frame != root:
        entry = parent_of[frame]
        pose = _transform(entry) @ pose
        frame = entry["header"]["frame_id"]
    return pose


def test_a_foxglove_client_lists_subscribes_and_decodes_the_arm(live_view, foxglove_client):
    from manip_kin.core.kinematics import frame_pose

    node = live_view.start_view(rate_hz=40.0)
    result = _run_client(live_view, node.port, 1.5, "/tf,/tf_static,/joint_states,/robot_description")
    assert result["problems"] == []
    channels = {c["topic"]: c for c in result["channels"]}
    expected = {t.name if t.name.startswith("/") else f"/{t.name}" for t in VIEW_TOPICS} | {"/tf", "/tf_static"}
    assert set(channels) == expected
    assert all(c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg" for c in channels.values())
    assert channels["/tf"]["schemaName"] == "tf2_msgs/msg/TFMessage"
    assert result["last"]["/robot_description"]["data"] == _description().data
    joint_state = result["last"]["/joint_states"]
    assert joint_state["name"] == list(MODEL.joint_names)
    np.testing.assert_allclose(joint_state["position"], Q, atol=1e-12)
    transforms = result["last"]["/tf"]["transforms"] + result["last"]["/tf_static"]["transforms"]
    for frame in ("tool", "ee"):
        np.testing.assert_allclose(_pose_in(transforms, "base_link", frame), frame_pose(MODEL, Q, frame), atol=1e-9)
    # About 375 joint states were published in 1.5 s; at most 40 Hz (+1) were sent on.
    assert 5 <= result["counts"]["/joint_states"] <= 40 * 1.5 + 2
    assert result["counts"]["/tf"] <= 40 * 1.5 + 2


def test_a_client_that_connects_later_still_gets_the_description_and_static_tf(live_view, foxglove_client):
    from sensor_msgs.msg import JointState

    node = live_view.start_view()
    # Bytes that are no JointState: forwarded as they are, no TF from them, the node goes on.
    live_view.wait_matched("joint_states", JointState, timeout=20.0)
    live_view.publisher(JointState, "joint_states").publish(b"\x00\x01\x00\x00\xff\xff")
    assert live_view.spin_until(lambda: node._feed.tf_failures == 1, 5.0)
    first = _run_client(live_view, node.port, 0.5, "/robot_description,/tf_static")
    second = _run_client(live_view, node.port, 0.5, "/robot_description,/tf_static")
    for result in (first, second):
        assert result["counts"].get("/robot_description") == 1, result["counts"]
        assert result["counts"].get("/tf_static") == 1, result["counts"]
        assert {e["child_frame_id"] for e in result["last"]["/tf_static"]["transforms"]} == {"ee", "tool"}
    assert node._intake_thread.is_alive()


def _unread_bytes(sock: socket.socket) -> int:
    return struct.unpack("i", fcntl.ioctl(sock.fileno(), termios.FIONREAD, b"\0\0\0\0"))[0]


def test_a_client_that_never_reads_does_not_hold_back_another(live_view, foxglove_client):
    node = live_view.start_view(rate_hz=100.0, message_backlog=32)
    stalled = stalled_client(node.port)
    try:
        live_view.spin_for(0.5)
        result = _run_client(live_view, node.port, 2.0, "/joint_states,/tf", publish_hz=250.0)
        # The reader gets its stream at about the rate (100 Hz; 2 s), the stalled one has a full buffer.
        assert result["counts"]["/joint_states"] >= 0.5 * 100 * 2.0, result["counts"]
        assert result["counts"]["/tf"] >= 0.5 * 100 * 2.0, result["counts"]
        assert _unread_bytes(stalled) > 0
        assert node._intake_thread.is_alive()
    finally:
        stalled.close()


def test_bad_parameter_and_a_taken_port_are_one_line_errors():
    import sys

    executable = str(Path(sys.executable).parent / "live_view")
    bad = subprocess.run([executable, "--ros-args", "-p", "port:=-1"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.strip() == "error: parameter port = -1; valid: 0 to 65535"
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        busy = subprocess.run(
            [executable, "--ros-args", "-p", f"port:={port}"], capture_output=True, text=True, timeout=60
        )
    assert busy.returncode == 1
    assert busy.stderr.strip().startswith(f"error: cannot serve on 127.0.0.1:{port}: ")
    assert "Address already in use" in busy.stderr


def test_demo_live_runs_the_live_view_beside_the_pipeline():
    from manip_kin.cli import build_parser
    from manip_kin.cli.demo_command import demo_processes

    live = build_parser().parse_args(["demo", "--live", "--live-port", "9100"])
    processes = {p.name: p for p in demo_processes(live, Path("demo.mcap"), {}, {})}
    assert processes["live_view"].parameters == {"port": 9100}
    assert processes["live_view"].ready_status == "live_view"
    plain = build_parser().parse_args(["demo"])
    assert "live_view" not in {p.name for p in demo_processes(plain, Path("demo.mcap"), {}, {})}


@given(st.binary(max_size=200))
def test_a_joint_state_that_does_not_decode_is_forwarded_without_tf_and_the_feed_goes_on(garbage):
    feed = LiveFeed(rate_hz=50.0)
    feed.feed("/robot_description", "std_msgs/msg/String", Delivery.LATCHED, _cdr(_description()), 1)
    out = feed.feed("/joint_states", "sensor_msgs/msg/JointState", Delivery.STREAM, garbage, 2)
    assert out[0].topic == "/joint_states" and out[0].data == garbage
    assert all(m.topic == "/tf" for m in out[1:])
    good = feed.feed(
        "/joint_states", "sensor_msgs/msg/JointState", Delivery.STREAM, _cdr(_joint_state(Q, 10**9)), 10**9
    )
    assert [m.topic for m in good] == ["/joint_states", "/tf"]


def test_a_namespaced_arm_gets_its_tf_with_the_frame_prefix():
    feed = LiveFeed(rate_hz=50.0, frame_prefix="left/")
    feed.feed("/left/robot_description", "std_msgs/msg/String", Delivery.LATCHED, _cdr(_description()), 1)
    out = feed.feed("/left/joint_states", "sensor_msgs/msg/JointState", Delivery.STREAM, _cdr(_joint_state(Q, 5)), 2)
    transforms = [t for _, t in decode_tf_message(out[1].data)]
    assert transforms[0].parent == "left/base_link" and transforms[-1].child == "left/link7"
    assert feed.feed("/right/joint_states", "sensor_msgs/msg/JointState", Delivery.STREAM, b"", 3)[1:] == []
