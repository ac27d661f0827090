"""The recorder's parameters: declared, read and checked once at start (all read-only)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from rclpy.node import Node

from manip_kin.recording.errors import RecordingError
from manip_kin.recording.tf_synthesis import DEFAULT_TF_RATE_HZ, TF_TOPICS
from manip_kin.recording.writer import COMPRESSION_CHOICES
from manip_kin.ros.runtime.declared_params import declare_parameters
from manip_kin.ros.runtime.param_struct import param_struct
from manip_kin.ros.runtime.params import ParamSpec
from manip_kin.ros.runtime.usage import usage_text
from manip_kin.ros.wire.topics import PIPELINE_TOPIC_TYPES

NODE_NAME = "recorder"

# /tf and /tf_static are recorded when a node publishes them (a ROS install), else synthesised.
DEFAULT_TOPICS = tuple(PIPELINE_TOPIC_TYPES) + TF_TOPICS

#: The recorder's parameters (all read-only: read once at start). The ranges keep every timer
#: period a finite number of nanoseconds (a ``tf_rate_hz`` of 1e-300 Hz is refused, not an
#: OverflowError at start).
PARAMETERS = (
    ParamSpec(
        "topics",
        "str_list",
        list(DEFAULT_TOPICS),
        "topics to record; relative names resolve in the recorder's namespace, absolute ones "
        "(/left/joint_states) are taken as given",
        default_text="every manip_kin topic of the recorder's namespace",
    ),
    ParamSpec(
        "all_topics",
        "bool",
        False,
        "record every topic discovered instead, in any namespace, as ros2 bag record -a (hidden topics excluded)",
    ),
    ParamSpec("output", "str", "", "FILE.mcap or a bag directory ('' = runs/recording_YYYYmmdd_HHMMSS.mcap)"),
    ParamSpec("compression", "str", "zstd", "MCAP chunk compression", choices=COMPRESSION_CHOICES),
    ParamSpec(
        "duration",
        "float",
        0.0,
        "stop after this long (0 = until Ctrl-C or SIGTERM)",
        "s",
        minimum=0.01,
        maximum=1e7,  # 116 days: beyond any recording, and a timer period that fits in ns
        zero_is_off=True,
    ),
    ParamSpec(
        "max_messages",
        "int",
        0,
        "stop after this many messages (0 = unlimited)",
        minimum=1,
        maximum=10**12,  # 30 years of a 1 kHz topic
        zero_is_off=True,
    ),
    ParamSpec(
        "tf_rate_hz",
        "float",
        DEFAULT_TF_RATE_HZ,
        "rate of the /tf written from joint_states when no node publishes /tf (as robot_state's)",
        "Hz",
        minimum=0.1,
        maximum=1e3,  # as robot_state's tf_rate_hz
    ),
    ParamSpec("frame_prefix", "str", "", "prefix of the synthesised TF frame ids (as robot_state's)"),
)


#: The parameters as a typed struct (what the node reads).
RecorderParams = param_struct("RecorderParams", PARAMETERS, "recorder's parameters, typed (docs/interfaces.md).")

USAGE = usage_text(
    NODE_NAME,
    "Record topics to a rosbag2-compatible MCAP file (ros2 bag, Foxglove, rosbags read it).\n"
    "Without a live /tf, the recorder writes /tf and /tf_static itself (tf2_msgs/msg/TFMessage)\n"
    "from the recorded joint_states and robot_description, so the file alone shows the arm.\n"
    "Ctrl-C or SIGTERM finish the file; a SIGKILL loses at most about the last second,\n"
    "and `manip_kin info --salvage OUT FILE` recovers the rest.",
    PARAMETERS,
    subscribes=[("the topics parameter's", "any type", "default " + " ".join(DEFAULT_TOPICS) + "; or all, all_topics")],
    publishes=[("output", "MCAP file or bag directory", "")],
    example="recorder --ros-args -p output:=runs/line.mcap -p duration:=10.0",
)


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
        InvalidArgumentError: a value of the wrong type or outside its range, naming the parameter.
        RecordingError: nothing to record.
    """
    params = declare_parameters(node, RecorderParams)
    if not params.all_topics and not params.topics:
        raise RecordingError("parameter topics is empty and all_topics is false: nothing to record")
    return RecorderConfig(
        tuple(params.topics),
        params.all_topics,
        params.output or default_output(),
        params.compression,
        params.duration,
        params.max_messages,
        params.tf_rate_hz,
        params.frame_prefix,
    )
