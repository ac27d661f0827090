"""Recordings of manip_kin runs: rosbag2-compatible MCAP files, their inspection and replay.

* :class:`RecordingWriter` writes a ``.mcap`` file or a rosbag2 bag directory
  that ``ros2 bag info/play``, Foxglove and ``rosbags`` read.
* :func:`read_messages` reads one back into rclpy messages (for plots):
  ``for topic, msg, log_time_ns, publish_time_ns in read_messages(path, topics=[...])``.
* :func:`read_info` is ``manip_kin info``; :func:`salvage` recovers a truncated file.
* :func:`manip_kin.recording.replay.replay` is ``manip_kin replay``.
* :func:`benchmark_writer` measures the write cost per message, :func:`benchmark_recorder`
  the recorder node's loss and CPU under a synthetic load (both for ``make bench``).

The recorder node is :mod:`manip_kin.nodes.recorder`.
"""

from manip_kin.recording.errors import CorruptRecordingError, MessageDefinitionError, RecordingError
from manip_kin.recording.reader import (
    RecordedMessage,
    RecordingInfo,
    SalvageReport,
    iter_raw_messages,
    read_info,
    read_messages,
    salvage,
)
from manip_kin.recording.writer import RecordingSummary, RecordingWriter

__all__ = [
    "benchmark_recorder",
    "benchmark_writer",
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


def __getattr__(name: str):
    # Lazy, so that `python -m manip_kin.recording.bench` (the bench's load publisher) does not
    # find its own module already imported by this package.
    if name in ("benchmark_writer", "benchmark_recorder"):
        from manip_kin.recording import bench

        return getattr(bench, name)
    raise AttributeError(f"module 'manip_kin.recording' has no attribute {name!r}")
