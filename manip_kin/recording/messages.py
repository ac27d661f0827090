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

import importlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from mcap.reader import SeekingReader

from manip_kin.recording.errors import CorruptRecordingError, MessageDefinitionError
from manip_kin.recording.files import DECODE_ERRORS, check_complete, recording_files, salvage_hint
from manip_kin.recording.msgdef import normalize_type_name


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
            except DECODE_ERRORS as error:
                raise CorruptRecordingError(
                    f"{file_path} is damaged ({type(error).__name__}: {error}); {salvage_hint(file_path)}"
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

    classes: dict[str, Any] = {}
    for raw in iter_raw_messages(path, topics):
        cls = classes.get(raw.type)
        if cls is None:
            cls = classes[raw.type] = _reader_for(raw.type)
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
        transforms: ``(stamp_ns, LinkTransform)`` pairs (see :mod:`manip_kin.tf_tree`).
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
