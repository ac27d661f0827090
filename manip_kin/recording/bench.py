"""Cost of writing recordings, for ``make bench`` (not run by the tests).

:func:`benchmark_writer` times the writer alone, without ROS transport:

* ``raw``: :meth:`RecordingWriter.write_raw` of CDR bytes, which is what the
  recorder node does per received message;
* ``object``: :meth:`RecordingWriter.write` of an rclpy message (serialize,
  trim to the real CDR length, write), what offline tools do.

Both include chunking, zstd compression, flushing and the final summary.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

NS_PER_S = 1_000_000_000


def _joint_state(index: int, joints: int, stamp_ns: int) -> Any:
    from sensor_msgs.msg import JointState

    message = JointState()
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp_ns, NS_PER_S)
    message.header.frame_id = "base_link"
    message.name = [f"joint_{j + 1}" for j in range(joints)]
    message.position = [0.001 * index + 0.1 * j for j in range(joints)]
    message.velocity = [0.01 * j for j in range(joints)]
    return message


def benchmark_writer(n_messages: int = 20_000, joints: int = 7, compression: str = "zstd") -> dict:
    """Measure the cost of writing ``sensor_msgs/JointState`` messages at 1 kHz timestamps.

    Args:
        n_messages: messages per measurement (>= 1).
        joints: joints per message (7 = the demo arms).
        compression: ``zstd``, ``lz4`` or ``none``.

    Returns:
        ``{"n_messages", "joints", "compression", "message_bytes",
        "raw_write_us_per_message", "object_write_us_per_message",
        "file_bytes_per_message"}``: microseconds of wall time per message
        (process is single-threaded, so this is also CPU time), CDR bytes of one
        message, and compressed file bytes per message.
    """
    from rclpy.serialization import serialize_message

    from manip_kin.recording.cdr import CdrLayout
    from manip_kin.recording.msgdef import local_definitions
    from manip_kin.recording.writer import RecordingWriter

    if n_messages < 1:
        raise ValueError(f"n_messages must be >= 1, got {n_messages}")
    type_name = "sensor_msgs/msg/JointState"
    start_ns = time.time_ns()
    period_ns = NS_PER_S // 1000
    messages = [_joint_state(i, joints, start_ns + i * period_ns) for i in range(n_messages)]
    layout = CdrLayout(local_definitions(type_name))
    serialized = []
    for message in messages:
        data = serialize_message(message)
        serialized.append(data[: layout.message_length(type_name, data)])

    with tempfile.TemporaryDirectory(prefix="manip_kin_bench_") as directory:
        raw_path = Path(directory) / "raw.mcap"
        begin = time.perf_counter()
        writer = RecordingWriter(raw_path, compression=compression)
        writer.add_topic("/joint_states", type_name)
        for index, data in enumerate(serialized):
            writer.write_raw("/joint_states", data, start_ns + index * period_ns)
        raw_summary = writer.close()
        raw_seconds = time.perf_counter() - begin

        object_path = Path(directory) / "object.mcap"
        begin = time.perf_counter()
        writer = RecordingWriter(object_path, compression=compression)
        for index, message in enumerate(messages):
            writer.write("/joint_states", message, log_time_ns=start_ns + index * period_ns)
        writer.close()
        object_seconds = time.perf_counter() - begin

    return {
        "n_messages": n_messages,
        "joints": joints,
        "compression": compression,
        "message_bytes": len(serialized[0]),
        "raw_write_us_per_message": raw_seconds / n_messages * 1e6,
        "object_write_us_per_message": object_seconds / n_messages * 1e6,
        "file_bytes_per_message": raw_summary.file_bytes / n_messages,
    }
