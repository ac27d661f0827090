"""A live pipeline run recorded by the recorder node, read back independently, and plotted.

The pipeline (robot_state, cartesian_controller, trajectory_generator) and the recorder run
as separate processes. While the arm moves to a goal, this test subscribes to the same
topics; afterwards the file is read with ``rosbags`` (independent of our writer) and with
rclpy, and every message this test saw must be in the file with the same values.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState

from manip_kin.pipeline import NodeProcess, Pipeline, pipeline_processes
from manip_kin.plotting import FIGURES, load_run, tracking_errors
from manip_kin.recording import read_info, read_messages
from manip_kin.rotations import make_transform, rpy_to_matrix

MANIP_KIN = Path(sys.executable).parent / "manip_kin"
GOAL = make_transform(rpy_to_matrix(0.0, 1.2, 0.3), [0.2, -0.8, 0.35])


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory):
    """Record a genova7 goal; returns (file, joint states seen by the test, tool poses seen)."""
    out = tmp_path_factory.mktemp("live") / "run.mcap"
    recorder = NodeProcess("recorder", "recorder", {"output": str(out)})
    controller = {"gain_linear": 2.0, "gain_angular": 2.0}
    processes = [recorder] + pipeline_processes("genova7", rate_hz=200.0, controller=controller)
    seen_states: list[JointState] = []
    seen_tool: list[PoseStamped] = []
    with Pipeline(processes) as pipeline:
        client = pipeline.client()
        client.node.create_subscription(JointState, "/joint_states", seen_states.append, 1000)
        client.node.create_subscription(PoseStamped, "/tool_pose", seen_tool.append, 1000)
        client.spin_for(0.5)
        stamp = client.send_goal(GOAL)
        converged, status = client.wait_converged(stamp, timeout=40)
        assert converged, status
        # A one-shot message from a publisher created just now is recorded too.
        client.send_line(GOAL)
        client.spin_for(0.3)
        assert pipeline.stop_process("recorder", timeout=15) == 0
        summary = pipeline.log_text("recorder").strip().splitlines()[-1]
    return out, seen_states, seen_tool, summary


def test_recorder_summary_reports_no_loss(recorded_run):
    _, _, _, summary = recorded_run
    # Nothing lost, and /diagnostics (three publishers numbering their own messages) is not
    # mistaken for a lossy topic.
    assert "recorded" in summary and "; 0 dropped" in summary, summary


def test_rosbags_reads_every_message_the_test_saw_with_the_same_values(recorded_run):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path, seen_states, seen_tool, _ = recorded_run
    assert len(seen_states) > 200 and len(seen_tool) > 200
    recorded_states: dict[tuple[int, int], np.ndarray] = {}
    recorded_tool: dict[tuple[int, int], np.ndarray] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        connections = [c for c in reader.connections if c.topic in ("/joint_states", "/tool_pose")]
        for connection, _timestamp, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
            key = (message.header.stamp.sec, message.header.stamp.nanosec)
            if connection.topic == "/joint_states":
                recorded_states[key] = np.asarray(message.position)
                assert list(message.name) == [f"joint{i}" for i in range(1, 8)]
            else:
                p = message.pose.position
                recorded_tool[key] = np.array([p.x, p.y, p.z])
    # Discovery settles in the first moments after a subscription appears; from 0.5 s after the
    # recorder's first message on, every message this test saw must be in the file.
    settled = {
        topic: _plus_seconds(min(keys), 0.5) for topic, keys in (("states", recorded_states), ("tool", recorded_tool))
    }
    checked = 0
    for message in seen_states:
        key = (message.header.stamp.sec, message.header.stamp.nanosec)
        if key >= settled["states"]:
            assert key in recorded_states, f"joint state stamped {key} missing from the recording"
            np.testing.assert_array_equal(recorded_states[key], np.asarray(message.position))
            checked += 1
    for message in seen_tool:
        key = (message.header.stamp.sec, message.header.stamp.nanosec)
        if key >= settled["tool"]:
            p = message.pose.position
            np.testing.assert_array_equal(recorded_tool[key], [p.x, p.y, p.z])
    assert checked > 200
    # The run ends at the goal: the last recorded tool position is the goal position.
    last = recorded_tool[max(recorded_tool)]
    np.testing.assert_allclose(last, GOAL[:3, 3], atol=2e-4)


def _plus_seconds(stamp: tuple[int, int], seconds: float) -> tuple[int, int]:
    total = stamp[0] * 1_000_000_000 + stamp[1] + int(seconds * 1e9)
    return divmod(total, 1_000_000_000)


def test_rclpy_reader_counts_match_info(recorded_run):
    path = recorded_run[0]
    info = read_info(path)
    counts: dict[str, int] = {}
    for topic, _message, log_time_ns, publish_time_ns in read_messages(path):
        counts[topic] = counts.get(topic, 0) + 1
        assert log_time_ns > 0 and publish_time_ns > 0
    for topic in (
        "/joint_states",
        "/tool_pose",
        "/joint_velocity_commands",
        "/robot_description",
        "/goal_pose",
        "/line_target",
    ):
        assert counts.get(topic, 0) == info.topic(topic).message_count > 0, topic
    assert counts["/robot_description"] == 1 and counts["/line_target"] == 1


def test_the_recorded_errors_decay_to_the_goal(recorded_run):
    run = load_run(recorded_run[0])
    time, position_error, orientation_error = tracking_errors(run)
    assert position_error[0] > 0.05  # the goal is far from the start
    assert position_error[-1] < 2e-4 and orientation_error[-1] < 2e-3
    assert run.joint_position.shape[1] == 7 and run.command.shape[1] == 7


def _figures_in(directory: Path) -> set[str]:
    return {p.name for p in directory.glob("*.png") if p.stat().st_size > 10_000}


def test_plot_writes_every_figure_from_the_recorded_run(recorded_run, tmp_path):
    result = subprocess.run(
        [str(MANIP_KIN), "plot", str(recorded_run[0]), "--out", str(tmp_path / "plots")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert _figures_in(tmp_path / "plots") == set(FIGURES)


def test_replayed_and_re_recorded_run_plots_too(recorded_run, tmp_path):
    re_recorded = tmp_path / "replayed.mcap"
    recorder = NodeProcess("recorder", "recorder", {"output": str(re_recorded)})
    with Pipeline([recorder]) as pipeline:
        replay = subprocess.run(
            [str(MANIP_KIN), "replay", str(recorded_run[0]), "--rate", "4", "--wait-for-subscribers", "8", "--quiet"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert replay.returncode == 0, replay.stderr
        assert pipeline.stop_process("recorder", timeout=15) == 0
    original = read_info(recorded_run[0])
    copy = read_info(re_recorded)
    for topic in ("/joint_states", "/tool_pose", "/robot_description"):
        assert copy.topic(topic).message_count == original.topic(topic).message_count, topic
    result = subprocess.run(
        [str(MANIP_KIN), "plot", str(re_recorded), "--out", str(tmp_path / "plots")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert _figures_in(tmp_path / "plots") == set(FIGURES)
