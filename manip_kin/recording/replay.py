"""Republish a recording with its recorded timing and QoS (``manip_kin replay``).

Messages go out in receive-time order, each at
``wall_start + (log_time - first_log_time) / rate``, still serialized (no
decode/encode). Publishers offer the QoS the recorded publishers offered
(transient-local stays transient-local, so ``/robot_description`` reaches late
subscribers). With ``clock``, ``/clock`` (rosgraph_msgs/Clock) carries the
recording's time, so nodes with ``use_sim_time`` follow the replay.
"""

from __future__ import annotations

import itertools
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from manip_kin.recording.errors import RecordingError
from manip_kin.recording.info import read_info
from manip_kin.recording.reader import iter_raw_messages, message_class

NS_PER_S = 1_000_000_000
VOLATILE_MIN_DEPTH = 100  # a replay burst must not overwrite unacknowledged reliable samples
CLOCK_PERIOD_S = 0.01  # /clock at 100 Hz while waiting between messages, as rosbag2's default
PROGRESS_PERIOD_S = 0.25
ACK_WAIT_S = 0.3
MATCH_SETTLE_S = 0.25


@dataclass(frozen=True)
class ReplayOptions:
    """How to replay.

    Attributes:
        rate: playback speed factor (2 = twice as fast); > 0.
        loop: start over at the end, until interrupted.
        topics: only these recorded topics (None: all).
        remaps: recorded topic → topic to publish on.
        start_offset_s: skip the first seconds of the recording.
        clock: publish the recording's time on ``/clock``.
        wait_for_subscribers_s: before the first message, wait up to this long
            for every publisher to be matched by a subscriber (discovery takes
            a moment; without it the first messages reach nobody).
        add_tf: also publish ``/tf`` and ``/tf_static`` computed from the replayed joint
            states and robot description (:mod:`.tf_synthesis`); needs ``tf2_msgs``.
    """

    rate: float = 1.0
    loop: bool = False
    topics: Sequence[str] | None = None
    remaps: Mapping[str, str] = field(default_factory=dict)
    start_offset_s: float = 0.0
    clock: bool = False
    wait_for_subscribers_s: float = 1.0
    add_tf: bool = False


@dataclass
class ReplayReport:
    """What a replay did.

    Attributes:
        messages_published: messages sent (all loops).
        topic_counts: per published topic.
        loops: passes over the recording.
        wall_duration_s: from the first to the last message published.
    """

    messages_published: int = 0
    topic_counts: dict[str, int] = field(default_factory=dict)
    loops: int = 0
    wall_duration_s: float = 0.0


def parse_remaps(items: Sequence[str]) -> dict[str, str]:
    """``["/a:=/b", ...]`` → ``{"/a": "/b"}``.

    Raises:
        RecordingError: on an item that is not ``from:=to``.
    """
    remaps = {}
    for item in items:
        source, separator, target = item.partition(":=")
        if not separator or not source or not target:
            raise RecordingError(f"remap {item!r} is not of the form /recorded_topic:=/new_topic")
        remaps[source] = target
    return remaps


class _Progress:
    """A progress line on a stream: rewritten in place on a terminal, one line per second otherwise."""

    def __init__(self, stream: TextIO | None, total_s: float, rate: float):
        self._stream = stream
        self._total_s = total_s
        self._rate = rate
        self._tty = bool(stream is not None and stream.isatty())
        self._last = 0.0
        self._written = False

    def update(self, position_s: float, count: int, force: bool = False) -> None:
        if self._stream is None:
            return
        now = time.monotonic()
        if not force and now - self._last < (PROGRESS_PERIOD_S if self._tty else 1.0):
            return
        self._last = now
        percent = 100.0 * position_s / self._total_s if self._total_s > 0 else 100.0
        text = f"replay: {position_s:7.2f} / {self._total_s:.2f} s ({percent:5.1f}%)  {count} messages  x{self._rate:g}"
        self._stream.write(("\r" + text) if self._tty else (text + "\n"))
        self._stream.flush()
        self._written = True

    def finish(self, position_s: float, count: int) -> None:
        self.update(position_s, count, force=True)
        if self._tty and self._written and self._stream is not None:
            self._stream.write("\n")
            self._stream.flush()


def replay(
    path: str | Path,
    options: ReplayOptions = ReplayOptions(),
    progress: TextIO | None = sys.stderr,
    should_stop: Callable[[], bool] = lambda: False,
) -> ReplayReport:
    """Replay a recording into the ROS graph (starts and shuts down its own rclpy context).

    Args:
        path: ``.mcap`` file or bag directory.
        options: see :class:`ReplayOptions`.
        progress: stream for the progress line (None: silent).
        should_stop: polled between messages; True ends the replay early.

    Raises:
        RecordingError: bad options, or a garbage/truncated recording (nothing is published).
        MessageDefinitionError: a recorded type without an installed Python class.
    """
    if not options.rate > 0:
        raise RecordingError(f"--rate must be > 0, got {options.rate}")
    if options.start_offset_s < 0:
        raise RecordingError(f"--start-offset must be >= 0 s, got {options.start_offset_s}")
    info = read_info(path)  # refuses garbage and truncated files before anything is published
    recorded = {t.name: t for t in info.topics}
    selected = list(recorded) if options.topics is None else list(options.topics)
    unknown = [t for t in selected if t not in recorded]
    unknown += [t for t in options.remaps if t not in recorded]
    if unknown:
        raise RecordingError(
            f"{path} has no topic {', '.join(repr(t) for t in unknown)}; it has {', '.join(recorded) or 'none'}"
        )
    if info.message_count and options.start_offset_s * NS_PER_S > info.end_ns - info.start_ns:
        raise RecordingError(
            f"--start-offset {options.start_offset_s} s is past the end of the recording ({info.duration_s:.3f} s long)"
        )
    if options.topics is None:
        # Everything that can be published here: a type without a Python class (tf2_msgs on a
        # PyPI-only machine) is left out with a note; named in --topics, it is an error.
        without_class = [name for name in selected if not _has_class(recorded[name].type)]
        if without_class and progress is not None:
            kinds = ", ".join(f"{name} ({recorded[name].type})" for name in without_class)
            progress.write(f"replay: not publishing {kinds}: no Python class for the type here\n")
        selected = [name for name in selected if name not in without_class]
    classes = {name: message_class(recorded[name].type) for name in selected}
    tf_class = None
    if options.add_tf:
        from manip_kin.recording.tf_message import tf_message_class

        tf_class = tf_message_class()
        if tf_class is None:
            raise RecordingError(
                "--add-tf publishes /tf live and needs tf2_msgs (a ROS install); here, write a copy "
                f"with TF instead: manip_kin info --add-tf OUT {path}"
            )

    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    # No rclpy signal handlers: Ctrl-C stays a KeyboardInterrupt that ends the loop at once.
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = rclpy.create_node("manip_kin_replay", context=context)
        publishers: dict[str, Any] = {}
        for name in selected:
            offered = recorded[name].offered_qos_profiles
            minimum_depth = 1 if offered.is_transient_local else VOLATILE_MIN_DEPTH
            publishers[name] = node.create_publisher(
                classes[name], options.remaps.get(name, name), offered.replay_profile(minimum_depth)
            )
        on_published = None
        if tf_class is not None:
            on_published = _tf_publisher(node, tf_class, "/tf" in recorded, progress)
        clock_publisher = None
        clock_class = None
        if options.clock:
            clock_class = message_class("rosgraph_msgs/msg/Clock")
            # rclcpp's ClockQoS, which the time source of every node subscribes with.
            clock_publisher = node.create_publisher(
                clock_class, "/clock", QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
            )
        unmatched = _wait_for_subscribers(list(publishers.values()), options.wait_for_subscribers_s, should_stop)
        if unmatched and progress is not None and options.wait_for_subscribers_s > 0:
            progress.write(
                f"replay: no subscriber after {options.wait_for_subscribers_s:g} s on {' '.join(unmatched)}; "
                "publishing anyway\n"
            )
        report = _play(
            path, info, options, selected, publishers, clock_publisher, clock_class, progress, should_stop, on_published
        )
        for publisher in publishers.values():
            # Reliable samples still in flight would be lost if the process exited now. Acks come
            # at the writers' heartbeat (20 ms for `manip_kin replay`, whose process has the
            # client profile; Fast DDS's default 3 s otherwise): the wait stays short.
            publisher.wait_for_all_acked(_duration(ACK_WAIT_S))
        return report
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def _duration(seconds: float) -> Any:
    from rclpy.duration import Duration

    return Duration(nanoseconds=int(seconds * NS_PER_S))


def _wait_for_subscribers(publishers: list[Any], timeout_s: float, should_stop: Callable[[], bool]) -> list[str]:
    """Wait until every publisher is matched; return the topics still without a subscriber."""
    deadline = time.monotonic() + timeout_s
    while not should_stop():
        unmatched = [p.topic_name for p in publishers if p.get_subscription_count() == 0]
        if not unmatched:
            # The writer side matches first; a sample sent before the reader side has matched
            # too arrives only with a later retransmission, hundreds of ms late.
            time.sleep(MATCH_SETTLE_S)
            return []
        if time.monotonic() >= deadline:
            return unmatched
        time.sleep(0.02)
    return []


def _play(
    path: str | Path,
    info: Any,
    options: ReplayOptions,
    selected: list[str],
    publishers: dict[str, Any],
    clock_publisher: Any,
    clock_class: Any,
    progress_stream: TextIO | None,
    should_stop: Callable[[], bool],
    on_published: Callable[[Any], None] | None = None,
) -> ReplayReport:
    report = ReplayReport()
    begin_ns = info.start_ns + int(options.start_offset_s * NS_PER_S)
    total_s = max(0.0, (info.end_ns - begin_ns) / NS_PER_S)
    progress = _Progress(progress_stream, total_s, options.rate)
    first_wall = None
    last_wall = None
    position_s = 0.0

    def publish_clock(bag_time_ns: int) -> None:
        if clock_publisher is not None:
            message = clock_class()
            message.clock.sec, message.clock.nanosec = divmod(bag_time_ns, NS_PER_S)
            clock_publisher.publish(message)

    while True:
        report.loops += 1
        messages = iter_raw_messages(path, selected, start_ns=begin_ns)
        first = next(messages, None)  # opens the file and decodes a chunk: before the clock starts
        if first is None:
            break
        wall_zero = time.monotonic()
        next_clock = wall_zero
        for raw in itertools.chain((first,), messages):
            target = wall_zero + (raw.log_time_ns - begin_ns) / NS_PER_S / options.rate
            while True:
                if should_stop():
                    progress.finish(position_s, report.messages_published)
                    return report
                now = time.monotonic()
                if now >= target:
                    break
                if clock_publisher is not None and now >= next_clock:
                    publish_clock(begin_ns + int((now - wall_zero) * options.rate * NS_PER_S))
                    next_clock = now + CLOCK_PERIOD_S
                progress.update(position_s, report.messages_published)
                time.sleep(min(target - now, CLOCK_PERIOD_S if clock_publisher else 0.05))
            publish_clock(raw.log_time_ns)
            publishers[raw.topic].publish(raw.data)
            if on_published is not None:
                on_published(raw)
            last_wall = time.monotonic()
            if first_wall is None:
                first_wall = last_wall
            published_on = options.remaps.get(raw.topic, raw.topic)
            report.topic_counts[published_on] = report.topic_counts.get(published_on, 0) + 1
            report.messages_published += 1
            position_s = (raw.log_time_ns - begin_ns) / NS_PER_S
            progress.update(position_s, report.messages_published)
        if not options.loop or should_stop() or report.messages_published == 0:
            break
    if first_wall is not None and last_wall is not None:
        report.wall_duration_s = last_wall - first_wall
    progress.finish(position_s, report.messages_published)
    return report


def _has_class(type_name: str) -> bool:
    try:
        message_class(type_name)
    except RecordingError:
        return False
    return True


def _tf_publisher(node: Any, tf_class: type, recorded_tf: bool, progress: TextIO | None):
    """A callback publishing the TF synthesised from each replayed message (None if the file has /tf)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from manip_kin.recording.tf_message import TF_STATIC_TOPIC, TF_TOPIC
    from manip_kin.recording.tf_synthesis import TfSynthesizer

    if recorded_tf:
        if progress is not None:
            progress.write("replay: the recording has /tf; --add-tf adds nothing\n")
        return None
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    publishers = {
        TF_TOPIC: node.create_publisher(tf_class, TF_TOPIC, 100),
        TF_STATIC_TOPIC: node.create_publisher(tf_class, TF_STATIC_TOPIC, latched),
    }
    synthesizer = TfSynthesizer()

    def publish(raw: Any) -> None:
        for out in synthesizer.feed(raw.topic, raw.type, raw.data, raw.log_time_ns):
            publishers[out.topic].publish(out.data)

    return publish
