"""Read recordings: what they hold (``info``), their messages, and what a kill left (salvage).

Accepts a single ``.mcap`` file or a rosbag2 bag directory (``metadata.yaml``
plus ``.mcap`` files), written by :mod:`.writer` or by ``ros2 bag record``.

For plotting and analysis, :func:`read_messages` yields every message
deserialized into its rclpy class::

    from manip_kin.recording import read_messages
    for topic, msg, log_time_ns, publish_time_ns in read_messages("runs/demo.mcap",
                                                                  topics=["/tool_pose"]):
        ...

A file without its footer (the writer was killed) is refused with a
:class:`CorruptRecordingError` that points to :func:`salvage`
(``manip_kin info --salvage OUT FILE``), which copies every complete chunk
into a new, complete file.
"""

from __future__ import annotations

import datetime
import importlib
import os
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

import yaml
import zstandard
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from manip_kin.recording.errors import CorruptRecordingError, MessageDefinitionError, RecordingError
from manip_kin.recording.metadata import MCAP_METADATA_KEY, MCAP_METADATA_NAME, METADATA_FILENAME
from manip_kin.recording.msgdef import normalize_type_name
from manip_kin.recording.qos import OfferedProfiles, parse_profiles

MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_AND_MAGIC = 1 + 8 + 8 + 8 + 4 + len(MCAP_MAGIC)  # opcode, length, 2 offsets, crc, magic
# Errors a damaged file can raise from the mcap library, zstd, lz4 or struct decoding.
_DECODE_ERRORS = (
    McapError,
    EOFError,
    ValueError,
    struct.error,
    zlib.error,
    zstandard.ZstdError,
    RuntimeError,
    OSError,
    KeyError,
    IndexError,
    UnicodeDecodeError,
)


def _salvage_hint(path: Path) -> str:
    return f"`manip_kin info --salvage OUT {path}` recovers its readable part"


def recording_files(path: str | Path) -> list[Path]:
    """The MCAP files of a recording: the file itself, or a bag directory's files.

    Raises:
        RecordingError: when the path does not exist or holds no ``.mcap`` file.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file or directory; expected a .mcap file or a bag directory")
    if path.is_file():
        return [path]
    metadata_path = path / METADATA_FILENAME
    if metadata_path.is_file():
        try:
            document = yaml.safe_load(metadata_path.read_text(encoding="utf-8"))
            names = document["rosbag2_bagfile_information"]["relative_file_paths"]
        except (yaml.YAMLError, KeyError, TypeError) as error:
            raise CorruptRecordingError(
                f"{metadata_path}: not a rosbag2 metadata file ({type(error).__name__}: {error})"
            ) from None
        files = [path / Path(name).name for name in names]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise RecordingError(f"{path}: metadata.yaml lists missing files: {', '.join(missing)}")
        if any(f.suffix != ".mcap" for f in files):
            raise RecordingError(f"{path}: only MCAP storage is supported, metadata lists {names}")
        return files
    files = sorted(path.glob("*.mcap"))
    if not files:
        raise RecordingError(f"{path}: a directory without metadata.yaml or .mcap files is not a recording")
    return files


def check_complete(path: Path) -> None:
    """Raise unless ``path`` starts and ends with the MCAP magic (has its footer).

    Raises:
        CorruptRecordingError: naming what is wrong (empty, not MCAP, truncated).
    """
    size = path.stat().st_size
    if size == 0:
        raise CorruptRecordingError(f"{path} is empty (0 bytes): nothing was ever flushed to it")
    with open(path, "rb") as stream:
        head = stream.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise CorruptRecordingError(
                f"{path} is not an MCAP file: it starts with {head[:8]!r}, an MCAP file with {MCAP_MAGIC!r}"
            )
        if size < len(MCAP_MAGIC) + _FOOTER_AND_MAGIC:
            raise CorruptRecordingError(f"{path} is truncated ({size} bytes, no footer); {_salvage_hint(path)}")
        stream.seek(-len(MCAP_MAGIC), os.SEEK_END)
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise CorruptRecordingError(
                f"{path} is truncated: it has no footer (was the recorder killed?); {_salvage_hint(path)}"
            )


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a recording.

    Attributes:
        name, type: topic name and ``pkg/msg/Type``.
        message_count: messages recorded on it.
        serialization_format: ``cdr``.
        offered_qos_profiles: QoS of the publishers it was recorded from.
        type_hash: ``RIHS01_...`` or empty.
    """

    name: str
    type: str
    message_count: int
    serialization_format: str
    offered_qos_profiles: OfferedProfiles
    type_hash: str


@dataclass(frozen=True)
class RecordingInfo:
    """What ``manip_kin info`` prints (as ``ros2 bag info`` does).

    Attributes:
        path: the file or bag directory.
        files: its MCAP files.
        size_bytes: bytes on disk (the directory's, for a bag directory).
        start_ns, end_ns: first and last receive time, ns since the epoch.
        message_count: all messages.
        topics: per topic, in file order.
        compression: chunk compressions used (``zstd``, ``lz4``, ``none``).
        chunk_count: number of chunks.
        ros_distro: from the rosbag2 metadata record, if any.
        profile, library: from the MCAP header.
    """

    path: Path
    files: tuple[Path, ...]
    size_bytes: int
    start_ns: int
    end_ns: int
    message_count: int
    topics: tuple[TopicInfo, ...]
    compression: tuple[str, ...]
    chunk_count: int
    ros_distro: str
    profile: str
    library: str

    @property
    def duration_s(self) -> float:
        """Seconds between the first and last message."""
        return (self.end_ns - self.start_ns) / 1e9 if self.message_count else 0.0

    def topic(self, name: str) -> TopicInfo:
        """The :class:`TopicInfo` of ``name``.

        Raises:
            RecordingError: when the recording has no such topic.
        """
        for topic in self.topics:
            if topic.name == name:
                return topic
        raise RecordingError(
            f"{self.path} has no topic {name!r}; it has {', '.join(t.name for t in self.topics) or 'none'}"
        )

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready mapping (times in ns and ISO 8601 UTC, duration in s)."""
        return {
            "path": str(self.path),
            "files": [str(f) for f in self.files],
            "size_bytes": self.size_bytes,
            "storage_identifier": "mcap",
            "ros_distro": self.ros_distro,
            "duration_s": self.duration_s,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "start_iso": _iso(self.start_ns) if self.message_count else None,
            "end_iso": _iso(self.end_ns) if self.message_count else None,
            "message_count": self.message_count,
            "compression": list(self.compression),
            "chunk_count": self.chunk_count,
            "topics": [
                {
                    "name": t.name,
                    "type": t.type,
                    "count": t.message_count,
                    "serialization_format": t.serialization_format,
                    "type_hash": t.type_hash,
                    "offered_qos_profiles": t.offered_qos_profiles.to_list(),
                }
                for t in self.topics
            ],
        }

    def to_text(self) -> str:
        """The ``ros2 bag info`` layout."""
        pad = 19

        def line(label: str, value: str) -> str:
            return f"{label + ':':<{pad}}{value}"

        from manip_kin.recording.writer import format_bytes

        lines = [
            line("Files", ("\n" + " " * pad).join(str(f) for f in self.files)),
            line("Bag size", format_bytes(self.size_bytes)),
            line("Storage id", "mcap"),
            line("ROS Distro", self.ros_distro or "unknown"),
            line("Duration", f"{self.duration_s:.9f}s"),
            line("Start", _human_time(self.start_ns) if self.message_count else "-"),
            line("End", _human_time(self.end_ns) if self.message_count else "-"),
            line("Messages", str(self.message_count)),
            line("Compression", f"{', '.join(self.compression) or 'none'} (MCAP chunks: {self.chunk_count})"),
        ]
        width = max((len(t.name) for t in self.topics), default=0)
        type_width = max((len(t.type) for t in self.topics), default=0)
        topic_lines = [
            f"Topic: {t.name:<{width}} | Type: {t.type:<{type_width}} | Count: {t.message_count} | "
            f"Serialization Format: {t.serialization_format}"
            for t in self.topics
        ]
        lines.append(line("Topic information", ("\n" + " " * pad).join(topic_lines) or "none"))
        return "\n".join(lines)


def _iso(ns: int) -> str:
    moment = datetime.datetime.fromtimestamp(ns / 1e9, tz=datetime.UTC)
    return moment.isoformat(timespec="microseconds").replace("+00:00", "Z")


def _human_time(ns: int) -> str:
    moment = datetime.datetime.fromtimestamp(ns // 1_000_000_000).astimezone()
    return f"{moment:%b %d %Y %H:%M:%S}.{ns % 1_000_000_000:09d} ({ns // 1_000_000_000}.{ns % 1_000_000_000:09d})"


def _channel_topic_info(channel: Channel, schema: Schema | None, count: int) -> TopicInfo:
    return TopicInfo(
        name=channel.topic,
        type=schema.name if schema is not None else "",
        message_count=count,
        serialization_format=channel.message_encoding,
        offered_qos_profiles=parse_profiles(channel.metadata.get("offered_qos_profiles", "")),
        type_hash=channel.metadata.get("topic_type_hash", ""),
    )


def _size_on_disk(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def read_info(path: str | Path) -> RecordingInfo:
    """Summarize a recording from its summary sections (no message is decoded).

    Raises:
        RecordingError: path missing or not a recording.
        CorruptRecordingError: a file that is garbage or truncated.
    """
    path = Path(path)
    files = recording_files(path)
    topics: dict[str, TopicInfo] = {}
    start_ns, end_ns, message_count, chunk_count = 0, 0, 0, 0
    compressions: set[str] = set()
    ros_distro, profile, library = "", "", ""
    for file_path in files:
        check_complete(file_path)
        try:
            with open(file_path, "rb") as stream:
                reader = SeekingReader(stream, record_size_limit=file_path.stat().st_size)
                header = reader.get_header()
                profile, library = header.profile, header.library
                summary = reader.get_summary()
                if summary is None or summary.statistics is None:
                    raise CorruptRecordingError(f"{file_path} has no summary statistics; {_salvage_hint(file_path)}")
                stats = summary.statistics
                for channel_id, channel in summary.channels.items():
                    schema = summary.schemas.get(channel.schema_id)
                    count = stats.channel_message_counts.get(channel_id, 0)
                    info = _channel_topic_info(channel, schema, count)
                    if channel.topic in topics:
                        previous = topics[channel.topic]
                        info = TopicInfo(**{**previous.__dict__, "message_count": previous.message_count + count})
                    topics[channel.topic] = info
                if stats.message_count:
                    start_ns = (
                        stats.message_start_time if not message_count else min(start_ns, stats.message_start_time)
                    )
                    end_ns = max(end_ns, stats.message_end_time)
                message_count += stats.message_count
                chunk_count += len(summary.chunk_indexes)
                compressions.update(ci.compression or "none" for ci in summary.chunk_indexes)
                for record in reader.iter_metadata():
                    if record.name == MCAP_METADATA_NAME and MCAP_METADATA_KEY in record.metadata:
                        document = yaml.safe_load(record.metadata[MCAP_METADATA_KEY]) or {}
                        ros_distro = str(document.get("ros_distro", "") or ros_distro)
        except CorruptRecordingError:
            raise
        except _DECODE_ERRORS as error:
            raise CorruptRecordingError(
                f"{file_path} is damaged ({type(error).__name__}: {error}); {_salvage_hint(file_path)}"
            ) from None
    return RecordingInfo(
        path=path,
        files=tuple(files),
        size_bytes=_size_on_disk(path),
        start_ns=start_ns,
        end_ns=end_ns,
        message_count=message_count,
        topics=tuple(topics.values()),
        compression=tuple(sorted(compressions)),
        chunk_count=chunk_count,
        ros_distro=ros_distro,
        profile=profile,
        library=library,
    )


class RawMessage(NamedTuple):
    """One recorded message, still serialized.

    Attributes:
        topic: topic name.
        type: ``pkg/msg/Type``.
        data: CDR bytes (encapsulation header included).
        log_time_ns: receive time, ns since the epoch.
        publish_time_ns: header stamp (or receive time), ns since the epoch.
    """

    topic: str
    type: str
    data: bytes
    log_time_ns: int
    publish_time_ns: int


def iter_raw_messages(
    path: str | Path,
    topics: Iterable[str] | None = None,
    start_ns: int | None = None,
) -> Iterator[RawMessage]:
    """Every message of a recording in receive-time order, serialized.

    Args:
        path: ``.mcap`` file or bag directory.
        topics: only these topics (default: all).
        start_ns: only messages received at or after this time (ns since the epoch).

    Raises:
        CorruptRecordingError: for a garbage, truncated or damaged file.
    """
    wanted = None if topics is None else list(topics)
    for file_path in recording_files(path):
        check_complete(file_path)
        with open(file_path, "rb") as stream:
            reader = SeekingReader(stream, validate_crcs=True, record_size_limit=file_path.stat().st_size)
            try:
                for schema, channel, message in reader.iter_messages(
                    topics=wanted, start_time=start_ns, log_time_order=True
                ):
                    yield RawMessage(
                        channel.topic,
                        schema.name if schema is not None else "",
                        message.data,
                        message.log_time,
                        message.publish_time,
                    )
            except _DECODE_ERRORS as error:
                raise CorruptRecordingError(
                    f"{file_path} is damaged ({type(error).__name__}: {error}); {_salvage_hint(file_path)}"
                ) from None


def message_class(type_name: str) -> type:
    """The rclpy class of ``pkg/msg/Type`` (imported from ``pkg.msg``).

    Raises:
        MessageDefinitionError: when the package or type is not installed.
    """
    package, _, name = normalize_type_name(type_name).partition("/msg/")
    try:
        module = importlib.import_module(f"{package}.msg")
        return getattr(module, name)
    except (ImportError, AttributeError):
        raise MessageDefinitionError(
            f"message type {type_name!r} has no Python class here (import {package}.msg.{name} "
            f"failed); install the package that defines it"
        ) from None


class RecordedMessage(NamedTuple):
    """One recorded message, deserialized.

    Attributes:
        topic: topic name.
        message: the rclpy message object.
        log_time_ns: receive time, ns since the epoch.
        publish_time_ns: header stamp when the message has one, else receive time, ns.
    """

    topic: str
    message: Any
    log_time_ns: int
    publish_time_ns: int


def read_messages(path: str | Path, topics: Iterable[str] | None = None) -> Iterator[RecordedMessage]:
    """Read a recording into rclpy messages, in receive-time order (for plots and analysis).

    Args:
        path: ``.mcap`` file or bag directory.
        topics: only these topics (default: all).

    Yields:
        ``(topic, message, log_time_ns, publish_time_ns)`` tuples (:class:`RecordedMessage`).

    Raises:
        CorruptRecordingError: garbage, truncated or damaged file (salvage it first).
        MessageDefinitionError: a type without an installed Python class.
    """
    from rclpy.serialization import deserialize_message

    classes: dict[str, type] = {}
    for raw in iter_raw_messages(path, topics):
        cls = classes.get(raw.type)
        if cls is None:
            cls = classes[raw.type] = message_class(raw.type)
        try:
            message = deserialize_message(raw.data, cls)
        except Exception as error:  # rclpy raises a bare RuntimeError-like _rclpy error
            raise CorruptRecordingError(
                f"{path}: a {raw.type} message on {raw.topic} at {raw.log_time_ns} ns does not deserialize ({error})"
            ) from None
        yield RecordedMessage(raw.topic, message, raw.log_time_ns, raw.publish_time_ns)


# ---------------------------------------------------------------------------------------------
# Salvage


@dataclass
class SalvageReport:
    """What :func:`salvage` recovered.

    Attributes:
        source: the damaged recording.
        output: the complete recording written.
        complete: the source was already complete (everything was copied).
        topic_counts: messages recovered per topic.
        message_count: all messages recovered.
        start_ns, end_ns: first and last receive time recovered (0 when none).
        bytes_read: bytes of the source that held readable records.
        source_bytes: size of the source.
        stop_reason: why reading stopped (empty when it reached the end).
    """

    source: Path
    output: Path
    complete: bool = False
    topic_counts: dict[str, int] = field(default_factory=dict)
    message_count: int = 0
    start_ns: int = 0
    end_ns: int = 0
    bytes_read: int = 0
    source_bytes: int = 0
    stop_reason: str = ""

    def one_line(self) -> str:
        """Summary for the command line."""
        span = (self.end_ns - self.start_ns) / 1e9 if self.message_count else 0.0
        tail = (
            "source was complete"
            if self.complete
            else f"stopped at byte {self.bytes_read} of {self.source_bytes}: {self.stop_reason}"
        )
        return (
            f"salvaged {self.message_count} messages on {len(self.topic_counts)} topics "
            f"({span:.2f} s) from {self.source} into {self.output}; {tail}"
        )

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready mapping."""
        return {
            "source": str(self.source),
            "output": str(self.output),
            "complete": self.complete,
            "message_count": self.message_count,
            "topic_counts": self.topic_counts,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "bytes_read": self.bytes_read,
            "source_bytes": self.source_bytes,
            "stop_reason": self.stop_reason,
        }


class _TrackedStream:
    """A read-only file wrapper that remembers how far it was read."""

    def __init__(self, stream: BinaryIO):
        self._stream = stream
        self.position = 0

    def read(self, size: int = -1) -> bytes:
        data = self._stream.read(size)
        self.position += len(data)
        return data

    def readinto(self, buffer: Any) -> int:
        count = self._stream.readinto(buffer)
        self.position += count or 0
        return count


def salvage(source: str | Path, output: str | Path, compression: str = "zstd") -> SalvageReport:
    """Copy every complete, CRC-valid chunk of a (possibly truncated) recording into a new file.

    Reads records front to back and stops at the first one that is cut off or
    damaged, so what a killed recorder had flushed is recovered and the
    partially written tail is dropped.

    Args:
        source: a ``.mcap`` file or bag directory, complete or not.
        output: where the recovered recording goes (``.mcap`` file or new bag directory).
        compression: chunk compression of the output.

    Raises:
        CorruptRecordingError: when the source is not MCAP at all or nothing is recoverable.
    """
    from manip_kin.recording.writer import RecordingWriter

    source = Path(source)
    files = recording_files(source)
    output = Path(output)
    if any(output.resolve() == f.resolve() for f in files) or output.resolve() == source.resolve():
        raise RecordingError(f"salvage output {output} must differ from the damaged recording {source}")
    for file_path in files[:1]:
        # Refuse before creating the output: a first file that is empty or not MCAP holds nothing.
        _check_salvageable(file_path)
    report = SalvageReport(source=source, output=output, complete=True)
    writer = RecordingWriter(output, compression=compression)
    try:
        for file_path in files:
            _salvage_file(file_path, writer, report)
            if not report.complete:
                break  # later files of a split bag come after the damage
    finally:
        summary = writer.close()
    report.topic_counts = {k: v for k, v in summary.topic_counts.items()}
    report.message_count = summary.message_count
    report.start_ns, report.end_ns = summary.start_ns, summary.end_ns
    if report.message_count == 0 and not report.complete:
        raise CorruptRecordingError(
            f"nothing recoverable in {source}: {report.stop_reason} (an empty recording was written to {output})"
        )
    return report


def _check_salvageable(path: Path) -> None:
    """Raise unless ``path`` is non-empty and starts with the MCAP magic."""
    if path.stat().st_size == 0:
        raise CorruptRecordingError(f"{path} is empty (0 bytes): the writer never flushed anything; nothing to salvage")
    with open(path, "rb") as stream:
        head = stream.read(len(MCAP_MAGIC))
    if head != MCAP_MAGIC:
        raise CorruptRecordingError(
            f"{path} is not an MCAP file: it starts with {head[:8]!r}, an MCAP file with "
            f"{MCAP_MAGIC!r}; nothing to salvage"
        )


def _salvage_file(path: Path, writer: Any, report: SalvageReport) -> None:
    size = path.stat().st_size
    report.source_bytes += size
    try:
        _check_salvageable(path)
    except CorruptRecordingError as error:
        report.complete = False
        report.stop_reason = str(error)
        return
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with open(path, "rb") as raw_stream:
        stream = _TrackedStream(raw_stream)
        reader = StreamReader(stream, emit_chunks=True, record_size_limit=size)
        good_until = 0
        reached_footer = False
        try:
            for record in reader.records:
                records: list[Any]
                if isinstance(record, Chunk):
                    records = breakup_chunk(record, validate_crc=bool(record.uncompressed_crc))
                else:
                    records = [record]
                for item in records:
                    if isinstance(item, Schema):
                        schemas[item.id] = item
                    elif isinstance(item, Channel):
                        channels[item.id] = item
                    elif isinstance(item, Message):
                        _copy_message(item, schemas, channels, writer)
                good_until = stream.position
                if type(record).__name__ == "Footer":
                    reached_footer = True
        except _DECODE_ERRORS as error:
            report.complete = False
            detail = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
            report.stop_reason = f"cut off or damaged record ({detail})"
        else:
            if not reached_footer:
                report.complete = False
                report.stop_reason = "end of file before the footer"
        report.bytes_read += good_until


def _copy_message(message: Message, schemas: dict[int, Schema], channels: dict[int, Channel], writer: Any) -> None:
    channel = channels.get(message.channel_id)
    if channel is None:
        return  # a message whose channel record was lost cannot be typed
    if not writer.has_topic(channel.topic):
        schema = schemas.get(channel.schema_id)
        if schema is None:
            return
        writer.add_topic(
            channel.topic,
            schema.name,
            offered_qos_profiles=parse_profiles(channel.metadata.get("offered_qos_profiles", "")),
            type_description_hash=channel.metadata.get("topic_type_hash", ""),
            schema=(schema.encoding, schema.data.decode("utf-8", errors="replace")),
        )
    writer.write_raw(channel.topic, message.data, message.log_time, message.publish_time)
