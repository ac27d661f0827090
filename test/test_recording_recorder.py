"""The ``recorder`` executable as a subprocess, fed by publishers in this test process.

Ends by SIGTERM/SIGINT (complete file, every message), by SIGKILL (salvage
recovers all but about the last second), and by its own ``max_messages``.
Files are read back with ``rosbags``, independently of manip_kin's reader.
"""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from manip_kin.recording import read_info

REPO = Path(__file__).resolve().parents[1]
RECORDER = REPO / ".venv" / "bin" / "recorder"
MANIP_KIN = REPO / ".venv" / "bin" / "manip_kin"
URDF = "<robot name='probe'><link name='base_link'/></robot>"


@pytest.fixture
def ros():
    """A node in its own context, for the test's publishers; torn down after the test."""
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node(f"recorder_test_{time.monotonic_ns()}", context=context)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.fixture
def processes():
    """Subprocesses started by a test; any still running at the end is killed."""
    started: list[subprocess.Popen] = []
    yield started
    for process in started:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=10)


def start_recorder(processes: list, output: Path, *parameters: str) -> subprocess.Popen:
    command = [str(RECORDER), "--ros-args", "-p", f"output:={output}"]
    for parameter in parameters:
        command += ["-p", parameter]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    processes.append(process)
    return process


def wait_subscribed(publishers: list, process: subprocess.Popen, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert process.poll() is None, f"recorder exited early: {process.communicate()[1]}"
        if all(p.get_subscription_count() > 0 for p in publishers):
            return
        time.sleep(0.05)
    raise AssertionError("the recorder never subscribed")


def joint_state(node, i: int) -> JointState:
    message = JointState()
    message.header.stamp = node.get_clock().now().to_msg()
    message.header.frame_id = "base_link"
    message.name = ["joint_1", "joint_2"]
    message.position = [float(i), -float(i)]
    return message


def read_with_rosbags(path: Path) -> dict[str, list]:
    """``{topic: [(log_time, message), ...]}`` as rosbags decodes the file."""
    found: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, timestamp, raw in reader.messages():
            found.setdefault(connection.topic, []).append((timestamp, reader.deserialize(raw, connection.msgtype)))
    return found


@pytest.mark.parametrize(
    "stop_signal, output_name",
    [(signal.SIGTERM, "run.mcap"), (signal.SIGINT, "run_bag")],
    ids=["sigterm-file", "sigint-bag-directory"],
)
def test_signal_ends_with_complete_file_holding_every_message(ros, processes, tmp_path, stop_signal, output_name):
    description = ros.create_publisher(
        String, "/robot_description", QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    description.publish(String(data=URDF))  # before the recorder exists: only transient-local delivers it
    states = ros.create_publisher(JointState, "/joint_states", 100)
    output = tmp_path / output_name
    recorder = start_recorder(processes, output, "topics:=[/joint_states,/robot_description,/diagnostics]")
    wait_subscribed([states, description], recorder)
    published = 150
    send_times = []
    for i in range(published):
        send_times.append(time.time_ns())
        states.publish(joint_state(ros, i))
        time.sleep(0.005)
    time.sleep(0.5)
    recorder.send_signal(stop_signal)
    _, stderr = recorder.communicate(timeout=30)
    assert recorder.returncode == 0, stderr
    summary = [line for line in stderr.splitlines() if line.startswith("recorder: ")]
    assert len(summary) == 1, stderr
    assert f"recorded 2 topics, {published + 1} messages" in summary[0]
    assert "0 dropped" in summary[0] and "never published: /diagnostics" in summary[0]

    info = read_info(output)  # complete: summary and footer present
    assert {t.name: t.message_count for t in info.topics} == {"/joint_states": published, "/robot_description": 1}
    if output.suffix != ".mcap":
        assert (output / "metadata.yaml").is_file()
    recorded = read_with_rosbags(output)
    positions = [list(m.position) for _, m in recorded["/joint_states"]]
    assert positions == [[float(i), -float(i)] for i in range(published)]
    assert recorded["/robot_description"][0][1].data == URDF
    log_times = [t for t, _ in recorded["/joint_states"]]
    assert log_times == sorted(log_times)
    # Receive time: after the send, well within a second of it.
    assert all(0 <= log - sent < 1_000_000_000 for log, sent in zip(log_times, send_times))

    endpoints = {topic: ros.get_publishers_info_by_topic(topic)[0] for topic in ("/joint_states", "/robot_description")}
    for topic in info.topics:
        # rosidl's hash as rclpy reports it for the live publisher.
        assert topic.type_hash == str(endpoints[topic.name].topic_type_hash)
    assert info.topic("/robot_description").offered_qos_profiles.is_transient_local
    assert not info.topic("/joint_states").offered_qos_profiles.is_transient_local


def test_sigkill_then_salvage_recovers_all_but_the_last_second(ros, processes, tmp_path):
    states = ros.create_publisher(JointState, "/joint_states", 100)
    output = tmp_path / "killed.mcap"
    recorder = start_recorder(processes, output, "topics:=[/joint_states]")
    wait_subscribed([states], recorder)
    rate_hz, kill_after_s = 200.0, 2.5
    send_times = []
    start = time.monotonic()
    killed_at = None
    i = 0
    while time.monotonic() - start < kill_after_s + 0.3:
        if killed_at is None and time.monotonic() - start >= kill_after_s:
            recorder.send_signal(signal.SIGKILL)
            killed_at = time.time_ns()
        send_times.append(time.time_ns())
        states.publish(joint_state(ros, i))
        i += 1
        time.sleep(max(0.0, start + i / rate_hz - time.monotonic()))
    recorder.communicate(timeout=10)
    assert recorder.returncode == -signal.SIGKILL

    info = subprocess.run([str(MANIP_KIN), "info", str(output)], capture_output=True, text=True, timeout=60)
    assert info.returncode == 2 and "--salvage" in info.stderr and len(info.stderr.strip().splitlines()) == 1

    saved = tmp_path / "saved.mcap"
    result = subprocess.run(
        [str(MANIP_KIN), "info", "--salvage", str(saved), str(output)], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    recorded = read_with_rosbags(saved)["/joint_states"]
    positions = [m.position[0] for _, m in recorded]
    assert positions == [float(k) for k in range(len(positions))]  # a gap-free prefix
    sent_before = sum(1 for t in send_times if t < killed_at - 1_000_000_000)
    assert len(positions) >= sent_before, (len(positions), sent_before, len(send_times))
    assert len(positions) <= sum(1 for t in send_times if t <= killed_at)


def test_max_messages_ends_the_recording_by_itself(ros, processes, tmp_path):
    states = ros.create_publisher(
        JointState, "/probe/joint_states", QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
    )
    output = tmp_path / "limited.mcap"
    recorder = start_recorder(processes, output, "all_topics:=true", "max_messages:=40", "compression:=none")
    wait_subscribed([states], recorder)
    for i in range(200):
        states.publish(joint_state(ros, i))
        time.sleep(0.002)
        if recorder.poll() is not None:
            break
    _, stderr = recorder.communicate(timeout=30)
    assert recorder.returncode == 0, stderr
    assert "max_messages (40) reached" in stderr
    info = read_info(output)
    assert info.message_count == 40
    assert info.topic("/probe/joint_states").message_count <= 40
    assert info.compression == ("none",)
    assert info.topic("/probe/joint_states").offered_qos_profiles.profiles[0].reliability == "best_effort"


def test_bad_parameter_is_one_line_and_exit_2(processes, tmp_path):
    recorder = start_recorder(processes, tmp_path / "x.mcap", "compression:=bzip2")
    _, stderr = recorder.communicate(timeout=30)
    assert recorder.returncode == 2
    assert "compression" in stderr and "zstd" in stderr
