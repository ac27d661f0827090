"""What a recording holds (``manip_kin info``, as ``ros2 bag info``): topics, counts, times, sizes."""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Schema

from manip_kin.recording.chunks import ChunkError, mapped, parse_chunk, walk
from manip_kin.recording.errors import CorruptRecordingError, RecordingError
from manip_kin.recording.files import DECODE_ERRORS, check_complete, recording_files, salvage_hint
from manip_kin.recording.metadata import MCAP_METADATA_KEY, MCAP_METADATA_NAME
from manip_kin.recording.qos import OfferedProfiles, parse_profiles


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

        from manip_kin.recording.summary import format_bytes

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
    try:
        moment = datetime.datetime.fromtimestamp(ns / 1e9, tz=datetime.UTC)
    except (ValueError, OverflowError, OSError):  # a damaged time beyond the calendar
        return f"{ns} ns (not a calendar date)"
    return moment.isoformat(timespec="microseconds").replace("+00:00", "Z")


def _human_time(ns: int) -> str:
    try:
        moment = datetime.datetime.fromtimestamp(ns // 1_000_000_000).astimezone()
    except (ValueError, OverflowError, OSError):
        return f"{ns} ns (not a calendar date)"
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


def _ros_distro(serialized_metadata: str, file_path: Path) -> str:
    """``ros_distro`` of the rosbag2 metadata record ('' when it has none); YAML within the caps."""
    from manip_kin.core.robot_files import parse_yaml
    from manip_kin.errors import ModelFileError

    try:
        document = parse_yaml(serialized_metadata, f"{file_path} rosbag2 metadata record")
    except ModelFileError as error:
        raise CorruptRecordingError(f"{error}; {salvage_hint(file_path)}") from None
    distro = document.get("ros_distro", "") if isinstance(document, dict) else ""
    return distro if isinstance(distro, str) else ""


@dataclass(frozen=True)
class _FileTotals:
    """One file's channels, schemas, message counts per channel id, times and chunk compressions."""

    channels: dict[int, Channel]
    schemas: dict[int, Schema]
    counts: dict[int, int]
    start_ns: int
    end_ns: int
    compressions: list[str]


def _file_totals(reader: SeekingReader, data) -> _FileTotals:
    """From the summary section; a file without one (ended on a full disk) is scanned record by record."""
    summary = reader.get_summary()
    if summary is not None and summary.statistics is not None:
        stats = summary.statistics
        return _FileTotals(
            dict(summary.channels),
            dict(summary.schemas),
            dict(stats.channel_message_counts),
            stats.message_start_time,
            stats.message_end_time,
            [index.compression or "none" for index in summary.chunk_indexes],
        )
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    counts: dict[int, int] = {}
    times: list[int] = []
    compressions: list[str] = []
    for _, opcode, body, records in walk(data):
        if opcode == Opcode.CHUNK:
            compressions.append(parse_chunk(body).compression or "none")
        for record in records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            else:
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                times.append(record.log_time)
    return _FileTotals(channels, schemas, counts, min(times, default=0), max(times, default=0), compressions)


def read_info(path: str | Path) -> RecordingInfo:
    """Summarize a recording from its summary sections (no message is decoded); a file without
    one (ended on a full disk) is scanned record by record.

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
            with mapped(file_path) as stream:
                reader = SeekingReader(stream, record_size_limit=len(stream))
                header = reader.get_header()
                profile, library = header.profile, header.library
                totals = _file_totals(reader, stream)
                for channel_id, channel in totals.channels.items():
                    schema = totals.schemas.get(channel.schema_id)
                    count = totals.counts.get(channel_id, 0)
                    info = _channel_topic_info(channel, schema, count)
                    if channel.topic in topics:
                        previous = topics[channel.topic]
                        info = TopicInfo(**{**previous.__dict__, "message_count": previous.message_count + count})
                    topics[channel.topic] = info
                file_count = sum(totals.counts.values())
                if file_count:
                    start_ns = totals.start_ns if not message_count else min(start_ns, totals.start_ns)
                    end_ns = max(end_ns, totals.end_ns)
                message_count += file_count
                chunk_count += len(totals.compressions)
                compressions.update(totals.compressions)
                for record in reader.iter_metadata():
                    if record.name == MCAP_METADATA_NAME and MCAP_METADATA_KEY in record.metadata:
                        ros_distro = _ros_distro(record.metadata[MCAP_METADATA_KEY], file_path) or ros_distro
        except CorruptRecordingError as error:
            if not isinstance(error, ChunkError):
                raise
            raise CorruptRecordingError(f"{file_path} is damaged ({error}); {salvage_hint(file_path)}") from None
        except DECODE_ERRORS as error:
            raise CorruptRecordingError(
                f"{file_path} is damaged ({type(error).__name__}: {error}); {salvage_hint(file_path)}"
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
