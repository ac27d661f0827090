"""The recorder's two intake paths (manip_kin.ros.runtime.polling) record the same thing.

The fast path (the intake thread takes from the middleware, rclpy internals) is what every
other recorder test runs; here the recorder runs both ways as a subprocess —
``MANIP_KIN_PUBLIC_RCLPY=1`` forces the public API (executor callbacks) — and each file
must hold every message published, with its values and stamps, read back by rosbags.
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import signal
import subprocess
import sys
import sysconfig
import threading
import time
from pathlib import Path

import pytest
import rclpy
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState

from manip_kin.ros.runtime.polling import fast_path_problem
from manip_kin.ros.wire.messages import ns_to_stamp

RECORDER = Path(sysconfig.get_path("scripts")) / "recorder"
PUBLISHED = 300


@pytest.fixture
def ros():
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node(f"intake_test_{time.monotonic_ns()}", context=context)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


@contextlib.contextmanager
def _recording(ros, command: list[str], output: Path, env: dict | None = None):
    """The recorder (``command``) recording /joint_states to ``output``; yields it and a
    publisher it has subscribed to; killed at the end if still running."""
    recorder = subprocess.Popen(
        [*command, "--ros-args", "-p", f"output:={output}", "-p", "topics:=[/joint_states]"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        publisher = ros.create_publisher(JointState, "/joint_states", 100)
        deadline = time.monotonic() + 20
        while publisher.get_subscription_count() == 0:
            assert recorder.poll() is None and time.monotonic() < deadline, "the recorder never subscribed"
            time.sleep(0.05)
        time.sleep(0.3)
        yield recorder, publisher
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.communicate(timeout=10)


def test_fast_path_is_used_on_the_checked_rclpy():
    assert fast_path_problem() == ""
    os.environ["MANIP_KIN_PUBLIC_RCLPY"] = "1"
    try:
        assert "MANIP_KIN_PUBLIC_RCLPY" in fast_path_problem()
    finally:
        del os.environ["MANIP_KIN_PUBLIC_RCLPY"]


@pytest.mark.parametrize("public", [False, True], ids=["fast", "public-api"])
def test_both_intake_paths_record_every_message(ros, tmp_path, public):
    env = dict(os.environ)
    if public:
        env["MANIP_KIN_PUBLIC_RCLPY"] = "1"
    output = tmp_path / "run.mcap"
    with _recording(ros, [str(RECORDER)], output, env) as (recorder, publisher):
        stamps = []
        for i in range(PUBLISHED):
            message = JointState(name=["j"], position=[float(i)])
            stamps.append(1_700_000_000_000_000_000 + i * 1_000_000)
            message.header.stamp = ns_to_stamp(stamps[-1])
            publisher.publish(message)
            time.sleep(0.002)
        time.sleep(0.5)
        recorder.send_signal(signal.SIGINT)
        _, stderr = recorder.communicate(timeout=30)
    assert recorder.returncode == 0, stderr
    assert ("intake: public rclpy API" in stderr) == public, stderr
    assert f"recorded 1 topics, {PUBLISHED} messages" in stderr and "0 dropped" in stderr, stderr
    with AnyReader([output], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        recorded = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert [m.position[0] for m in recorded] == [float(i) for i in range(PUBLISHED)]
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in recorded] == stamps


# The recorder with a wide window inside the MCAP writer's chunk write: between emptying the
# chunk's buffer and its index (mcap's ChunkBuilder.end() and reset()), on the executor thread.
RECORDER_WITH_A_SLOW_CHUNK_WRITE = """
import sys, threading, time
import mcap._chunk_builder as chunk_builder
from manip_kin.ros.nodes.recorder import main

end = chunk_builder.ChunkBuilder.end

def slow_end(self):
    data = end(self)
    if threading.current_thread() is threading.main_thread():
        print("writing a chunk", flush=True)
        time.sleep(0.3)
    return data

chunk_builder.ChunkBuilder.end = slow_end
sys.exit(main(["recorder", *sys.argv[1:]]))
"""


def test_ctrl_c_during_a_chunk_write_loses_nothing(ros, tmp_path):
    """Ctrl-C once raised KeyboardInterrupt inside the executor's periodic flush, half-way
    through a chunk: the file then lacked the chunk's messages (summary 300, file 143 in a
    loaded run). Here the Ctrl-C lands in that window every time."""
    output = tmp_path / "run.mcap"
    with _recording(ros, [sys.executable, "-c", RECORDER_WITH_A_SLOW_CHUNK_WRITE], output) as (recorder, publisher):
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: [lines.put(line) for line in recorder.stdout], daemon=True).start()
        published = 0
        deadline = time.monotonic() + 60
        while True:
            # A burst, then quiet: the intake thread flushes when it writes after the flush
            # interval, so in the quiet the pending messages are the executor timer's to flush.
            for _ in range(50):
                publisher.publish(JointState(name=["j"], position=[float(published)]))
                published += 1
                time.sleep(0.002)
            try:
                lines.get(timeout=1.0)  # the executor's flush is inside a chunk write
                break
            except queue.Empty:
                assert time.monotonic() < deadline, "no chunk write on the executor thread"
        recorder.send_signal(signal.SIGINT)
        _, stderr = recorder.communicate(timeout=30)
    assert recorder.returncode == 0, stderr
    counted = re.search(r"recorded 1 topics, (\d+) messages", stderr)
    assert counted and "0 dropped" in stderr, stderr
    with AnyReader([output], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        positions = [reader.deserialize(raw, c.msgtype).position[0] for c, _, raw in reader.messages()]
    assert positions == [float(i) for i in range(published)]
    assert int(counted.group(1)) == published
