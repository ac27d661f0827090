"""A recording on a full disk (issue 29): one ERROR line, what was flushed kept and the file ended,
exit 1, no traceback. The disk is a small tmpfs the test mounts (it needs root); where mounting
fails the tests skip and say why.
"""

from __future__ import annotations

import subprocess
import sysconfig
import time
import uuid
from pathlib import Path

import pytest
import rclpy
from sensor_msgs.msg import JointState

from manip_kin.recording import RecordingWriter, read_info, read_messages, salvage
from manip_kin.recording.write_failure import RecordingWriteError

RECORDER = Path(sysconfig.get_path("scripts")) / "recorder"
MAGIC = b"\x89MCAP0\r\n"


@pytest.fixture
def small_disk(tmp_path):
    """A 192 KiB tmpfs mounted at tmp_path/disk, unmounted afterwards."""
    mount_point = tmp_path / "disk"
    mount_point.mkdir()
    result = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=192k", f"manip_kin_full_{uuid.uuid4().hex[:8]}", str(mount_point)],
        capture_output=True,
        text=True,
    )
    if result.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root and mount rights): {result.stderr.strip()}")
    try:
        yield mount_point
    finally:
        subprocess.run(["umount", "-l", str(mount_point)], check=False)


def _big_state(i: int) -> JointState:
    return JointState(name=[f"j{k}" for k in range(50)], position=[0.001 * i + k for k in range(50)])


def test_writer_on_a_full_disk_raises_once_and_keeps_every_flushed_message(small_disk, tmp_path):
    path = small_disk / "run.mcap"
    writer = RecordingWriter(path, chunk_size=8 * 1024)
    written = 0
    with pytest.raises(RecordingWriteError, match="No space left on device") as raised:
        for i in range(100_000):
            writer.write("/joint_states", _big_state(i), log_time_ns=1_700_000_000_000_000_000 + i * 1000)
            written += 1
    assert "messages flushed before are kept" in str(raised.value) and "--salvage" in str(raised.value)
    summary = writer.close()  # no second error: the failure was raised once
    # The failing write's own message is kept when its chunk got out before the write that failed.
    assert writer.failure is raised.value and 0 < summary.message_count <= written + 1
    data = path.read_bytes()
    assert data.startswith(MAGIC)
    ended = data.endswith(MAGIC)
    # Every flushed message is in the file, and nothing else: salvage (onto another disk) reads them all.
    report = salvage(path, tmp_path / "saved.mcap")
    recovered = [m.message.position[0] for m in read_messages(tmp_path / "saved.mcap")]
    assert recovered == [0.001 * i for i in range(summary.message_count)]
    assert report.message_count == summary.message_count
    assert ended == ("ended after them" in str(raised.value))
    if ended:  # a file ended without its summary reads directly too (scanned record by record)
        assert read_info(path).message_count == summary.message_count
        assert [m.message.position[0] for m in read_messages(path)] == recovered


def test_recorder_on_a_full_disk_one_error_line_exit_1_and_a_salvageable_file(small_disk, tmp_path):
    output = small_disk / "run.mcap"
    process = subprocess.Popen(
        [str(RECORDER), "--ros-args", "-p", f"output:={output}", "-p", "topics:=[/joint_states]"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("full_disk_publisher", context=context)
        publisher = node.create_publisher(JointState, "/joint_states", 100)
        deadline = time.monotonic() + 40.0
        i = 0
        while process.poll() is None and time.monotonic() < deadline:
            publisher.publish(_big_state(i))
            i += 1
            time.sleep(0.002)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    try:
        _, stderr = process.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        _, stderr = process.communicate()
        pytest.fail(f"the recorder did not stop on the full disk: {stderr[-2000:]}")
    assert process.returncode == 1, stderr[-2000:]
    assert "Traceback" not in stderr
    errors = [line for line in stderr.splitlines() if "ERROR" in line]
    assert len(errors) == 1 and "No space left on device" in errors[0], stderr[-2000:]
    report = salvage(output, tmp_path / "saved.mcap")
    assert report.message_count > 0 and report.topic_counts.get("/joint_states", 0) == report.message_count
    # The reserve made room for the ending: the file reads as it is, and the reserve is gone.
    assert output.read_bytes().endswith(MAGIC) and read_info(output).message_count == report.message_count
    assert list(small_disk.iterdir()) == [output]


def test_the_reserve_makes_room_for_the_ending_on_a_disk_filled_to_the_last_block(small_disk):
    from manip_kin.recording.write_failure import ENDING, WholeWrites, end_at_last_flush

    stream = WholeWrites(small_disk / "r.mcap")
    stream.write(MAGIC + b"r" * (4096 - len(MAGIC)))  # ends on a page boundary: the ending needs a new page
    with open(small_disk / "filler", "wb", buffering=0) as filler:  # whatever else fills the disk
        with pytest.raises(OSError):
            while True:
                filler.write(b"f" * 4096)
    with pytest.raises(OSError):
        stream.write(b"x" * 8192)
    assert end_at_last_flush(stream)
    assert (small_disk / "r.mcap").read_bytes() == MAGIC + b"r" * (4096 - len(MAGIC)) + ENDING
    assert not any(path.name.endswith(".reserve") for path in small_disk.iterdir())
