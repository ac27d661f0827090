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

    from manip_kin.recording.cdr_measure import CdrLayout
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


# ---------------------------------------------------------------------------------------------
# Live recorder throughput: a publisher process and the recorder node as subprocesses.

# The demo's topic set, in the order the load publisher uses them.
LOAD_TOPICS = (
    ("/joint_states", "sensor_msgs/msg/JointState"),
    ("/joint_velocity_commands", "std_msgs/msg/Float64MultiArray"),
    ("/tool_pose", "geometry_msgs/msg/PoseStamped"),
    ("/ee_pose", "geometry_msgs/msg/PoseStamped"),
    ("/tool_twist", "geometry_msgs/msg/TwistStamped"),
    ("/ee_twist", "geometry_msgs/msg/TwistStamped"),
    ("/goal_pose", "geometry_msgs/msg/PoseStamped"),
    ("/goal_twist", "geometry_msgs/msg/TwistStamped"),
)


def _cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of a process (Linux ``/proc``), None elsewhere."""
    import os

    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def publish_load(rate_hz: float, duration_s: float, n_topics: int, depth: int = 100, wait_s: float = 20.0) -> int:
    """Publish one message per topic every ``1/rate_hz`` s for ``duration_s`` (the bench's load).

    Waits (up to ``wait_s``) until every topic has a subscriber first. Returns the
    number of messages published. Run in its own process (``python
    bench/recorder.py publish RATE DURATION TOPICS``) so that its CPU is
    not the recorder's.
    """
    import rclpy

    from manip_kin.recording.reader import message_class

    rclpy.init(args=[])
    node = rclpy.create_node("recorder_bench_load")
    try:
        publishers = []
        for topic, type_name in LOAD_TOPICS[:n_topics]:
            message = message_class(type_name)()
            if type_name.endswith("JointState"):
                message.name = [f"joint_{j + 1}" for j in range(7)]
                message.position, message.velocity = [0.1] * 7, [0.2] * 7
            elif type_name.endswith("Float64MultiArray"):
                message.data = [0.1] * 7
            publishers.append((node.create_publisher(type(message), topic, depth), message))
        deadline = time.monotonic() + wait_s
        while any(p.get_subscription_count() == 0 for p, _ in publishers) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
        count, period = 0, 1.0 / rate_hz
        start = time.perf_counter()
        tick = start
        while time.perf_counter() - start < duration_s:
            now_ns = time.time_ns()
            for publisher, message in publishers:
                if hasattr(message, "header"):
                    message.header.stamp.sec, message.header.stamp.nanosec = divmod(now_ns, NS_PER_S)
                publisher.publish(message)
                count += 1
            tick += period
            time.sleep(max(0.0, tick - time.perf_counter()))
        time.sleep(0.5)  # let the last samples be delivered before the participant goes
        return count
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def benchmark_recorder(rate_hz: float = 1000.0, duration_s: float = 8.0, n_topics: int = 8, depth: int = 100) -> dict:
    """Record a synthetic load with the ``recorder`` node; measure loss and the recorder's CPU.

    Starts the recorder and a load publisher (:func:`publish_load`) as
    subprocesses on the current ``ROS_DOMAIN_ID`` (set it to a free one), reads
    the recorder's CPU time from ``/proc`` over the publishing window, stops it
    with SIGINT and counts what the file holds.

    Args:
        rate_hz: messages per second per topic.
        duration_s: publishing time [s] (the CPU window skips its first second).
        n_topics: how many of :data:`LOAD_TOPICS` (8 = the 1 kHz pipeline's topic set).
        depth: publisher queue depth (reliable keep-last publishers overwrite unacknowledged
            samples when it is too small, which shows as loss).

    Returns:
        ``{"rate_hz", "topics", "published", "recorded", "lost", "target_messages_per_s",
        "published_messages_per_s", "recorder_cpu_percent", "recorder_summary"}``; CPU in
        percent of one core (None where ``/proc`` is missing).
    """
    import signal
    import subprocess
    import sys

    from manip_kin.recording.info import read_info

    with tempfile.TemporaryDirectory(prefix="manip_kin_recbench_") as directory:
        output = Path(directory) / "load.mcap"
        topics = ",".join(topic for topic, _ in LOAD_TOPICS[:n_topics])
        recorder = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "manip_kin.ros.nodes.recorder",
                "--ros-args",
                "-p",
                f"output:={output}",
                "-p",
                f"topics:=[{topics}]",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        load = subprocess.Popen(
            [
                sys.executable,
                str(Path(__file__).resolve()),
                "publish",
                str(rate_hz),
                str(duration_s),
                str(n_topics),
                str(depth),
            ],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            # Discovery and matching first; then measure a window inside the publishing time.
            time.sleep(min(3.0, duration_s / 2))
            cpu_start, wall_start = _cpu_seconds(recorder.pid), time.monotonic()
            window = max(0.5, duration_s - 2.0)
            time.sleep(window)
            cpu_end, wall_end = _cpu_seconds(recorder.pid), time.monotonic()
            published = int((load.communicate(timeout=duration_s + 60)[0] or "0").strip().splitlines()[-1])
            recorder.send_signal(signal.SIGINT)
            _, stderr = recorder.communicate(timeout=60)
        finally:
            for process in (load, recorder):
                if process.poll() is None:
                    process.kill()
                    process.communicate()
        recorded = read_info(output).message_count
    cpu = None
    if cpu_start is not None and cpu_end is not None:
        cpu = 100.0 * (cpu_end - cpu_start) / (wall_end - wall_start)
    summary = next((line for line in stderr.splitlines() if line.startswith("recorder: ")), "")
    return {
        "rate_hz": rate_hz,
        "topics": n_topics,
        "published": published,
        "recorded": recorded,
        "lost": published - recorded,
        "target_messages_per_s": rate_hz * n_topics,
        # The load publisher is Python too: at high rates it falls behind its target.
        "published_messages_per_s": published / duration_s,
        "recorder_cpu_percent": cpu,
        "recorder_summary": summary,
    }


if __name__ == "__main__":
    import sys

    if len(sys.argv) >= 5 and sys.argv[1] == "publish":
        extra = [int(sys.argv[5])] if len(sys.argv) > 5 else []
        print(publish_load(float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]), *extra), flush=True)
    else:
        import json

        print(json.dumps({"writer": benchmark_writer(), "recorder": benchmark_recorder()}, indent=2))
