"""The MCAP files the writer produces, checked against independent readers.

``rosbags`` (its own MCAP parser, CDR decoder and RIHS01 implementation) and
rclpy (rosidl's type support) read what :class:`RecordingWriter` wrote; the
``mcap`` library's low-level records are checked against rosbag2 Jazzy's
layout (profile, schema encoding and text, channel metadata).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sysconfig
import time
from pathlib import Path

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TwistStamped
from mcap.reader import make_reader
from nav_msgs.msg import Path as PathMsg
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

from manip_kin.cli import main as cli_main
from manip_kin.recording import (
    CorruptRecordingError,
    RecordingWriter,
    read_info,
    read_messages,
    salvage,
)
from manip_kin.recording.cdr_measure import CdrLayout
from manip_kin.recording.msgdef import full_definition_text, local_definitions, read_msg_text
from manip_kin.recording.qos import default_offer, parse_profiles
from manip_kin.recording.type_hash import rihs01_from_schema, rosidl_type_hash

REPO = Path(__file__).resolve().parents[2]
# The console scripts of the interpreter running the tests (the venv make uses, or any other).
SCRIPTS = Path(sysconfig.get_path("scripts"))
MANIP_KIN = SCRIPTS / "manip_kin"
T0 = 1_700_000_000_000_000_000  # ns since the epoch
MS = 1_000_000

TYPES = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/tool_pose": "geometry_msgs/msg/PoseStamped",
    "/tool_twist": "geometry_msgs/msg/TwistStamped",
    "/joint_velocity_commands": "std_msgs/msg/Float64MultiArray",
    "/robot_description": "std_msgs/msg/String",
    "/planned_path": "nav_msgs/msg/Path",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def _stamp(msg, ns: int):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
    msg.header.frame_id = "base_link"
    return msg


def make_messages(i: int) -> dict[str, object]:
    """One message per topic, values depending on ``i`` (every 7th JointState is empty)."""
    joint_state = JointState()
    if i % 7:
        joint_state.name = [f"joint_{j}" for j in range(i % 4 + 1)]
        joint_state.position = [0.1 * i + j for j in range(i % 4 + 1)]
        joint_state.velocity = [-0.5 * i] * (i % 4 + 1)
    pose = PoseStamped()
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = 0.01 * i, -0.2, 0.3
    pose.pose.orientation.w = 1.0
    twist = TwistStamped()
    twist.twist.linear.x, twist.twist.angular.z = 0.5 * i, -0.25 * i
    command = Float64MultiArray(data=[float(i), 2.0 * i, -1.0])
    if i % 2:
        command.layout.dim = [MultiArrayDimension(label="joints", size=3, stride=3)]
    description = String(data="<robot name='r'>" + "x" * i + "</robot>")
    path = PathMsg()
    path.header.frame_id = "base_link"
    for k in range(i % 3):
        waypoint = PoseStamped()
        waypoint.header.frame_id = "base_link"
        waypoint.pose.position.x = float(k)
        path.poses.append(waypoint)
    diagnostics = DiagnosticArray()
    diagnostics.status = [
        DiagnosticStatus(
            level=bytes([i % 3]),
            name="controller",
            message=f"step {i}",
            hardware_id="",
            values=[KeyValue(key="manipulability", value=f"{0.01 * i:.3f}")],
        )
    ]
    stamp_ns = T0 + i * 10 * MS + 123
    for msg in (joint_state, pose, twist, diagnostics):
        _stamp(msg, stamp_ns) if hasattr(msg, "header") else None
    return {
        "/joint_states": joint_state,
        "/tool_pose": pose,
        "/tool_twist": twist,
        "/joint_velocity_commands": command,
        "/robot_description": description,
        "/planned_path": path,
        "/diagnostics": diagnostics,
    }


N_MESSAGES = 40


def write_recording(output: Path, compression: str = "zstd", chunk_size: int = 2048) -> dict[str, list]:
    """Write N_MESSAGES per topic; return what was written, per topic, in order."""
    written: dict[str, list] = {topic: [] for topic in TYPES}
    with RecordingWriter(output, compression=compression, chunk_size=chunk_size) as writer:
        writer.add_topic(
            "/robot_description",
            "std_msgs/msg/String",
            offered_qos_profiles=default_offer(transient_local=True, depth=1),
        )
        for i in range(N_MESSAGES):
            for topic, msg in make_messages(i).items():
                writer.write(topic, msg, log_time_ns=T0 + i * 10 * MS + 500)
                written[topic].append(msg)
    return written


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("recordings")
    written = write_recording(root / "run.mcap")
    write_recording(root / "bag")
    write_recording(root / "plain.mcap", compression="none")
    return {"root": root, "written": written}


# -- rosbag2 layout ----------------------------------------------------------------------------


def test_header_schema_and_channels_follow_rosbag2(recordings):
    with open(recordings["root"] / "run.mcap", "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == set(TYPES.values())
    for schema in schemas.values():
        assert schema.encoding == "ros2msg"
        assert schema.data.decode() == full_definition_text(schema.name)
        assert schema.data.decode().startswith(read_msg_text(schema.name))
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr"
        assert TYPES[channel.topic] == schema.name
        assert set(channel.metadata) == {"offered_qos_profiles", "topic_type_hash"}
        assert channel.metadata["topic_type_hash"] == rosidl_type_hash(schema.name)
        profiles = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert list(profiles[0]) == [
            "history",
            "depth",
            "reliability",
            "durability",
            "deadline",
            "lifespan",
            "liveliness",
            "liveliness_lease_duration",
            "avoid_ros_namespace_conventions",
        ]
    description = next(c for c in summary.channels.values() if c.topic == "/robot_description")
    assert parse_profiles(description.metadata["offered_qos_profiles"]).is_transient_local
    assert {c.compression for c in summary.chunk_indexes} == {"zstd"}


def test_schema_text_lists_dependencies_depth_first_sorted_once():
    text = full_definition_text("nav_msgs/msg/Path")
    separator = "\n" + "=" * 80 + "\nMSG: "
    sections = text.split(separator)
    assert sections[0] == read_msg_text("nav_msgs/msg/Path")
    names = [s.split("\n", 1)[0] for s in sections[1:]]
    # Path -> PoseStamped -> Pose -> Point, Quaternion; PoseStamped -> Header -> Time; Path's own
    # std_msgs/Header already seen. Names as written in the fields (rosbag2 keeps that spelling).
    assert names == [
        "geometry_msgs/PoseStamped",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "std_msgs/Header",
        "builtin_interfaces/Time",
    ]
    for name, section in zip(names, sections[1:]):
        package, type_name = name.split("/")
        # Each dependency: "MSG: pkg/Type\n" then its .msg text exactly as installed.
        assert section == f"{name}\n" + read_msg_text(f"{package}/msg/{type_name}")
    assert not re.search(r"={81}", text)


@pytest.mark.parametrize("type_name", sorted(set(TYPES.values()) | {"rosgraph_msgs/msg/Clock"}))
def test_schema_text_hashes_to_rosidl_type_hash(type_name):
    rosidl = rosidl_type_hash(type_name)  # rosidl_generator_type_description's output
    assert rosidl and rosidl.startswith("RIHS01_")
    text = full_definition_text(type_name)
    assert rihs01_from_schema(type_name, text) == rosidl
    typestore = get_typestore(Stores.EMPTY)  # rosbags' independent parser and hash
    typestore.register(get_types_from_msg(text, type_name))
    assert typestore.hash_rihs01(type_name) == rosidl


def test_type_hashes_equal_what_rclpy_reports_at_runtime():
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node("hash_probe", context=context)
        classes = {
            "sensor_msgs/msg/JointState": JointState,
            "geometry_msgs/msg/PoseStamped": PoseStamped,
            "geometry_msgs/msg/TwistStamped": TwistStamped,
            "std_msgs/msg/Float64MultiArray": Float64MultiArray,
            "std_msgs/msg/String": String,
            "nav_msgs/msg/Path": PathMsg,
            "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray,
            "rosgraph_msgs/msg/Clock": Clock,
        }
        for index, cls in enumerate(classes.values()):
            node.create_publisher(cls, f"/hash_probe_{index}", 1)
        reported = {}
        deadline = time.monotonic() + 5
        while len(reported) < len(classes) and time.monotonic() < deadline:
            for index, name in enumerate(classes):
                for info in node.get_publishers_info_by_topic(f"/hash_probe_{index}"):
                    reported[name] = str(info.topic_type_hash)
            time.sleep(0.05)
        for name in classes:
            assert reported[name] == rihs01_from_schema(name, full_definition_text(name)), name
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


# -- CDR length ------------------------------------------------------------------------------


def test_serialize_message_pads_and_rosbags_rejects_it_trimmed_bytes_pass():
    typestore = get_typestore(Stores.ROS2_JAZZY)
    padded = serialize_message(JointState())
    with pytest.raises(SerdeError, match="size mismatch"):
        typestore.deserialize_cdr(padded, "sensor_msgs/msg/JointState")
    layout = CdrLayout(local_definitions("sensor_msgs/msg/JointState"))
    length = layout.message_length("sensor_msgs/msg/JointState", padded)
    assert length < len(padded)
    message = typestore.deserialize_cdr(padded[:length], "sensor_msgs/msg/JointState")
    assert list(message.name) == [] and message.header.frame_id == ""


@pytest.mark.parametrize("i", range(0, 14))
def test_trimmed_length_is_what_rosbags_serializes(i):
    typestore = get_typestore(Stores.ROS2_JAZZY)
    for topic, msg in make_messages(i).items():
        type_name = TYPES[topic]
        data = serialize_message(msg)
        trimmed = data[: CdrLayout(local_definitions(type_name)).message_length(type_name, data)]
        decoded = typestore.deserialize_cdr(trimmed, type_name)
        assert len(typestore.serialize_cdr(decoded, type_name)) == len(trimmed), (topic, i)
        assert deserialize_message(trimmed, type(msg)) == msg


# -- reading back ----------------------------------------------------------------------------


def _field_values(msg) -> object:
    """Comparable plain values of a rosbags or rclpy message (arrays as lists)."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {k: _field_values(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if hasattr(msg, "__dataclass_fields__"):
        # rosbags lists constants (upper case) as fields too; ROS field names are lower case.
        return {
            k: _field_values(getattr(msg, k))
            for k in msg.__dataclass_fields__
            if not k.startswith("__") and not k.isupper()
        }
    if isinstance(msg, (bytes, bytearray)):
        # rclpy gives a `byte` field as bytes of length 1, rosbags as an int.
        return msg[0] if len(msg) == 1 else list(msg)
    if hasattr(msg, "tolist"):
        return msg.tolist()
    if isinstance(msg, (list, tuple)) or type(msg).__name__ == "array":
        return [_field_values(v) for v in msg]
    return msg


@pytest.mark.parametrize("name", ["run.mcap", "bag", "plain.mcap"])
def test_rosbags_reads_every_message_with_its_values(recordings, name):
    written = recordings["written"]
    seen: dict[str, list] = {topic: [] for topic in TYPES}
    with AnyReader([recordings["root"] / name], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TYPES
        assert reader.message_count == N_MESSAGES * len(TYPES)
        for connection, timestamp, raw in reader.messages():
            seen[connection.topic].append((timestamp, reader.deserialize(raw, connection.msgtype)))
    for topic, items in seen.items():
        assert [t for t, _ in items] == [T0 + i * 10 * MS + 500 for i in range(N_MESSAGES)]
        assert [_field_values(m) for _, m in items] == [_field_values(m) for m in written[topic]], topic


def test_bag_directory_metadata_agrees_with_file(recordings):
    bag = recordings["root"] / "bag"
    document = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert document["version"] == 9 and document["storage_identifier"] == "mcap"
    assert document["relative_file_paths"] == ["bag_0.mcap"]
    assert document["compression_format"] == "" and document["compression_mode"] == ""
    info = read_info(bag / "bag_0.mcap")
    assert document["message_count"] == info.message_count == N_MESSAGES * len(TYPES)
    assert document["starting_time"]["nanoseconds_since_epoch"] == info.start_ns
    assert document["duration"]["nanoseconds"] == info.end_ns - info.start_ns
    by_topic = {t["topic_metadata"]["name"]: t for t in document["topics_with_message_count"]}
    for topic in info.topics:
        entry = by_topic[topic.name]
        assert entry["message_count"] == topic.message_count
        assert entry["topic_metadata"]["type"] == topic.type
        assert entry["topic_metadata"]["type_description_hash"] == topic.type_hash
        assert entry["topic_metadata"]["offered_qos_profiles"] == topic.offered_qos_profiles.to_list()
    # The rosbag2 metadata record inside the file is the same BagMetadata.
    with open(bag / "bag_0.mcap", "rb") as stream:
        records = [m for m in make_reader(stream).iter_metadata() if m.name == "rosbag2"]
    assert yaml.safe_load(records[0].metadata["serialized_metadata"]) == document
    # rosbags' directory reader pairs metadata.yaml topics with the file's channels by
    # name, type, QoS and hash: a disagreement would drop the messages.
    with Rosbag2Reader(bag) as reader:
        assert sum(1 for _ in reader.messages()) == N_MESSAGES * len(TYPES)
        assert all(c.digest.startswith("RIHS01_") for c in reader.connections)


def test_read_messages_gives_rclpy_objects_and_times(recordings):
    written = recordings["written"]
    got = list(read_messages(recordings["root"] / "run.mcap", topics=["/joint_states", "/robot_description"]))
    assert len(got) == 2 * N_MESSAGES
    states = [m for m in got if m.topic == "/joint_states"]
    assert [m.message for m in states] == written["/joint_states"]
    assert [m.log_time_ns for m in states] == [T0 + i * 10 * MS + 500 for i in range(N_MESSAGES)]
    # publish_time is the header stamp for stamped types, the receive time otherwise.
    assert [m.publish_time_ns for m in states] == [T0 + i * 10 * MS + 123 for i in range(N_MESSAGES)]
    descriptions = [m for m in got if m.topic == "/robot_description"]
    assert [m.publish_time_ns for m in descriptions] == [m.log_time_ns for m in descriptions]
    topic, message, log_time, publish_time = got[0]
    assert isinstance(message, (JointState, String))


def test_info_reports_counts_times_compression(recordings):
    info = read_info(recordings["root"] / "run.mcap")
    assert info.message_count == N_MESSAGES * len(TYPES)
    assert info.start_ns == T0 + 500 and info.end_ns == T0 + (N_MESSAGES - 1) * 10 * MS + 500
    assert info.duration_s == pytest.approx((N_MESSAGES - 1) * 0.01)
    assert {t.name: t.message_count for t in info.topics} == {t: N_MESSAGES for t in TYPES}
    assert info.compression == ("zstd",) and info.chunk_count > 1
    assert read_info(recordings["root"] / "plain.mcap").compression == ("none",)
    text = info.to_text()
    for label in ("Files:", "Bag size:", "Duration:", "Start:", "End:", "Messages:", "Compression:"):
        assert label in text
    assert "Topic: /joint_states" in text and "Count: 40" in text


# -- durability and salvage ------------------------------------------------------------------


def test_periodic_flush_puts_messages_on_disk_before_close(tmp_path):
    writer = RecordingWriter(tmp_path / "open.mcap", flush_interval_s=0.05)
    for i in range(30):
        writer.write("/joint_states", make_messages(i)["/joint_states"], log_time_ns=T0 + i * MS)
    time.sleep(0.06)  # longer than the 50 ms flush interval (the behaviour is that interval)
    writer.write("/joint_states", JointState(), log_time_ns=T0 + 30 * MS)  # triggers the due flush
    # Copy the file as a SIGKILL would leave it: the writer is still open.
    shutil.copy(tmp_path / "open.mcap", tmp_path / "killed.mcap")
    with pytest.raises(CorruptRecordingError, match="truncated"):
        read_info(tmp_path / "killed.mcap")
    report = salvage(tmp_path / "killed.mcap", tmp_path / "saved.mcap")
    assert report.message_count == 31 and not report.complete
    writer.close()


def test_salvage_recovers_a_prefix_at_every_cut(recordings, tmp_path):
    source = (recordings["root"] / "run.mcap").read_bytes()
    # Write order of write_recording: message i of every topic, then i + 1.
    complete = [(topic, T0 + i * 10 * MS + 500) for i in range(N_MESSAGES) for topic in TYPES]
    previous = 0
    for cut in range(0, len(source), max(1, len(source) // 25)):
        damaged = tmp_path / f"cut_{cut}.mcap"
        damaged.write_bytes(source[:cut])
        if cut < 8:
            with pytest.raises(CorruptRecordingError):
                salvage(damaged, tmp_path / f"out_{cut}.mcap")
            continue
        try:
            report = salvage(damaged, tmp_path / f"out_{cut}.mcap")
        except CorruptRecordingError as error:
            assert "nothing recoverable" in str(error)
            continue
        recovered = [(m.topic, m.log_time_ns) for m in read_messages(tmp_path / f"out_{cut}.mcap")]
        # Whole chunks survive, so what is recovered is the first messages written.
        assert sorted(recovered) == sorted(complete[: len(recovered)])
        assert len(recovered) >= previous
        previous = len(recovered)
        assert report.message_count == len(recovered)
    assert previous > 0.8 * len(complete)


# -- command line ----------------------------------------------------------------------------


def test_cli_info_json(recordings, capsys):
    assert cli_main(["info", str(recordings["root"] / "bag"), "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["message_count"] == N_MESSAGES * len(TYPES)
    assert {t["name"]: t["count"] for t in document["topics"]} == {t: N_MESSAGES for t in TYPES}
    assert {t["name"]: t["type"] for t in document["topics"]} == TYPES
    assert document["compression"] == ["zstd"]


@pytest.mark.parametrize("content", ["garbage", "truncated", "empty"])
def test_cli_info_of_a_bad_file_is_one_line_and_exit_2(recordings, tmp_path, content):
    bad = tmp_path / f"{content}.mcap"
    source = (recordings["root"] / "run.mcap").read_bytes()
    bad.write_bytes(
        {"garbage": b"not an mcap file\n" * 50, "truncated": source[: len(source) // 2], "empty": b""}[content]
    )
    result = subprocess.run([str(MANIP_KIN), "info", str(bad)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("manip_kin info: error:") and str(bad) in lines[0]
    if content == "truncated":
        assert "--salvage" in lines[0]


def test_cli_salvage(recordings, tmp_path, capsys):
    source = (recordings["root"] / "run.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(source[: int(len(source) * 0.7)])
    assert cli_main(["info", "--salvage", str(tmp_path / "saved"), str(tmp_path / "cut.mcap"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["complete"] is False and report["message_count"] > 0
    assert (tmp_path / "saved" / "metadata.yaml").is_file()
    assert read_info(tmp_path / "saved").message_count == report["message_count"]


def test_benchmark_writer_reports_cost_per_message():
    # The bench code lives under bench/, outside the package.
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_recorder", Path(__file__).parents[2] / "bench" / "recorder.py")
    bench_recorder = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench_recorder)
    result = bench_recorder.benchmark_writer(300)
    assert result["n_messages"] == 300
    assert 0 < result["raw_write_us_per_message"] < 10_000
    assert 0 < result["object_write_us_per_message"] < 10_000
    assert result["message_bytes"] > 100
