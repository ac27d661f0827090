"""Write rosbag2-compatible MCAP recordings (``ros2 bag info/play``, Foxglove, rosbags).

One file per recording. The output is either a single ``.mcap`` file (needs no
``metadata.yaml``) or a bag directory ``NAME/`` holding ``NAME_0.mcap`` and a
``metadata.yaml`` that agrees with it, as ``ros2 bag record -s mcap`` leaves.

Durability: chunks are small and finished at least every ``flush_interval_s``
seconds and handed to the OS, so a SIGKILL loses at most about that much; the
salvage reader (:func:`manip_kin.recording.salvage.salvage`) recovers the rest.
:meth:`RecordingWriter.close` writes the summary and footer that make the
file complete (and the ``rosbag2`` metadata record and ``metadata.yaml``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from manip_kin import __version__
from manip_kin.recording import metadata as bag_metadata
from manip_kin.recording.cdr_measure import header_stamp_ns
from manip_kin.recording.channels import Channels
from manip_kin.recording.errors import RecordingError
from manip_kin.recording.output_layout import resolve_output
from manip_kin.recording.qos import OfferedProfiles
from manip_kin.recording.summary import RecordingSummary
from manip_kin.recording.write_failure import DiskGuard, RecordingWriteError

MCAP_PROFILE = "ros2"
# Bytes: the MCAP writers' default. The flush every DEFAULT_FLUSH_INTERVAL_S ends a chunk anyway
# (what SIGKILL can lose); each chunk keeps an index entry in memory until the summary (a
# 10-minute soak: 3103 chunks at 256 KiB, 1203 at 1 MiB; the recorder grew 4.6 and 4.0 MiB).
DEFAULT_CHUNK_SIZE = 1024 * 1024
DEFAULT_FLUSH_INTERVAL_S = 0.5  # SIGKILL loses at most about this much (plus one write)

_COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
COMPRESSION_CHOICES = tuple(_COMPRESSIONS)


def type_name_of(message_class: type) -> str:
    """``pkg/msg/Type`` of a generated rclpy message class."""
    package = message_class.__module__.split(".")[0]
    return f"{package}/msg/{message_class.__name__}"


class RecordingWriter:
    """A rosbag2-compatible MCAP writer. Not thread-safe: call it from one thread.

    Args:
        output: ``.mcap`` file path, or a bag directory path (see :func:`resolve_output`).
        compression: chunk compression, one of ``zstd`` (default), ``lz4``, ``none``.
        chunk_size: uncompressed bytes after which a chunk is finished.
        flush_interval_s: a chunk is also finished and flushed to the OS when
            this many seconds passed since the last flush (checked on each write
            and by :meth:`flush_if_due`).
        overwrite: replace an existing ``.mcap`` file.

    Raises:
        RecordingError: on an unknown compression or an unusable output path.
    """

    def __init__(
        self,
        output: str | Path,
        *,
        compression: str = "zstd",
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S,
        overwrite: bool = True,
    ):
        if compression not in _COMPRESSIONS:
            raise RecordingError(
                f"compression {compression!r} is not supported; valid: {', '.join(COMPRESSION_CHOICES)}"
            )
        if chunk_size <= 0 or flush_interval_s <= 0:
            raise RecordingError(
                f"chunk_size ({chunk_size}) and flush_interval_s ({flush_interval_s}) must be positive"
            )
        self.layout = resolve_output(output, overwrite=overwrite)
        self.compression = compression
        self._flush_interval_s = flush_interval_s
        self._disk = DiskGuard(self.layout.mcap_path)
        self._file = self._disk.stream
        self._mcap = McapWriter(
            self._file,
            chunk_size=chunk_size,
            compression=_COMPRESSIONS[compression],
        )
        with self._disk.guard():
            self._mcap.start(profile=MCAP_PROFILE, library=f"manip_kin {__version__}; mcap-python")
            self._file.flush()
        self._channels = Channels(self._mcap)
        self._topics = self._channels.topics
        self._message_bytes = 0
        self._start_ns = 0
        self._end_ns = 0
        self._message_count = 0
        self._pending = False
        self._last_flush = time.monotonic()
        self._summary: RecordingSummary | None = None

    # -- topics -----------------------------------------------------------------------------

    @property
    def topics(self) -> dict[str, str]:
        """``{topic: pkg/msg/Type}`` registered so far."""
        return {name: topic.type for name, topic in self._topics.items()}

    def has_topic(self, topic: str) -> bool:
        """True when ``topic`` was registered."""
        return topic in self._topics

    def add_topic(
        self,
        topic: str,
        type_name: str,
        *,
        offered_qos_profiles: OfferedProfiles | None = None,
        type_description_hash: str | None = None,
        schema: tuple[str, str] | None = None,
    ) -> None:
        """Register a topic (a channel, and its type's schema once).

        Args:
            topic: topic name.
            type_name: ``pkg/msg/Type``.
            offered_qos_profiles: QoS of the publishers it is recorded from;
                default: one reliable, volatile, keep-last-10 profile.
            type_description_hash: ``RIHS01_...``; default: the installed type's.
            schema: ``(encoding, text)``; default: ``ros2msg`` text from the
                installed ``.msg`` files, as rosbag2 builds it.

        Raises:
            RecordingError: when the topic was registered with another type.
            MessageDefinitionError: when the type's definition cannot be found.
        """
        self._channels.add(topic, type_name, offered_qos_profiles, type_description_hash, schema)

    # -- messages ---------------------------------------------------------------------------

    def write_raw(
        self,
        topic: str,
        data: bytes,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        source_time_ns: int | None = None,
    ) -> None:
        """Append one serialized (CDR) message.

        Args:
            topic: a registered topic.
            data: the CDR bytes, encapsulation header included, exact length.
            log_time_ns: receive time, ns since the epoch.
            publish_time_ns: ns since the epoch; default: the message's header
                stamp when its type starts with a Header and the stamp is set,
                else ``source_time_ns``, else ``log_time_ns``.
            source_time_ns: when the publisher sent it (DDS source timestamp),
                ns since the epoch, if known.

        Raises:
            RecordingError: for an unregistered topic or a closed writer.
        """
        entry = self._topics.get(topic)
        if entry is None:
            raise RecordingError(f"topic {topic!r} is not registered; registered: {', '.join(self._topics) or 'none'}")
        if self._summary is not None:
            raise RecordingError(f"recording {self.layout.mcap_path} is closed")
        if self._disk.failure is not None:
            raise self._disk.failure
        if publish_time_ns is None:
            stamp = header_stamp_ns(data) if entry.header_first else None
            if stamp is not None:
                publish_time_ns = stamp
            else:
                publish_time_ns = source_time_ns if source_time_ns else log_time_ns
        entry.sequence += 1
        written_before = self._file.flushed_end
        with self._disk.guard(kept_if_written=self._message_count + 1):
            self._mcap.add_message(
                channel_id=entry.channel_id,
                log_time=log_time_ns,
                data=data,
                publish_time=publish_time_ns,
                sequence=entry.sequence,
            )
        entry.message_count += 1
        if self._message_count == 0:
            self._start_ns = self._end_ns = log_time_ns
        else:
            self._start_ns = min(self._start_ns, log_time_ns)
            self._end_ns = max(self._end_ns, log_time_ns)
        self._message_count += 1
        if self._file.flushed_end != written_before:  # a full chunk, this message included, went out
            self._disk.kept_messages = self._message_count
        self._message_bytes += len(data)
        self._pending = True
        self.flush_if_due()

    def write(
        self,
        topic: str,
        message: Any,
        log_time_ns: int | None = None,
        publish_time_ns: int | None = None,
    ) -> None:
        """Serialize an rclpy message and append it (registering the topic on first use).

        The CDR from ``serialize_message`` is trimmed to its real length (see :mod:`.cdr`).

        Args:
            topic: topic name.
            message: an rclpy message instance.
            log_time_ns: receive time, ns since the epoch; default now.
            publish_time_ns: as in :meth:`write_raw`.
        """
        from rclpy.serialization import serialize_message

        if topic not in self._topics:
            self.add_topic(topic, type_name_of(type(message)))
        data = self._channels.trimmed(topic, serialize_message(message))
        self.write_raw(
            topic,
            data,
            time.time_ns() if log_time_ns is None else log_time_ns,
            publish_time_ns,
        )

    # -- durability -------------------------------------------------------------------------

    def flush(self) -> None:
        """Finish the current chunk and hand everything written so far to the OS."""
        if self._summary is None and self._disk.failure is None:
            with self._disk.guard(kept_if_written=self._message_count):
                self._mcap.flush()
            self._disk.kept_messages = self._message_count
            self._pending = False
            self._last_flush = time.monotonic()

    def flush_if_due(self) -> None:
        """:meth:`flush` when messages are pending and the flush interval has passed."""
        if self._pending and time.monotonic() - self._last_flush >= self._flush_interval_s:
            self.flush()

    # -- end --------------------------------------------------------------------------------

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._message_count

    def topic_summaries(self) -> list[bag_metadata.TopicSummary]:
        """Per-topic metadata, in registration order."""
        return self._channels.summaries()

    def close(self) -> RecordingSummary:
        """Finish the file (rosbag2 metadata record, summary, footer) and ``metadata.yaml``.

        Calling it again returns the same summary. After a disk failure (raised once, by the
        write or flush that met it) it returns what the file keeps: the flushed messages.

        Raises:
            RecordingWriteError: the disk fails while finishing; the file keeps what was
                flushed before (see :mod:`.write_failure`).
        """
        if self._summary is not None:
            return self._summary
        if self._disk.failure is not None:
            return self._kept_summary()
        try:
            return self._complete()
        except OSError as error:
            failure = self._disk.fail(error)
            self._kept_summary()
            raise failure from None

    def _complete(self) -> RecordingSummary:
        relative_path = self.layout.mcap_path.name
        metadata = bag_metadata.bag_metadata(
            self.topic_summaries(),
            [relative_path],
            self._start_ns,
            self._end_ns - self._start_ns,
        )
        self._mcap.flush()
        self._mcap.add_metadata(
            bag_metadata.MCAP_METADATA_NAME,
            {bag_metadata.MCAP_METADATA_KEY: bag_metadata.serialized_metadata(metadata)},
        )
        self._mcap.finish()
        self._file.close()
        self._disk.kept_messages = self._message_count
        if self.layout.bag_directory is not None:
            try:
                (self.layout.bag_directory / bag_metadata.METADATA_FILENAME).write_text(
                    bag_metadata.metadata_yaml(metadata), encoding="utf-8"
                )
            except OSError as error:  # the .mcap is complete: readers find it without metadata.yaml
                self._disk.failure = RecordingWriteError(
                    f"writing {self.layout.bag_directory / bag_metadata.METADATA_FILENAME} failed: "
                    f"{error.strerror or error}; {self.layout.mcap_path} is complete"
                )
                raise self._disk.failure from None
        return self._kept_summary()

    # -- a failing disk ------------------------------------------------------------------------

    @property
    def failure(self) -> RecordingWriteError | None:
        """The disk failure that ended the recording, or None."""
        return self._disk.failure

    def _kept_summary(self) -> RecordingSummary:
        """The summary of what the file keeps: every message once complete, the flushed ones after a failure."""
        self._summary = RecordingSummary(
            path=self.layout.bag_directory or self.layout.mcap_path,
            mcap_path=self.layout.mcap_path,
            topic_counts={t.name: t.message_count for t in self._topics.values()},
            message_count=self._disk.kept_messages,
            message_bytes=self._message_bytes,
            file_bytes=self.layout.mcap_path.stat().st_size if self.layout.mcap_path.exists() else 0,
            start_ns=self._start_ns,
            end_ns=self._end_ns,
        )
        return self._summary

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
