"""Recordings carry the arm: /tf and /tf_static synthesised from joint_states and robot_description.

Recordings are written here with the tool pose from the model's compiled forward
kinematics at every joint state; TF is then added (the recorder's synthesiser, via
``add_tf``), read back with rosbags (independent of our writer and decoder) and composed
from base_link with numpy: the tool frame must sit at the recorded tool pose at every
TF stamp, for every bundled robot.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import bundled_robot_names, load_robot
from manip_kin.core.rotations import quat_to_matrix
from manip_kin.core.urdf import model_to_urdf
from manip_kin.recording import RecordingWriter, read_info
from manip_kin.recording.qos import default_offer
from manip_kin.recording.tf_synthesis import TfSynthesizer, add_tf
from manip_kin.ros.wire.messages import make_pose_stamped, ns_to_stamp

MANIP_KIN = Path(sys.executable).parent / "manip_kin"
T0 = 1_700_000_000_000_000_000
PERIOD_NS = 2_000_000  # joint states at 500 Hz
STEPS = 400  # 0.8 s


def write_run(path: Path, robot: str, description: bool = True, joint_states: bool = True, extra_names=()):
    """A recording of the arm moving between two random configurations; returns the model."""
    model = load_robot(robot)
    rng = np.random.default_rng(len(robot))
    q_from, q_to = model.random_configuration(rng, 0.1), model.random_configuration(rng, 0.1)
    tool = model.default_frame
    with RecordingWriter(path) as writer:
        if description:
            writer.add_topic("/robot_description", "std_msgs/msg/String", offered_qos_profiles=default_offer(True, 1))
            writer.write("/robot_description", String(data=model_to_urdf(model)), log_time_ns=T0)
        for k in range(STEPS):
            stamp = T0 + 1_000_000 + k * PERIOD_NS
            q = q_from + (q_to - q_from) * k / (STEPS - 1)
            if joint_states:
                names = list(model.joint_names) + list(extra_names)
                values = list(q) + [0.5] * len(extra_names)
                message = JointState(name=names, position=values)
                message.header.stamp = ns_to_stamp(stamp)
                writer.write("/joint_states", message, log_time_ns=stamp + 300_000)
            pose = make_pose_stamped(frame_pose(model, q, tool), model.base_frame, ns_to_stamp(stamp))
            writer.write("/tool_pose", pose, log_time_ns=stamp + 310_000)
    return model


def read_with_rosbags(path: Path) -> dict[str, list]:
    by_topic: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, timestamp, raw in reader.messages():
            by_topic.setdefault(connection.topic, []).append((timestamp, reader.deserialize(raw, connection.msgtype)))
    return by_topic


def _matrix(transform) -> np.ndarray:
    t, r = transform.translation, transform.rotation
    matrix = np.eye(4)
    matrix[:3, :3] = quat_to_matrix([r.x, r.y, r.z, r.w])
    matrix[:3, 3] = [t.x, t.y, t.z]
    return matrix


def composed_tool_poses(messages: dict[str, list], root: str, tool: str) -> dict[int, np.ndarray]:
    """Per /tf stamp: the tool frame composed from root through the latest transforms."""
    latest = {}
    for _, message in messages["/tf_static"]:
        for t in message.transforms:
            latest[t.child_frame_id] = t
    result = {}
    for _, message in messages["/tf"]:
        stamps = {(t.header.stamp.sec, t.header.stamp.nanosec) for t in message.transforms}
        assert len(stamps) == 1  # one joint state, one stamp
        for t in message.transforms:
            latest[t.child_frame_id] = t
        frame, pose = tool, np.eye(4)
        while frame != root:
            t = latest[frame]
            pose = _matrix(t.transform) @ pose
            frame = t.header.frame_id
        sec, nanosec = stamps.pop()
        result[sec * 10**9 + nanosec] = pose
    return result


@pytest.mark.parametrize("robot", bundled_robot_names())
def test_added_tf_composes_to_the_recorded_tool_pose_at_every_stamp(robot, tmp_path):
    model = write_run(tmp_path / "run.mcap", robot)
    summary, status = add_tf(tmp_path / "run.mcap", tmp_path / "with_tf.mcap")
    assert "/tf synthesised" in status, status
    messages = read_with_rosbags(tmp_path / "with_tf.mcap")
    assert len(messages["/tf_static"]) == 1
    tool_frame = "tool" if model.has_tool else "ee"
    poses = composed_tool_poses(messages, model.base_frame, tool_frame)
    recorded = {}
    for _, message in messages["/tool_pose"]:
        p, o = message.pose.position, message.pose.orientation
        matrix = np.eye(4)
        matrix[:3, :3] = quat_to_matrix([o.x, o.y, o.z, o.w])
        matrix[:3, 3] = [p.x, p.y, p.z]
        recorded[message.header.stamp.sec * 10**9 + message.header.stamp.nanosec] = matrix
    assert poses and set(poses) <= set(recorded)
    for stamp, pose in poses.items():
        np.testing.assert_allclose(pose, recorded[stamp], atol=1e-12)
    # At most 50 Hz by stamp: consecutive stamps 20 ms apart to within one joint-state period.
    stamps = np.array(sorted(poses))
    gaps = np.diff(stamps)
    assert gaps.min() >= 20_000_000 and gaps.max() < 20_000_000 + PERIOD_NS
    assert len(stamps) == pytest.approx((STEPS - 1) * PERIOD_NS / 20_000_000 + 1, abs=1)
    # One transform per movable joint, written at the joint state's receive time.
    assert all(len(m.transforms) == model.dof for _, m in messages["/tf"])
    assert summary.topic_counts["/joint_states"] == STEPS


def test_unknown_joint_names_are_ignored_for_tf(tmp_path):
    model = write_run(tmp_path / "run.mcap", "genova7", extra_names=["gripper_joint", "camera_pan"])
    add_tf(tmp_path / "run.mcap", tmp_path / "with_tf.mcap")
    messages = read_with_rosbags(tmp_path / "with_tf.mcap")
    assert all(len(m.transforms) == model.dof for _, m in messages["/tf"])
    assert composed_tool_poses(messages, "base_link", "tool")


@pytest.mark.parametrize(
    ("description", "joint_states", "reason"),
    [(False, True, "no /robot_description was recorded"), (True, False, "no /joint_states was recorded")],
)
def test_without_description_or_joint_states_no_tf_and_the_rest_is_kept(tmp_path, description, joint_states, reason):
    write_run(tmp_path / "run.mcap", "irb120", description=description, joint_states=joint_states)
    summary, status = add_tf(tmp_path / "run.mcap", tmp_path / "out.mcap")
    assert reason in status and "no /tf synthesised" in status, status
    before = {t.name: t.message_count for t in read_info(tmp_path / "run.mcap").topics}
    after = {t.name: t.message_count for t in read_info(tmp_path / "out.mcap").topics}
    # Everything recorded is kept; no /tf (a description alone still gives its fixed joints on /tf_static).
    assert "/tf" not in after
    assert {k: v for k, v in after.items() if k != "/tf_static"} == before
    assert after.get("/tf_static", 0) == (1 if description else 0)


def test_cli_add_tf_and_replay_without_tf2_msgs(tmp_path):
    write_run(tmp_path / "run.mcap", "scara")
    done = subprocess.run(
        [str(MANIP_KIN), "info", "--add-tf", str(tmp_path / "tf.mcap"), str(tmp_path / "run.mcap")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert "/tf synthesised from joint_states (" in done.stdout
    topics = {t.name: t.type for t in read_info(tmp_path / "tf.mcap").topics}
    assert topics["/tf"] == topics["/tf_static"] == "tf2_msgs/msg/TFMessage"
    # Live /tf needs tf2_msgs: one line, exit 2, pointing to the file way.
    replay = subprocess.run(
        [str(MANIP_KIN), "replay", "--add-tf", "--quiet", str(tmp_path / "run.mcap")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert replay.returncode == 2 and "manip_kin info --add-tf OUT" in replay.stderr
    assert len(replay.stderr.strip().splitlines()) == 1


def test_plot_animates_the_arm_from_tf(tmp_path):
    write_run(tmp_path / "run.mcap", "rpp")
    add_tf(tmp_path / "run.mcap", tmp_path / "tf.mcap")
    done = subprocess.run(
        [str(MANIP_KIN), "plot", str(tmp_path / "tf.mcap"), "--out", str(tmp_path / "plots"), "--gif", "--frames", "8"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    from PIL import Image

    with Image.open(tmp_path / "plots" / "arm.gif") as gif:
        assert gif.n_frames == 8
    assert (tmp_path / "plots" / "arm_tf.png").stat().st_size > 10_000
    # Without /tf there is nothing to animate: exit 2 with the way to add it.
    bare = subprocess.run(
        [str(MANIP_KIN), "plot", str(tmp_path / "run.mcap"), "--out", str(tmp_path / "p2"), "--gif"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert bare.returncode == 2 and "--add-tf" in bare.stderr


def test_no_tf_is_logged_before_its_tf_static():
    """The recorder drains topic by topic, so a joint state received before the description can
    be fed after it; its /tf, logged before the /tf_static, once left a reader going by log time
    without the tool frame (a loaded test run)."""
    from rclpy.serialization import serialize_message

    model = load_robot("irb120")
    description = serialize_message(String(data=model_to_urdf(model)))
    synthesizer = TfSynthesizer(rate_hz=1000.0)
    static = synthesizer.feed("/robot_description", "std_msgs/msg/String", description, 2_000_000_000)
    assert [out.topic for out in static] == ["/tf_static"]

    def joint_state(stamp_ns: int) -> bytes:
        message = JointState(name=list(model.joint_names), position=[0.1] * len(model.joint_names))
        message.header.stamp = ns_to_stamp(stamp_ns)
        return serialize_message(message)

    early = synthesizer.feed("/joint_states", "sensor_msgs/msg/JointState", joint_state(1_990_000_000), 1_999_000_000)
    assert early == []
    later = synthesizer.feed("/joint_states", "sensor_msgs/msg/JointState", joint_state(2_001_000_000), 2_001_000_000)
    assert [out.topic for out in later] == ["/tf"] and later[0].log_time_ns >= static[0].log_time_ns
