"""The recorder's topics: which QoS it subscribes with, what it writes as offered, and each
recorded topic's counts of messages lost.

A topic is subscribed as rosbag2 does (:func:`requested_qos`: reliable and transient local only
when every publisher offers it, a deep queue); a manip_kin topic is subscribed at start, before
any publisher is seen, as manip_kin's nodes publish it (:func:`presubscription_qos`). A message
lost shows as a gap in its publisher's sequence numbers while one publisher numbers them
(:meth:`RecordedTopic.sequence_seen`), or in the middleware's message-lost events.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from manip_kin.recording.qos import OfferedProfiles, default_offer
from manip_kin.ros.runtime.polling import RawSubscription
from manip_kin.ros.wire.topics import PIPELINE_TOPIC_TYPES

# Every manip_kin topic is subscribed at start, before any publisher is seen, so a one-shot
# message (a goal sent by `manip_kin goal` right after its publisher appears) is not missed
# while discovery catches up. Relative names resolve in the recorder's namespace.
MANIP_KIN_TOPIC_TYPES = PIPELINE_TOPIC_TYPES
LATCHED_TOPICS = frozenset({"robot_description"})
# One-shot commands, which manip_kin's clients publish latched (pipeline.delivery): pre-subscribed
# transient local too. A volatile reader whose side of the match comes late (under load) is
# acknowledged without the sample; a transient-local one then gets it from the writer's history.
ONE_SHOT_TOPICS = frozenset({"goal_pose", "line_target", "joint_trajectory", "collision_objects"})
# Messages the middleware may queue per topic between two intake passes or while a
# chunk is compressed: about 2 s of the 1 kHz joint states.
SUBSCRIPTION_DEPTH = 2000


def manip_kin_type(topic: str) -> str:
    """The type of a manip_kin topic in any namespace (``/left/joint_states``), else ""."""
    if topic in MANIP_KIN_TOPIC_TYPES:
        return MANIP_KIN_TOPIC_TYPES[topic]
    return MANIP_KIN_TOPIC_TYPES.get(_name(topic), "")


def _name(topic: str) -> str:
    """The last part of ``topic``: ``joint_states`` of ``/left/joint_states``."""
    return topic.rsplit("/", 1)[-1]


def _latched(topic: str) -> bool:
    return _name(topic) in LATCHED_TOPICS


def _presubscribed_transient_local(topic: str) -> bool:
    """The description and the one-shot commands."""
    return _latched(topic) or _name(topic) in ONE_SHOT_TOPICS


def requested_qos(publisher_profiles: list[Any]) -> QoSProfile:
    """rosbag2's rule: reliable / transient-local only if every publisher offers it; deep queue."""
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in publisher_profiles)
    transient = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publisher_profiles)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=SUBSCRIPTION_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE,
    )


def presubscription_qos(topic: str) -> QoSProfile:
    """As manip_kin's own publishers offer ``topic``: reliable; transient local for the
    description and the one-shot commands."""
    latched = _latched(topic)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=1 if latched else SUBSCRIPTION_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if _presubscribed_transient_local(topic) else DurabilityPolicy.VOLATILE
        ),
    )


def presubscription_matches(topic: str, publisher_profiles: list[Any]) -> bool:
    """False when a publisher offers less than :func:`presubscription_qos` requests (best effort,
    or volatile where it is transient local): that publisher cannot match the pre-subscription."""
    transient_local = _presubscribed_transient_local(topic)
    return all(
        p.reliability == ReliabilityPolicy.RELIABLE
        and (not transient_local or p.durability == DurabilityPolicy.TRANSIENT_LOCAL)
        for p in publisher_profiles
    )


def channel_offer(topic: str, publishers: list) -> tuple[OfferedProfiles, str | None]:
    """The offered QoS profiles and type hash the recording gives ``topic``: its publishers',
    or what manip_kin's publishers offer once the publisher is gone; None: the local type's hash."""
    if publishers:
        offered = OfferedProfiles.from_rclpy(p.qos_profile for p in publishers)
        type_hash = str(publishers[0].topic_type_hash)
    else:
        latched = _latched(topic)
        offered = default_offer(transient_local=latched, depth=1 if latched else 10)
        type_hash = ""
    # An unset hash (a publisher from before Iron) is not RIHS01: use the local one.
    return offered, type_hash if type_hash.startswith("RIHS01_") else None


@dataclass
class RecordedTopic:
    """A raw subscription handle the executor never sees (the intake thread drains it)."""

    name: str
    type_name: str
    message_type: type
    intake: RawSubscription
    last_sequence: int | None = None
    sequence_gaps: int = 0
    middleware_lost: int = 0
    single_publisher: bool = True
    received: int = 0
    presubscribed: bool = False  # subscribed before any publisher was seen

    def sequence_seen(self, sequence: int, publishers: Callable[[], list | None]) -> None:
        """Count the messages a gap before ``sequence`` (its publisher's number) lost;
        ``publishers()`` gives the topic's publishers (None once the graph is gone)."""
        if self.last_sequence is not None and self.single_publisher and sequence > self.last_sequence + 1:
            # A second publisher that discovery has not reported yet numbers its own
            # messages: ask the graph before calling the gap a loss.
            found = publishers()
            if found is None or len(found) <= 1:
                self.sequence_gaps += sequence - self.last_sequence - 1
            else:
                self.single_publisher = False
        self.last_sequence = sequence  # a restarted publisher counts from 1 again: no gap
