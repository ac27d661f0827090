"""The messages of a recording, in receive-time order: serialized (:func:`iter_raw_messages`)
or as rclpy objects (:func:`read_messages`, for plots and analysis)::

    from manip_kin.recording import read_messages
    for topic, msg, log_time_ns, publish_time_ns in read_messages("runs/demo.mcap",
                                                                  topics=["/tool_pose"]):
        ...

``tf2_msgs/msg/TFMessage`` has no Python class on a PyPI-only machine; :func:`read_messages`
then yields it as a :class:`DecodedTfMessage` (decoded by :mod:`.tf_message`).
"""

from __future__ import annotations

import heapq
import importlib
import itertools
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Schema

from manip_kin.recording.chunks import ChunkError, chunk_records, mapped, parse_chunk, record_at, walk
from manip_kin.recording.errors import CorruptRecordingError, MessageDefinitionError
from manip_kin.recording.files import DECODE_ERRORS, check_complete, recording_files, salvage_hint
from manip_kin.recording.msgdef import find_interface_file, normalize_type_name


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

    Chunks are read through :mod:`.chunks` (bounded decompression, CRCs checked).

    Args:
        path: ``.mcap`` file or bag directory.
        topics: only these topics (default: all).
        start_ns: only messages received at or after this time (ns since the epoch).

    Raises:
        CorruptRecordingError: for a garbage, truncated or damaged file.
    """
    wanted = None if topics is None else set(topics)
    for file_path in recording_files(path):
        check_complete(file_path)
        with mapped(file_path) as data:
            try:
                yield from _file_messages(data, wanted, start_ns)
            except DECODE_ERRORS as error:
                if isinstance(error, CorruptRecordingError) and not isinstance(error, ChunkError):
                    raise
                raise CorruptRecordingError(
                    f"{file_path} is damaged ({type(error).__name__}: {error}); {salvage_hint(file_path)}"
                ) from None


class _Messages:
    """Turns records into RawMessages: remembers schemas and channels, keeps the wanted topics."""

    def __init__(self, schemas: dict, channels: dict, wanted: set[str] | None, earliest: int):
        self.schemas, self.channels, self.wanted, self.earliest = schemas, channels, wanted, earliest

    def take(self, records: list) -> Iterator[RawMessage]:
        for record in records:
            if isinstance(record, Schema):
                self.schemas.setdefault(record.id, record)
            elif isinstance(record, Channel):
                self.channels.setdefault(record.id, record)
            elif record.log_time >= self.earliest:
                channel = self.channels.get(record.channel_id)
                if channel is None or (self.wanted is not None and channel.topic not in self.wanted):
                    continue
                schema = self.schemas.get(channel.schema_id)
                name = schema.name if schema is not None else ""
                yield RawMessage(channel.topic, name, record.data, record.log_time, record.publish_time)


def _file_messages(data, wanted: set[str] | None, start_ns: int | None) -> Iterator[RawMessage]:
    """The messages of one mapped file in log-time order, merged across chunks by their index.

    A file without a summary section (ended on a full disk) is read in one pass and sorted.
    """
    summary = SeekingReader(data, record_size_limit=len(data)).get_summary()
    earliest = start_ns if start_ns is not None else -1
    if summary is None or not summary.chunk_indexes:
        decode = _Messages({}, {}, wanted, earliest)
        found = [raw for _, _, _, records in walk(data) for raw in decode.take(records)]
        yield from sorted(found, key=lambda raw: raw.log_time_ns)  # stable: file order within a time
        return
    decode = _Messages(dict(summary.schemas), dict(summary.channels), wanted, earliest)
    indexes = sorted(
        (index for index in summary.chunk_indexes if index.message_end_time >= earliest),
        key=lambda index: (index.message_start_time, index.chunk_start_offset),
    )
    pending: list[tuple[int, int, RawMessage]] = []  # a heap: messages read, not yet yielded
    order = itertools.count()
    for index in indexes:
        while pending and pending[0][0] < index.message_start_time:
            yield heapq.heappop(pending)[2]
        opcode, body, _ = record_at(data, index.chunk_start_offset)
        if opcode != Opcode.CHUNK:
            raise ChunkError(f"the chunk index points at byte {index.chunk_start_offset}, which is no chunk")
        for raw in decode.take(chunk_records(parse_chunk(body))):
            heapq.heappush(pending, (raw.log_time_ns, next(order), raw))
    while pending:
        yield heapq.heappop(pending)[2]


def message_class(type_name: str) -> type:
    """The rclpy class of ``pkg/msg/Type`` (imported from ``pkg.msg``).

    Only an installed interface package is imported: one with ``share/<pkg>/msg/<Type>.msg``
    under the install prefixes (:func:`~manip_kin.recording.msgdef.find_interface_file`).
    A type name read from a recording never makes Python import a module that is not one
    (a schema named ``this/msg/Thing`` imports nothing).

    Raises:
        MessageDefinitionError: when the package or type is not installed.
    """
    package, _, name = normalize_type_name(type_name).partition("/msg/")
    find_interface_file(type_name)  # the allow-list: installed interface definitions
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

    classes: dict[str, Any] = {}
    for raw in iter_raw_messages(path, topics):
        cls = classes.get(raw.type)
        if cls is None:
            try:
                cls = classes[raw.type] = _reader_for(raw.type)
            except MessageDefinitionError as error:
                raise MessageDefinitionError(f"{path}: topic {raw.topic}: {error}") from None
        try:
            message = cls(raw.data) if cls is DecodedTfMessage.from_cdr else deserialize_message(raw.data, cls)
        except Exception as error:  # rclpy raises a bare RuntimeError-like _rclpy error
            raise CorruptRecordingError(
                f"{path}: a {raw.type} message on {raw.topic} at {raw.log_time_ns} ns does not deserialize ({error})"
            ) from None
        yield RecordedMessage(raw.topic, message, raw.log_time_ns, raw.publish_time_ns)


@dataclass(frozen=True)
class DecodedTfMessage:
    """A ``tf2_msgs/msg/TFMessage`` read where the package is not installed.

    Attributes:
        transforms: ``(stamp_ns, LinkTransform)`` pairs (see :mod:`manip_kin.core.tf_tree`).
    """

    transforms: tuple

    @staticmethod
    def from_cdr(data: bytes) -> DecodedTfMessage:
        """Decode CDR bytes (raises ValueError or struct.error when they are not a TFMessage)."""
        from manip_kin.recording.tf_message import decode_tf_message

        return DecodedTfMessage(tuple(decode_tf_message(data)))


def _reader_for(type_name: str):
    """The rclpy class of a type, or the TFMessage decoder where tf2_msgs is missing."""
    from manip_kin.recording.tf_message import TF_MESSAGE_TYPE

    try:
        return message_class(type_name)
    except MessageDefinitionError:
        if normalize_type_name(type_name) == TF_MESSAGE_TYPE:
            return DecodedTfMessage.from_cdr
        raise
