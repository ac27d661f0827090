"""``recorder``: record topics to a rosbag2-compatible MCAP file.

Subscribes to each wanted topic once a publisher of it appears (the graph is
polled, so topics may come up later), with the publishers' reliability and
durability (transient-local topics such as ``/robot_description`` deliver
their latched message) and a deep queue. Messages stay serialized (raw CDR).
Ctrl-C, SIGTERM, ``duration`` or ``max_messages`` end it with a complete file
and a one-line summary.

Why an intake thread instead of subscription callbacks: the rclpy executor
rebuilds its wait set for every message, which measured ~400 µs per message
here (40% of a core for 1 kHz of joint states alone). The intake thread
instead drains every subscription's queue every few milliseconds; each message
costs a take (~2 µs) and a write (~8 µs). The receive time recorded is the
middleware's reception timestamp, so the polling delay does not show in the
file's timing. The subscriptions are :class:`~manip_kin.ros.runtime.polling.RawSubscription` s:
the one module that touches rclpy internals, with a public-API fallback.

TF: unless a node publishes ``/tf`` (then it is recorded as it is), the recorder writes
``/tf`` and ``/tf_static`` itself from the recorded ``joint_states`` and
``robot_description`` (:mod:`manip_kin.recording.tf_synthesis`).

Drops: DDS reports samples it knows it lost (message-lost events), and each
sample carries its publisher's sequence number, so on a topic with a single
publisher a gap in the numbers is a message that never reached the file (for
instance overwritten in a full queue). Both are counted and reported.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

from rclpy.node import Node

from manip_kin.recording.errors import RecordingError
from manip_kin.recording.reader import message_class
from manip_kin.recording.tf_synthesis import TF_TOPICS, TfSynthesizer, write_tf
from manip_kin.recording.write_failure import RecordingWriteError
from manip_kin.recording.writer import RecordingWriter
from manip_kin.ros.nodes.recorder_config import NODE_NAME, USAGE, read_config
from manip_kin.ros.nodes.recorder_topics import (
    RecordedTopic,
    channel_offer,
    manip_kin_type,
    presubscription_matches,
    presubscription_qos,
    requested_qos,
)
from manip_kin.ros.runtime.polling import RawSubscription, fast_path_problem
from manip_kin.ros.runtime.runner import run_node

DISCOVERY_PERIOD_S = 0.5
FLUSH_CHECK_PERIOD_S = 0.25
INTAKE_PERIOD_S = 0.005
LOST_CHECK_PERIOD_S = 0.5


class RecorderNode(Node):
    """The ``recorder`` node: see the module docstring and ``recorder --help``."""

    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        config = read_config(self)
        topics = config.topics
        self._all_topics = config.all_topics
        self._duration_s = config.duration_s
        self._max_messages = config.max_messages
        output, compression = config.output, config.compression
        tf_rate_hz, frame_prefix = config.tf_rate_hz, config.frame_prefix
        self._wanted = {self.resolve_topic_name(t) for t in topics}
        # TF from the recorded joint states, unless /tf is not wanted or a live /tf is recorded (_discover).
        wants_tf = self._all_topics or "/tf" in self._wanted
        self._tf: TfSynthesizer | None = TfSynthesizer(tf_rate_hz, frame_prefix) if wants_tf else None
        self._tf_note = "" if wants_tf else "no /tf synthesised: /tf is not among the topics"
        if output.endswith(".mcap") and Path(output).is_file():
            self.get_logger().warning(f"overwriting the existing recording {output}")
        self._writer = RecordingWriter(output, compression=compression)
        # The writer is shared by the intake thread and the executor thread (discovery, flush).
        self._lock = threading.Lock()
        self._topics: dict[str, RecordedTopic] = {}
        self._skipped: set[str] = set()
        self._stopping = threading.Event()
        self._finished_line: str | None = None
        self._stop_reason = ""
        self._write_error: RecordingWriteError | None = None
        self._intake: threading.Thread | None = None
        try:
            self._start(compression)
        except Exception:
            # A stop signal shuts the context down at any moment, this start included ("context
            # is invalid" from the first discovery or a timer): the node is made all the same,
            # and finish() completes the file as on any stop.
            if self.context.ok():
                raise

    def _start(self, compression: str) -> None:
        """Subscriptions, discovery, timers and the intake thread."""
        if not self._all_topics:
            for topic in sorted(self._wanted):
                known_type = manip_kin_type(topic)
                if known_type:
                    self._subscribe(topic, [], [known_type])
        self._discover()
        self.create_timer(DISCOVERY_PERIOD_S, self._discover)
        self.create_timer(FLUSH_CHECK_PERIOD_S, self._flush_if_due)
        if self._duration_s > 0:
            self._duration_timer = self.create_timer(self._duration_s, self._on_duration)
        problem = fast_path_problem()
        self.get_logger().info(
            "intake: the intake thread takes messages from the middleware"
            if not problem
            else f"intake: public rclpy API, messages through the executor ({problem})"
        )
        self._intake = threading.Thread(target=self._intake_loop, name="recorder_intake", daemon=True)
        self._intake.start()
        what = "all topics" if self._all_topics else " ".join(sorted(self._wanted))
        self.get_logger().info(f"recording {what} to {self._writer.layout.mcap_path} ({compression})")

    # -- discovery (executor thread) ---------------------------------------------------------

    def _is_wanted(self, topic: str) -> bool:
        if self._all_topics:
            # As rosbag2 --all: hidden topics (a name part starting with "_") are left out.
            return not any(part.startswith("_") for part in topic.split("/"))
        return topic in self._wanted

    def _discover(self) -> None:
        if self._stopping.is_set():
            return
        for topic, types in self.get_topic_names_and_types():
            if topic in self._skipped or not self._is_wanted(topic):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if topic == "/tf" and publishers and self._tf is not None:
                self._tf_note = "live /tf recorded (none synthesised)"
                self.get_logger().info("a node publishes /tf: recording it, no longer synthesising TF")
                with self._lock:
                    self._tf = None
            if topic in self._topics:
                entry = self._topics[topic]
                # Sequence gaps only mean drops while one publisher numbers the messages.
                entry.single_publisher &= len(publishers) <= 1
                if entry.presubscribed and not presubscription_matches(topic, [p.qos_profile for p in publishers]):
                    self._resubscribe(entry, publishers, types)
                continue
            if not publishers:
                continue  # only subscribers so far: the publishers' QoS decides ours
            self._subscribe(topic, publishers, types)

    def _subscribe(self, topic: str, publishers: list, types: list[str]) -> None:
        """Subscribe to ``topic``; with no ``publishers`` yet, as manip_kin's nodes publish it."""
        type_name = publishers[0].topic_type if publishers else types[0]
        if len({p.topic_type for p in publishers}) > 1 or len(types) > 1:
            self.get_logger().warning(
                f"{topic} is published with several types ({', '.join(sorted(set(types)))}); recording {type_name}"
            )
        try:
            message_type = message_class(type_name)
        except RecordingError as error:
            self._skipped.add(topic)
            self.get_logger().warning(f"not recording {topic}: {error}")
            return
        if publishers:
            qos = requested_qos([p.qos_profile for p in publishers])
            with self._lock:
                self._add_channel(topic, type_name, publishers)
        else:  # the channel is added with the first message, when the publisher is known
            qos = presubscription_qos(topic)
        intake = RawSubscription(self, message_type, topic, qos)
        entry = RecordedTopic(
            topic,
            type_name,
            message_type,
            intake,
            single_publisher=len(publishers) <= 1,
            presubscribed=not publishers,
        )
        with self._lock:
            self._topics[topic] = entry
        self.get_logger().info(f"recording {topic} ({type_name}, {len(publishers)} publisher(s))")

    def _add_channel(self, topic: str, type_name: str, publishers: list) -> None:
        """Register ``topic`` with the writer, with its publishers' QoS and type hash (lock held)."""
        if self._writer.has_topic(topic):
            return
        offered, type_hash = channel_offer(topic, publishers)
        self._writer.add_topic(topic, type_name, offered_qos_profiles=offered, type_description_hash=type_hash)

    def _resubscribe(self, entry: RecordedTopic, publishers: list, types: list[str]) -> None:
        """Replace a pre-subscription by one whose QoS matches the publishers found."""
        with self._lock:
            del self._topics[entry.name]
        entry.intake.destroy(self)
        self._subscribe(entry.name, publishers, types)

    def _flush_if_due(self) -> None:
        with self._lock:
            try:
                self._writer.flush_if_due()
            except RecordingWriteError as error:
                self._on_write_error(error)

    def _on_write_error(self, error: RecordingWriteError) -> None:
        """The disk failed (lock held): one ERROR line, then stop; ``finish`` ends the file."""
        if self._write_error is None:
            self._write_error = error
            self.get_logger().error(str(error))
            self._stop("the recording could not be written")

    def _on_duration(self) -> None:
        self._duration_timer.cancel()
        self._stop(f"duration ({self._duration_s:g} s) reached")

    def _stop(self, reason: str) -> None:
        """End the spin loop; ``finish`` (run by ``run_node``) then completes the file."""
        if not self._stopping.is_set():
            self._stop_reason = reason
            self._stopping.set()
            self.get_logger().info(f"stopping: {reason}")
            self.context.try_shutdown()

    # -- intake (its own thread) -------------------------------------------------------------

    def _intake_loop(self) -> None:
        next_lost_check = time.monotonic()
        while not self._stopping.is_set():
            started = time.monotonic()
            self._drain()
            if started >= next_lost_check:
                self._take_lost_events()
                next_lost_check = started + LOST_CHECK_PERIOD_S
            time.sleep(max(0.0, INTAKE_PERIOD_S - (time.monotonic() - started)))

    def _take_lost_events(self) -> None:
        """Add the middleware's message-lost counts since the last call."""
        with self._lock:
            entries = list(self._topics.values())
        for entry in entries:
            entry.middleware_lost += entry.intake.take_lost()

    def _drain(self, final: bool = False) -> None:
        """Take every queued message of every topic and write it (``final``: see ``RawSubscription.take``)."""
        with self._lock:
            entries = list(self._topics.values())
        for entry in entries:
            while True:
                taken = entry.intake.take(final)
                if taken is None:
                    break
                data, info = taken
                if not self._record(entry, data, info):
                    return

    def _record(self, entry: RecordedTopic, data: bytes, info: dict) -> bool:
        """Write one message; False once the recording must not take more."""
        with self._lock:
            if self._finished_line is not None or (
                self._max_messages and self._writer.message_count >= self._max_messages
            ):
                return False
            received = info.get("received_timestamp") or time.time_ns()
            if self._write_error is not None:
                return False
            try:
                if not self._writer.has_topic(entry.name):
                    self._add_channel(entry.name, entry.type_name, self._publishers_or_none(entry.name) or [])
                self._writer.write_raw(entry.name, data, received, source_time_ns=info.get("source_timestamp") or None)
                if self._tf is not None:
                    self._synthesise_tf(entry, data, received)
            except RecordingWriteError as error:
                self._on_write_error(error)
                return False
            count = self._writer.message_count
        entry.received += 1
        sequence = info.get("publication_sequence_number")
        if sequence:
            entry.sequence_seen(sequence, lambda: self._publishers_or_none(entry.name))
        if self._max_messages and count >= self._max_messages:
            self._stop(f"max_messages ({self._max_messages}) reached")
            return False
        return True

    def _publishers_or_none(self, topic: str) -> list | None:
        """The topic's publishers, or None once the graph is gone (the final drain runs after shutdown)."""
        if not self.context.ok():
            return None
        try:
            return self.get_publishers_info_by_topic(topic)
        except Exception:  # noqa: BLE001 - the context can end between the check and the query
            return None

    def _synthesise_tf(self, entry: RecordedTopic, data: bytes, received: int) -> None:
        """Write the TF this message gives (lock held); a failure stops synthesis, not the recording."""
        try:
            for out in self._tf.feed(entry.name, entry.type_name, data, received):
                write_tf(self._writer, out)
        except RecordingWriteError:
            raise  # the disk, not the synthesis: the recording ends
        except Exception as error:  # noqa: BLE001 - the recording itself must go on
            self._tf_note = f"TF synthesis stopped at a {entry.name} message: {type(error).__name__}: {error}"
            self._tf = None
            self.get_logger().error(self._tf_note)

    # -- end ---------------------------------------------------------------------------------

    @property
    def write_failed(self) -> bool:
        """True when the disk failed: the recording ended early (exit code 1)."""
        return self._write_error is not None

    def dropped_messages(self) -> dict[str, int]:
        """Per topic: messages known lost.

        Both counters see the same losses (a sample the middleware gave up on is also a
        sequence gap), so the larger one is the count.
        """
        return {t.name: max(t.sequence_gaps, t.middleware_lost) for t in self._topics.values()}

    def finish(self) -> str:
        """Stop the intake, take what is still queued, complete the file; return the summary line."""
        if self._finished_line is not None:
            return self._finished_line
        self._stopping.set()
        if self._intake is not None:
            self._intake.join(timeout=5.0)
        self._drain(final=True)  # messages that arrived before the signal are part of the run
        self._take_lost_events()
        for entry in self._topics.values():
            entry.intake.destroy(self)
        with self._lock:
            try:
                summary = self._writer.close()
            except RecordingWriteError as error:
                self._on_write_error(error)
                summary = self._writer.close()  # what the file keeps
            dropped = self.dropped_messages()
            total = sum(dropped.values())
            dropped_text = (
                f"{total} dropped ({', '.join(f'{t}: {n}' for t, n in dropped.items() if n)})" if total else "0 dropped"
            )
            heard = {name for name, entry in self._topics.items() if entry.received}
            missing = [] if self._all_topics else sorted(self._wanted - heard)
            missing = [t for t in missing if t not in TF_TOPICS or not self._tf or not self._tf.tf_count]
            missing_text = f"; never published: {' '.join(missing)}" if missing else ""
            tf_text = self._tf.status() if self._tf is not None else self._tf_note
            self._finished_line = f"{summary.one_line()}; {dropped_text}{missing_text}; {tf_text}"
        return self._finished_line


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``recorder`` executable: exit 1 when the disk failed (the file keeps what was flushed)."""
    failed = []

    def finish(node: RecorderNode) -> None:
        line = node.finish()
        print(f"recorder: {line}", file=sys.stderr, flush=True)
        failed.append(node.write_failed)

    code = run_node(RecorderNode, USAGE, argv, on_shutdown=finish)
    return 1 if code == 0 and any(failed) else code


if __name__ == "__main__":
    sys.exit(main())
