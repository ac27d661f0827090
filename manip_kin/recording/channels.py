"""The topics of a recording being written: one MCAP channel per topic, one schema per type.

:class:`Channels` registers them on an MCAP writer as rosbag2 does (the ``ros2msg`` schema text,
the offered QoS profiles and the type hash in the channel's metadata), keeps each topic's counts
and the field lists of its type (to find a Header first, and to trim a serialized message to
its real length), and gives the per-topic summary of the bag's metadata.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from mcap.writer import Writer as McapWriter

from manip_kin.recording import metadata as bag_metadata
from manip_kin.recording.cdr_measure import CdrLayout
from manip_kin.recording.errors import RecordingError
from manip_kin.recording.msgdef import (
    definitions_from_schema,
    full_definition_text,
    has_header_first,
    normalize_type_name,
)
from manip_kin.recording.qos import OfferedProfiles, default_offer
from manip_kin.recording.type_hash import type_hash

SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


@dataclass
class Channel:
    """One recorded topic: its MCAP channel, what its metadata says, and its counts."""

    name: str
    type: str
    channel_id: int
    offered: OfferedProfiles
    type_hash: str
    header_first: bool
    message_count: int = 0
    sequence: int = 0


class Channels:
    """The topics registered on one MCAP writer, by name (:attr:`topics`, in registration order)."""

    def __init__(self, mcap: McapWriter):
        self._mcap = mcap
        self._schemas: dict[str, int] = {}
        self._definitions: dict[str, Any] = {}
        self._layouts: dict[str, CdrLayout] = {}
        self.topics: dict[str, Channel] = {}

    def add(
        self,
        topic: str,
        type_name: str,
        offered_qos_profiles: OfferedProfiles | None,
        type_description_hash: str | None,
        schema: tuple[str, str] | None,
    ) -> None:
        """Register ``topic`` (see :meth:`~manip_kin.recording.writer.RecordingWriter.add_topic`)."""
        type_name = normalize_type_name(type_name)
        existing = self.topics.get(topic)
        if existing is not None:
            if existing.type != type_name:
                raise RecordingError(f"topic {topic!r} is recorded as {existing.type}; cannot also record {type_name}")
            return
        if type_name not in self._schemas:
            encoding, text = schema or (SCHEMA_ENCODING, full_definition_text(type_name))
            self._schemas[type_name] = self._mcap.register_schema(
                name=type_name, encoding=encoding, data=text.encode("utf-8")
            )
            if encoding == SCHEMA_ENCODING:
                self._definitions[type_name] = definitions_from_schema(type_name, text)
        offered = offered_qos_profiles if offered_qos_profiles is not None else default_offer()
        hash_text = type_description_hash if type_description_hash is not None else type_hash(type_name)
        channel_id = self._mcap.register_channel(
            topic=topic,
            message_encoding=MESSAGE_ENCODING,
            schema_id=self._schemas[type_name],
            metadata={"offered_qos_profiles": offered.to_yaml(), "topic_type_hash": hash_text},
        )
        definitions = self._definitions.get(type_name)
        self.topics[topic] = Channel(
            name=topic,
            type=type_name,
            channel_id=channel_id,
            offered=offered,
            type_hash=hash_text,
            header_first=bool(definitions) and has_header_first(type_name, definitions),
        )

    def trimmed(self, topic: str, data: bytes) -> bytes:
        """``data`` serialized by rclpy for ``topic``, cut to its real length when the type's
        fields are known (``serialize_message`` may leave padding after the message)."""
        type_name = self.topics[topic].type
        layout = self._layouts.get(type_name)
        if layout is None and type_name in self._definitions:
            layout = self._layouts[type_name] = CdrLayout(self._definitions[type_name])
        return data[: layout.message_length(type_name, data)] if layout is not None else data

    def summaries(self) -> list[bag_metadata.TopicSummary]:
        """Per-topic metadata, in registration order."""
        return [
            bag_metadata.TopicSummary(
                name=t.name,
                type=t.type,
                message_count=t.message_count,
                offered_qos_profiles=t.offered,
                type_hash=t.type_hash,
            )
            for t in self.topics.values()
        ]
