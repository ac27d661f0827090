"""Recordings of manip_kin runs: rosbag2-compatible MCAP files, their inspection and replay.

* :class:`RecordingWriter` writes a ``.mcap`` file or a rosbag2 bag directory
  that ``ros2 bag info/play``, Foxglove and ``rosbags`` read.
* :func:`read_messages` reads one back into rclpy messages (for plots):
  ``for topic, msg, log_time_ns, publish_time_ns in read_messages(path, topics=[...])``.
* :func:`read_info` is ``manip_kin info``; :func:`salvage` recovers a truncated file.
* :func:`manip_kin.recording.replay.replay` is ``manip_kin replay``.

The recorder node is :mod:`manip_kin.ros.nodes.recorder`.
"""

from manip_kin.recording.errors import CorruptRecordingError, MessageDefinitionError, RecordingError
from manip_kin.recording.info import RecordingInfo, read_info
from manip_kin.recording.reader import RecordedMessage, iter_raw_messages, read_messages
from manip_kin.recording.salvage import SalvageReport, salvage
from manip_kin.recording.summary import RecordingSummary
from manip_kin.recording.writer import RecordingWriter

__all__ = [
    "CorruptRecordingError",
    "MessageDefinitionError",
    "RecordedMessage",
    "RecordingError",
    "RecordingInfo",
    "RecordingSummary",
    "RecordingWriter",
    "SalvageReport",
    "iter_raw_messages",
    "read_info",
    "read_messages",
    "salvage",
]
