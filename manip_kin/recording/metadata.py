"""rosbag2 ``BagMetadata`` (version 9): the ``metadata.yaml`` of a bag directory and the
``rosbag2``/``serialized_metadata`` record inside the MCAP file.

Field order and layout follow rosbag2 Jazzy (``rosbag2_storage/yaml.hpp``). MCAP
chunk compression is a storage setting, not rosbag2 compression, so
``compression_format`` and ``compression_mode`` stay empty as they do for
``ros2 bag record --storage-preset-profile zstd_fast``; a reader that saw
``zstd`` there would try to decompress whole files or messages.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

from manip_kin.recording.qos import OfferedProfiles, yaml_text

BAG_METADATA_VERSION = 9
STORAGE_IDENTIFIER = "mcap"
METADATA_FILENAME = "metadata.yaml"
MCAP_METADATA_NAME = "rosbag2"
MCAP_METADATA_KEY = "serialized_metadata"


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a recording.

    Attributes:
        name: topic name.
        type: ``pkg/msg/Type``.
        message_count: messages recorded.
        offered_qos_profiles: profiles of the publishers it was recorded from.
        type_hash: ``RIHS01_...`` (may be empty when unknown).
        serialization_format: ``cdr``.
    """

    name: str
    type: str
    message_count: int
    offered_qos_profiles: OfferedProfiles
    type_hash: str = ""
    serialization_format: str = "cdr"


def ros_distro() -> str:
    """The ROS distribution recorded in metadata: ``$ROS_DISTRO``, else ``jazzy`` (our wheels)."""
    return os.environ.get("ROS_DISTRO", "jazzy")


def bag_metadata(
    topics: Sequence[TopicSummary],
    relative_file_paths: Sequence[str],
    starting_time_ns: int,
    duration_ns: int,
) -> dict:
    """The BagMetadata mapping, keys in rosbag2's order.

    Args:
        topics: every topic of the recording (also those without messages).
        relative_file_paths: storage files relative to the bag directory.
        starting_time_ns: earliest receive time, ns since the epoch (0 when empty).
        duration_ns: latest minus earliest receive time, ns.
    """
    message_count = sum(t.message_count for t in topics)
    return {
        "version": BAG_METADATA_VERSION,
        "storage_identifier": STORAGE_IDENTIFIER,
        "duration": {"nanoseconds": duration_ns},
        "starting_time": {"nanoseconds_since_epoch": starting_time_ns},
        "message_count": message_count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": t.serialization_format,
                    "offered_qos_profiles": t.offered_qos_profiles.to_list(),
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.message_count,
            }
            for t in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": list(relative_file_paths),
        "files": [
            {
                "path": path,
                "starting_time": {"nanoseconds_since_epoch": starting_time_ns},
                "duration": {"nanoseconds": duration_ns},
                "message_count": message_count,
            }
            for path in relative_file_paths
        ],
        "custom_data": None,
        "ros_distro": ros_distro(),
    }


def serialized_metadata(metadata: dict) -> str:
    """The ``serialized_metadata`` value (the BagMetadata mapping as YAML)."""
    return yaml_text(metadata)


def metadata_yaml(metadata: dict) -> str:
    """The ``metadata.yaml`` text of a bag directory."""
    return yaml_text({"rosbag2_bagfile_information": metadata}) + "\n"
