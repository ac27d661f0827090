"""Recover what a killed recorder left: copy every complete, CRC-valid chunk into a new file
(``manip_kin info --salvage OUT FILE``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Message, Schema

from manip_kin.recording.chunks import chunk_records, mapped, parse_chunk, record_at, top_level_records
from manip_kin.recording.errors import CorruptRecordingError, RecordingError
from manip_kin.recording.files import DECODE_ERRORS, MCAP_MAGIC, recording_files
from manip_kin.recording.qos import parse_profiles


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


def salvage(source: str | Path, output: str | Path, compression: str = "zstd") -> SalvageReport:
    """Copy every complete, CRC-valid chunk of a (possibly truncated or damaged) recording into a new file.

    Reads records front to back. After a record that is cut off or damaged it resynchronises
    on the next chunk that parses, decompresses (within :mod:`.chunks`' bounds) and matches
    its CRC, so the chunks after a damaged one are recovered too; the partially written
    tail of a killed recorder is dropped. Channels and schemas come from the records read
    and, when the file's summary is readable, from the summary as well (a chunk after the
    damage may use a channel first defined in the damaged one).

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
    with mapped(path) as data:
        schemas, channels = _summary_definitions(data)
        offset, reached_footer, damaged = len(MCAP_MAGIC), False, []
        while offset < len(data) and not reached_footer:
            try:
                opcode, body, next_offset = record_at(data, offset)
                records = top_level_records(opcode, body)
            except DECODE_ERRORS as error:
                detail = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
                resume = next_valid_chunk(data, offset + 1)
                damaged.append(f"byte {offset}: {detail}")
                if resume is None:
                    break
                offset = resume
                continue
            for item in records:
                if isinstance(item, Schema):
                    schemas[item.id] = item
                elif isinstance(item, Channel):
                    channels[item.id] = item
                elif isinstance(item, Message):
                    _copy_message(item, schemas, channels, writer)
            report.bytes_read += next_offset - offset
            reached_footer = opcode == Opcode.FOOTER
            offset = next_offset
    if damaged or not reached_footer:
        report.complete = False
        first = f"cut off or damaged record ({damaged[0]})" if damaged else "end of file before the footer"
        more = f"; {len(damaged) - 1} more damaged regions skipped" if len(damaged) > 1 else ""
        report.stop_reason = report.stop_reason or first + more


def next_valid_chunk(data, start: int) -> int | None:
    """Offset of the first chunk record at or after ``start`` that parses and checks out, or None."""
    chunk_opcode = bytes([Opcode.CHUNK])
    position = start
    while (position := data.find(chunk_opcode, position)) >= 0:
        try:
            opcode, body, _ = record_at(data, position)
            chunk_records(parse_chunk(body))
            return position
        except DECODE_ERRORS:
            position += 1
    return None


def _summary_definitions(data) -> tuple[dict[int, Schema], dict[int, Channel]]:
    """Schemas and channels of the file's summary, when it has a readable one; else empty."""
    try:
        summary = SeekingReader(data, record_size_limit=len(data)).get_summary()
    except DECODE_ERRORS:
        return {}, {}
    if summary is None:
        return {}, {}
    return dict(summary.schemas), dict(summary.channels)


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
