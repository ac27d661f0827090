"""Hostile recordings (issue 29): ``info``, ``info --salvage``, ``plot`` and ``replay`` never print a
traceback; bombs and hostile lengths are bounded; a recording never chooses what Python imports;
no byte of a file outside a bag is printed; salvage resynchronises after a damaged chunk.

The damaged files are real recordings (written by the recorder's RecordingWriter) loaded in one
subprocess bounded by RLIMIT_CPU, RLIMIT_AS and a CPU alarm per command (``hostile_recordings.py``).
"""

from __future__ import annotations

import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from bounded_cli import run_bounded_script
from hostile_recordings import chunk_offsets
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.recording import RecordingWriter
from manip_kin.recording.reader import message_class

EXAMPLES = 40
MANIP_KIN = Path(sysconfig.get_path("scripts")) / "manip_kin"
ALL_MESSAGES = 280  # write_recording: 40 messages on 7 topics


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory) -> dict:
    return run_bounded_script("hostile_recordings.py", tmp_path_factory.mktemp("hostile") / "out.json", str(EXAMPLES))


CASES = [
    "chunk_length_2_64",
    "chunk_length_2_40",
    "chunk_size_2_64",
    "chunk_size_2_40",
    "middle_chunk_bits",
    "bomb_declared",
    "bomb_understated",
    "metadata_damaged",
    "metadata_list",
    "metadata_paths_5",
    "metadata_paths_escape",
    "metadata_alias_bomb",
    "symlinked_mcap",
    "schema_this",
    "wrong_schema",
    "wrong_type_data",
]


@pytest.mark.parametrize("case", CASES)
def test_every_command_exits_0_or_2_with_one_line(outcomes, case):
    for command in ("info", "info_json", "salvage", "plot"):
        result = outcomes[case][command]
        assert result["problem"] is None, f"{command}: {result['problem']}"


@pytest.mark.parametrize("case", ["chunk_length_2_64", "chunk_length_2_40", "chunk_size_2_64", "chunk_size_2_40"])
def test_a_hostile_first_chunk_is_refused_and_salvage_resynchronises_after_it(outcomes, case):
    assert outcomes["chunk_count"] > 20
    assert outcomes[case]["plot"]["rc"] == 2 and "ChunkError" in outcomes[case]["plot"]["stderr"]
    # Only the first chunk's messages (a few) are lost; the file's summary gives the channels.
    assert ALL_MESSAGES - 12 <= outcomes[case]["salvaged_count"] < ALL_MESSAGES


def test_salvage_recovers_the_chunks_after_a_damaged_one_in_the_middle(outcomes):
    assert ALL_MESSAGES - 12 <= outcomes["middle_chunk_bits"]["salvaged_count"] < ALL_MESSAGES
    assert "damaged record" in outcomes["middle_chunk_bits"]["salvage"]["stdout"]


@pytest.mark.parametrize(
    ("case", "why"), [("bomb_declared", "declares 1073741824"), ("bomb_understated", "inflates to more")]
)
def test_a_zip_bomb_chunk_is_refused_without_inflating_it(outcomes, case, why):
    assert outcomes[case]["salvage"]["rc"] == 2 and why in outcomes[case]["salvage"]["stderr"]


@pytest.mark.parametrize(
    ("case", "why"),
    [
        ("metadata_damaged", "malformed YAML"),
        ("metadata_list", "valid: a mapping"),
        ("metadata_paths_5", "relative_file_paths is 5"),
        ("metadata_paths_escape", "missing files"),
        ("metadata_alias_bomb", "aliases expanded"),
        ("symlinked_mcap", "leads outside the bag directory"),
    ],
)
def test_bag_metadata_of_the_wrong_types_and_paths_out_of_the_bag_are_one_line(outcomes, case, why):
    for command in ("info", "salvage", "plot"):
        assert outcomes[case][command]["rc"] == 2 and why in outcomes[case][command]["stderr"]


def test_a_schema_named_this_msg_thing_imports_nothing(outcomes):
    result = outcomes["schema_this"]["plot"]
    assert result["rc"] == 2 and "nothing to plot" in result["stderr"]  # the commands have a foreign type
    assert "this" not in sys.modules
    with pytest.raises(Exception, match=r"no share/this/msg/Thing\.msg"):
        message_class("this/msg/Thing")
    assert "this" not in sys.modules
    assert message_class("std_msgs/msg/String").__name__ == "String"  # an installed interface package


def test_mutated_recordings_never_give_a_traceback(outcomes):
    assert outcomes["hypothesis"]["problem"] is None, outcomes["hypothesis"]["problem"]


def _commands_on_a_ros2_control_topic(path: Path, topic: str) -> None:
    with RecordingWriter(path) as writer:
        for i in range(10):
            t = 1_700_000_000_000_000_000 + i * 10_000_000
            writer.write("/joint_states", JointState(name=["a", "b"], position=[0.1 * i, -0.1 * i]), log_time_ns=t)
            writer.write(topic, Float64MultiArray(data=[float(i), -2.0 * i]), log_time_ns=t + 1)


def test_plot_finds_the_commands_by_type_on_a_remapped_topic(tmp_path):
    from manip_kin.viz.run_data import load_run

    path = tmp_path / "remapped.mcap"
    _commands_on_a_ros2_control_topic(path, "/forward_velocity_controller/commands")
    run = load_run(path)
    assert run.found_by_type == {"/joint_velocity_commands": "/forward_velocity_controller/commands"}
    np.testing.assert_array_equal(run.command, [[float(i), -2.0 * i] for i in range(10)])
    np.testing.assert_allclose(run.command_time, np.arange(10) * 0.01, atol=1e-9)


def test_a_type_is_looked_up_only_when_one_topic_has_it_and_poses_only_by_name():
    from manip_kin.viz.run_data import plotted_topics

    two = {"/a/commands": "std_msgs/msg/Float64MultiArray", "/b/commands": "std_msgs/msg/Float64MultiArray"}
    assert plotted_topics(two) == {}
    poses = {"/my_tool": "geometry_msgs/msg/PoseStamped", "/joint_states": "sensor_msgs/msg/JointState"}
    assert plotted_topics(poses) == {"/joint_states": "/joint_states"}
    # A plotted name of the wrong type is neither read as itself nor as another plotted topic.
    assert plotted_topics({"/tool_pose": "std_msgs/msg/String"}) == {}


def test_replay_of_a_damaged_recording_is_one_line_and_exit_2(tmp_path):
    path = tmp_path / "run.mcap"
    _commands_on_a_ros2_control_topic(path, "/joint_velocity_commands")
    data = bytearray(path.read_bytes())
    first = chunk_offsets(bytes(data))[0]
    data[first + 60 : first + 68] = bytes(b ^ 0xFF for b in data[first + 60 : first + 68])
    path.write_bytes(bytes(data))
    result = subprocess.run(
        [str(MANIP_KIN), "replay", str(path), "--wait-for-subscribers", "0", "--quiet"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and str(path) in lines[0], result.stderr[-2000:]
