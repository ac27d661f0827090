"""The recorder's parameters: declared, read and checked once at start (all read-only)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node

from manip_kin.nodes.topics import PIPELINE_TOPIC_TYPES
from manip_kin.recording.errors import RecordingError
from manip_kin.recording.tf_synthesis import DEFAULT_TF_RATE_HZ, TF_TOPICS
from manip_kin.recording.writer import COMPRESSION_CHOICES

# /tf and /tf_static are recorded when a node publishes them (a ROS install), else synthesised.
DEFAULT_TOPICS = tuple(PIPELINE_TOPIC_TYPES) + TF_TOPICS

USAGE = f"""usage: recorder [--ros-args -p NAME:=VALUE ...]

Record topics to a rosbag2-compatible MCAP file (ros2 bag, Foxglove, rosbags read it).

parameters:
  topics        string[]  topics to record; relative names resolve in the recorder's namespace
                          (default: every manip_kin topic of its namespace:
                          {" ".join(DEFAULT_TOPICS)})
  all_topics    bool      record every topic discovered instead, in any namespace, as
                          `ros2 bag record -a` (hidden ones excluded; default false)
  output        string    FILE.mcap for a single file, or a bag directory path
                          (default runs/recording_YYYYmmdd_HHMMSS.mcap)
  compression   string    zstd (default) | lz4 | none: MCAP chunk compression
  duration      double    stop after this many seconds [s]; 0 = until Ctrl-C/SIGTERM (default 0)
  max_messages  int       stop after this many messages; 0 = unlimited (default 0)
  tf_rate_hz    double    rate of the /tf written from joint_states when no node publishes /tf
                          [Hz] (default {DEFAULT_TF_RATE_HZ:g}, as robot_state's tf_rate_hz)
  frame_prefix  string    prefix of the synthesised TF frame ids (default "", as robot_state's)

Without a live /tf, the recorder writes /tf and /tf_static itself (tf2_msgs/msg/TFMessage)
from the recorded joint_states and robot_description, so the file alone shows the arm.

Ctrl-C or SIGTERM finish the file; a SIGKILL loses at most about the last second,
and `manip_kin info --salvage OUT FILE` recovers the rest."""


def _descriptor(description: str, parameter_type: int) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, type=parameter_type, read_only=True)


def default_output() -> str:
    """``runs/recording_<local time>.mcap`` under the working directory."""
    return f"runs/recording_{datetime.now():%Y%m%d_%H%M%S}.mcap"


@dataclass(frozen=True)
class RecorderConfig:
    """The recorder's parameters, checked.

    Attributes:
        topics: topics to record as given (relative names resolve in the node's namespace).
        all_topics: record every discovered topic instead.
        output: ``.mcap`` file or bag directory.
        compression: MCAP chunk compression.
        duration_s: stop after this long [s]; 0 = unlimited.
        max_messages: stop after this many messages; 0 = unlimited.
        tf_rate_hz: rate of the synthesised ``/tf`` [Hz].
        frame_prefix: prefix of the synthesised frame ids.
    """

    topics: tuple[str, ...]
    all_topics: bool
    output: str
    compression: str
    duration_s: float
    max_messages: int
    tf_rate_hz: float
    frame_prefix: str


def read_config(node: Node) -> RecorderConfig:
    """Declare the parameters on the recorder node and return them checked.

    Raises:
        RecordingError: a value outside its valid range, naming the parameter.
    """
    topics = node.declare_parameter(
        "topics", list(DEFAULT_TOPICS), _descriptor("topics to record", ParameterType.PARAMETER_STRING_ARRAY)
    ).value
    all_topics = bool(
        node.declare_parameter(
            "all_topics", False, _descriptor("record every discovered topic", ParameterType.PARAMETER_BOOL)
        ).value
    )
    output = (
        str(
            node.declare_parameter(
                "output",
                "",
                _descriptor(
                    "FILE.mcap or bag directory; empty: timestamped file under runs/",
                    ParameterType.PARAMETER_STRING,
                ),
            ).value
        )
        or default_output()
    )
    compression = str(
        node.declare_parameter(
            "compression", "zstd", _descriptor("zstd | lz4 | none", ParameterType.PARAMETER_STRING)
        ).value
    )
    duration_s = float(
        node.declare_parameter(
            "duration",
            0.0,
            _descriptor("stop after this many seconds; 0 = unlimited", ParameterType.PARAMETER_DOUBLE),
        ).value
    )
    max_messages = int(
        node.declare_parameter(
            "max_messages",
            0,
            _descriptor("stop after this many messages; 0 = unlimited", ParameterType.PARAMETER_INTEGER),
        ).value
    )
    tf_rate_hz = float(
        node.declare_parameter(
            "tf_rate_hz",
            DEFAULT_TF_RATE_HZ,
            _descriptor("rate of the synthesised /tf [Hz]", ParameterType.PARAMETER_DOUBLE),
        ).value
    )
    frame_prefix = str(
        node.declare_parameter(
            "frame_prefix", "", _descriptor("prefix of synthesised frame ids", ParameterType.PARAMETER_STRING)
        ).value
    )
    if not tf_rate_hz > 0:
        raise RecordingError(f"parameter tf_rate_hz is {tf_rate_hz}; valid: a positive rate [Hz]")
    if compression not in COMPRESSION_CHOICES:
        raise RecordingError(f"parameter compression is {compression!r}; valid: {', '.join(COMPRESSION_CHOICES)}")
    if duration_s < 0 or max_messages < 0:
        raise RecordingError(
            f"parameters duration ({duration_s}) and max_messages ({max_messages}) must be >= 0 (0 = unlimited)"
        )
    if not all_topics and not topics:
        raise RecordingError("parameter topics is empty and all_topics is false: nothing to record")
    return RecorderConfig(
        tuple(topics), all_topics, output, compression, duration_s, max_messages, tf_rate_hz, frame_prefix
    )
