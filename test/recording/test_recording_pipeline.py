"""A live pipeline run recorded by the recorder node, read back independently, and plotted.

The pipeline (robot_state, cartesian_controller, trajectory_generator) and the recorder run
as separate processes. While the arm moves to a goal, this test subscribes to the same
topics; afterwards the file is read with ``rosbags`` (independent of our writer) and with
rclpy, and every message this test saw must be in the file with the same values.
"""

from __future__ import annotations

import subprocess
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from pipeline_checks import checked_pipeline, recorder_reads
from sensor_msgs.msg import JointState

from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.pipeline import NodeProcess, pipeline_processes
from manip_kin.recording import read_info, read_messages
from manip_kin.viz.plotting import FIGURES, TF_FIGURE
from manip_kin.viz.run_data import load_run, tracking_errors

MANIP_KIN = Path(sysconfig.get_path("scripts")) / "manip_kin"
GOAL = make_transform(rpy_to_matrix(0.0, 1.2, 0.3), [0.2, -0.8, 0.35])


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory):
    """Record a genova7 goal; returns (file, joint states seen by the test, tool poses seen, the
    recorder's summary line, times the goal was sent again)."""
    out = tmp_path_factory.mktemp("live") / "run.mcap"
    recorder = NodeProcess("recorder", "recorder", {"output": str(out)})
    controller = {"gain_linear": 2.0, "gain_angular": 2.0}
    processes = [recorder] + pipeline_processes("genova7", rate_hz=200.0, controller=controller)
    seen_states: list[JointState] = []
    seen_tool: list[PoseStamped] = []
    with checked_pipeline(processes) as pipeline:
        client = pipeline.client()
        client.node.create_subscription(JointState, "/joint_states", seen_states.append, 1000)
        client.node.create_subscription(PoseStamped, "/tool_pose", seen_tool.append, 1000)
        assert client.spin_until(lambda: seen_states and seen_tool, 10), "the test's subscriptions got nothing"
        # The recorder matched before the arm moves (once it matched late, and the recording
        # began with the arm 3 cm from the goal).
        streams = ("/joint_states", "/tool_pose", "/joint_velocity_commands")
        assert client.spin_until(lambda: recorder_reads(client, streams), 30), "the recorder subscribes to nothing"
        stamp = client.send_goal(GOAL)
        converged, status = client.wait_converged(stamp, timeout=40)
        assert converged, status
        resends = client.resends(stamp)
        # A one-shot message from a publisher created just now is recorded too. send_line returns
        # once every subscriber (the recorder too) acknowledged it: it is in the recorder's queue,
        # which the recorder empties into the file when stopped.
        client.send_line(GOAL)
        assert pipeline.stop_process("recorder", timeout=15) == 0
        summary = pipeline.log_text("recorder").strip().splitlines()[-1]
    return out, seen_states, seen_tool, summary, resends


def test_recorder_summary_reports_no_loss(recorded_run):
    summary = recorded_run[3]
    # Nothing lost, and /diagnostics (three publishers numbering their own messages) is not
    # mistaken for a lossy topic. (That the count is not stuck at 0 is proven where loss is
    # caused: test_recording_recorder.py.)
    assert "recorded" in summary and "; 0 dropped" in summary, summary


def test_rosbags_reads_every_message_the_test_saw_with_the_same_values(recorded_run):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path, seen_states, seen_tool = recorded_run[:3]
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


def test_package_reader_agrees_with_rosbags(recorded_run):
    """manip_kin's reader against rosbags (an independent MCAP and CDR implementation)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = recorded_run[0]
    ours: dict[str, list] = {}
    for topic, message, log_time_ns, publish_time_ns in read_messages(path):
        assert publish_time_ns > 0
        ours.setdefault(topic, []).append((log_time_ns, message))
    theirs: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, timestamp, raw in reader.messages():
            theirs.setdefault(connection.topic, []).append((timestamp, reader.deserialize(raw, connection.msgtype)))
    assert {t: len(m) for t, m in ours.items()} == {t: len(m) for t, m in theirs.items()}
    for topic in ("/joint_states", "/tool_pose", "/joint_velocity_commands", "/goal_pose", "/line_target"):
        assert ours[topic], topic
        assert [t for t, _ in ours[topic]] == [t for t, _ in theirs[topic]], topic
    for (_, a), (_, b) in zip(ours["/joint_states"], theirs["/joint_states"]):
        assert list(a.name) == list(b.name) and list(a.position) == list(b.position)
        assert (a.header.stamp.sec, a.header.stamp.nanosec) == (b.header.stamp.sec, b.header.stamp.nanosec)
    for (_, a), (_, b) in zip(ours["/tool_pose"], theirs["/tool_pose"]):
        assert (a.pose.position.x, a.pose.position.y, a.pose.position.z) == (
            b.pose.position.x,
            b.pose.position.y,
            b.pose.position.z,
        )
    for (_, a), (_, b) in zip(ours["/joint_velocity_commands"], theirs["/joint_velocity_commands"]):
        assert list(a.data) == list(b.data)
    assert [m.data for _, m in ours["/robot_description"]] == [m.data for _, m in theirs["/robot_description"]]
    assert len(ours["/robot_description"]) == 1 and len(ours["/line_target"]) == 1


def test_the_recorded_errors_decay_to_the_goal(recorded_run):
    run = load_run(recorded_run[0])
    time, position_error, orientation_error = tracking_errors(run)
    # The goal is far from the start (0.41 m), so the recording has the goal from when it was sent.
    assert position_error[0] > 0.05, (
        f"the first tool pose after the recorded goal is {position_error[0]:.3f} m from it: goal logged at "
        f"{run.goal.time} s, tool from {run.tool.time[0]:.3f} s, goal sent again {recorded_run[4]} times"
    )
    assert position_error[-1] < 2e-4 and orientation_error[-1] < 2e-3
    assert run.joint_position.shape[1] == 7 and run.command.shape[1] == 7


def _figures_in(directory: Path) -> set[str]:
    """Names of the PNGs in ``directory`` that hold a drawn figure (checked pixel by pixel)."""
    from matplotlib.image import imread

    drawn = set()
    for path in directory.glob("*.png"):
        image = imread(path)
        height, width = image.shape[:2]
        rgb = image[:, :, :3].reshape(-1, 3)
        ink = np.mean(np.any(rgb < 0.9, axis=1))  # share of pixels that are not (near) white
        colours = len(np.unique((rgb * 255).astype(np.uint8), axis=0))
        # A 110 dpi figure of several inches; axes, text and curves (not a blank or one-colour image).
        if height > 300 and width > 500 and 0.01 < ink < 0.6 and colours > 20:
            drawn.add(path.name)
    return drawn


def test_plotted_curves_are_the_recorded_data(recorded_run, tmp_path, monkeypatch):
    """The tool position figure draws the recorded /tool_pose positions (as rosbags reads them)."""
    import matplotlib.figure
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from manip_kin.viz.plotting import plot_run

    drawn: dict[str, list] = {}
    save = matplotlib.figure.Figure.savefig

    def capture(figure, path, *args, **kwargs):
        drawn[Path(path).name] = [[line.get_ydata() for line in axes.get_lines()] for axes in figure.axes]
        return save(figure, path, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", capture)
    plot_run(load_run(recorded_run[0]), tmp_path)
    with AnyReader([recorded_run[0]], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        connections = [c for c in reader.connections if c.topic == "/tool_pose"]
        positions = np.array(
            [
                [m.pose.position.x, m.pose.position.y, m.pose.position.z]
                for m in (reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections))
            ]
        )
    assert len(positions) > 100
    for axis in range(3):
        np.testing.assert_array_equal(drawn["tool_position.png"][axis][0], positions[:, axis])


def test_plot_writes_every_figure_from_the_recorded_run(recorded_run, tmp_path):
    result = subprocess.run(
        [str(MANIP_KIN), "plot", str(recorded_run[0]), "--out", str(tmp_path / "plots")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert _figures_in(tmp_path / "plots") == set(FIGURES) | {TF_FIGURE}  # the recorder wrote /tf


def test_replayed_and_re_recorded_run_plots_too(recorded_run, tmp_path):
    re_recorded = tmp_path / "replayed.mcap"
    recorder = NodeProcess("recorder", "recorder", {"output": str(re_recorded)})
    with checked_pipeline([recorder]) as pipeline:
        replay = subprocess.run(
            [str(MANIP_KIN), "replay", str(recorded_run[0]), "--rate", "4", "--wait-for-subscribers", "8", "--quiet"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert replay.returncode == 0, replay.stderr
        assert pipeline.stop_process("recorder", timeout=15) == 0

    # The copy holds the recorded messages, in order. Replay waits only 0.3 s (ACK_WAIT_S) for
    # acknowledgements before it exits, and Fast DDS resends a lost reliable sample only at its
    # heartbeat: under load the last message of a topic can miss the copy. Anything else
    # missing (first messages, a gap inside) fails.
    def stamps(path, topic):
        return [
            (m.header.stamp.sec, m.header.stamp.nanosec) if hasattr(m, "header") else m.data
            for _, m, _, _ in read_messages(path, [topic])
        ]

    for topic in ("/joint_states", "/tool_pose", "/robot_description"):
        original, copy = stamps(recorded_run[0], topic), stamps(re_recorded, topic)
        assert copy in (original, original[:-1]), (topic, len(original), len(copy))
    result = subprocess.run(
        [str(MANIP_KIN), "plot", str(re_recorded), "--out", str(tmp_path / "plots")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert _figures_in(tmp_path / "plots") == set(FIGURES) | {TF_FIGURE}  # the recorder wrote /tf


def test_recording_without_live_tf_gains_tf_that_composes_to_the_tool_pose(recorded_run):
    """No node publishes /tf here (no tf2_msgs): the recorder synthesised it; rosbags reads it."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from manip_kin.viz.arm_animation import iter_tf_poses

    path, summary = recorded_run[0], recorded_run[3]
    assert "/tf synthesised from joint_states" in summary, summary
    counts = {t.name: t.message_count for t in read_info(path).topics}
    assert counts["/tf"] > 20 and counts["/tf_static"] == 1 and counts["/markers"] > 5
    tool = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        wanted = [c for c in reader.connections if c.topic in ("/tf", "/tf_static", "/markers", "/tool_pose")]
        for connection, _timestamp, raw in reader.messages(connections=wanted):
            message = reader.deserialize(raw, connection.msgtype)  # every message decodes
            if connection.topic == "/tool_pose":
                p = message.pose.position
                tool[message.header.stamp.sec * 10**9 + message.header.stamp.nanosec] = np.array([p.x, p.y, p.z])
    matched = 0
    for stamp, _log, poses in iter_tf_poses(path, root="base_link"):
        if stamp in tool:
            matched += 1
            np.testing.assert_allclose(poses["tool"][:3, 3], tool[stamp], atol=1e-12)
    assert matched > 20


def test_foxglove_layout_names_only_recorded_topics(recorded_run):
    import json

    layout = json.loads((Path(__file__).resolve().parents[2] / "config" / "foxglove_layout.json").read_text())
    recorded = {t.name for t in read_info(recorded_run[0]).topics}
    panels = layout["configById"]
    used = set(panels["3D!arm"]["topics"])
    for panel in panels.values():
        used |= {path["value"].split(".")[0] for path in panel.get("paths", [])}
    assert used and used <= recorded, used - recorded
    assert {"/tf", "/tf_static", "/robot_description", "/markers"} <= recorded
