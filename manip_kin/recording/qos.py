"""QoS profiles as rosbag2 stores them (``offered_qos_profiles``, metadata version 9).

Version 9 writes policies as rmw's lower-case names (``keep_last``,
``reliable``, ``transient_local``, ``automatic``) and durations as
``{sec, nsec}``, infinity being rmw's ``{9223372036, 854775807}``. Older files
(version ≤ 8) used the enum integers; :func:`parse_profiles` reads both.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import yaml

from manip_kin.recording.errors import RecordingError

NS_PER_S = 1_000_000_000


def yaml_text(value: object) -> str:
    """Block-style YAML of ``value``, keys in their order, no trailing newline (any YAML reader takes it)."""
    return yaml.safe_dump(value, sort_keys=False, default_flow_style=False, allow_unicode=True).rstrip("\n")


RMW_DURATION_INFINITE_NS = 2**63 - 1

# Enum integer → rmw name, per rmw/types.h (the integers are those of version ≤ 8 files).
HISTORY_NAMES = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
RELIABILITY_NAMES = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
DURABILITY_NAMES = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
LIVELINESS_NAMES = {
    0: "system_default",
    1: "automatic",
    2: "manual_by_node",
    3: "manual_by_topic",
    4: "unknown",
    5: "best_available",
}


def _time_dict(nanoseconds: int) -> dict[str, int]:
    return {"sec": nanoseconds // NS_PER_S, "nsec": nanoseconds % NS_PER_S}


@dataclass(frozen=True)
class QosProfileRecord:
    """One offered QoS profile, as recorded.

    Durations in nanoseconds; 0 means "unspecified", 2**63-1 "infinite".
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int = 0
    lifespan_ns: int = 0
    liveliness: str = "system_default"
    liveliness_lease_duration_ns: int = 0
    avoid_ros_namespace_conventions: bool = False

    def to_dict(self) -> dict[str, Any]:
        """The mapping rosbag2 writes, keys in its order."""
        return {
            "history": self.history,
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": _time_dict(self.deadline_ns),
            "lifespan": _time_dict(self.lifespan_ns),
            "liveliness": self.liveliness,
            "liveliness_lease_duration": _time_dict(self.liveliness_lease_duration_ns),
            "avoid_ros_namespace_conventions": self.avoid_ros_namespace_conventions,
        }

    @classmethod
    def from_rclpy(cls, profile: Any) -> QosProfileRecord:
        """From an ``rclpy.qos.QoSProfile`` (e.g. ``TopicEndpointInfo.qos_profile``)."""

        def nanoseconds(duration: Any) -> int:
            return int(getattr(duration, "nanoseconds", 0))

        return cls(
            history=HISTORY_NAMES.get(int(profile.history), "unknown"),
            depth=int(profile.depth),
            reliability=RELIABILITY_NAMES.get(int(profile.reliability), "unknown"),
            durability=DURABILITY_NAMES.get(int(profile.durability), "unknown"),
            deadline_ns=nanoseconds(profile.deadline),
            lifespan_ns=nanoseconds(profile.lifespan),
            liveliness=LIVELINESS_NAMES.get(int(profile.liveliness), "unknown"),
            liveliness_lease_duration_ns=nanoseconds(profile.liveliness_lease_duration),
            avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
        )

    def to_rclpy(self, minimum_depth: int = 1) -> Any:
        """An ``rclpy.qos.QoSProfile`` offering the same, for a replay publisher.

        ``unknown``/``system_default`` history (what endpoint discovery reports) becomes
        keep-last; depth is at least ``minimum_depth``. Deadline and liveliness are
        left unspecified: they do not affect delivery and a replay cannot honour them.
        """
        from rclpy.duration import Duration
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        history = HistoryPolicy.KEEP_ALL if self.history == "keep_all" else HistoryPolicy.KEEP_LAST
        reliability = {
            "best_effort": ReliabilityPolicy.BEST_EFFORT,
        }.get(self.reliability, ReliabilityPolicy.RELIABLE)
        durability = {
            "transient_local": DurabilityPolicy.TRANSIENT_LOCAL,
        }.get(self.durability, DurabilityPolicy.VOLATILE)
        profile = QoSProfile(
            history=history,
            depth=max(int(self.depth), minimum_depth),
            reliability=reliability,
            durability=durability,
        )
        if 0 < self.lifespan_ns < RMW_DURATION_INFINITE_NS:
            profile.lifespan = Duration(nanoseconds=self.lifespan_ns)
        return profile


@dataclass(frozen=True)
class OfferedProfiles:
    """The profiles offered by a topic's publishers when it was recorded."""

    profiles: tuple[QosProfileRecord, ...] = field(default_factory=tuple)

    def to_yaml(self) -> str:
        """The ``offered_qos_profiles`` channel metadata string (``YAML::Dump`` layout)."""
        return yaml_text([p.to_dict() for p in self.profiles])

    def to_list(self) -> list[dict[str, Any]]:
        """The list written into ``metadata.yaml`` (version 9 stores it as YAML, not a string)."""
        return [p.to_dict() for p in self.profiles]

    def replay_profile(self, minimum_depth: int = 1) -> Any:
        """The rclpy QoS a replay publisher offers (rosbag2's rule).

        When all recorded publishers agree, their profile; otherwise (or when none
        was recorded) reliable + volatile, which every subscriber can match.
        """
        if not self.profiles:
            return QosProfileRecord().to_rclpy(minimum_depth)
        first = self.profiles[0]
        if all((p.reliability, p.durability) == (first.reliability, first.durability) for p in self.profiles):
            return first.to_rclpy(minimum_depth)
        return QosProfileRecord().to_rclpy(minimum_depth)

    @property
    def is_transient_local(self) -> bool:
        """True when every recorded publisher offered transient-local durability."""
        return bool(self.profiles) and all(p.durability == "transient_local" for p in self.profiles)

    @classmethod
    def from_rclpy(cls, profiles: Iterable[Any]) -> OfferedProfiles:
        """From rclpy QoS profiles."""
        return cls(tuple(QosProfileRecord.from_rclpy(p) for p in profiles))


def _policy(value: Any, names: dict[int, str]) -> str:
    if isinstance(value, bool):
        raise RecordingError(f"QoS policy {value!r} is neither a name nor an rmw enum integer")
    if isinstance(value, int):
        return names.get(value, "unknown")
    text = str(value).strip().lower()
    return text if text in names.values() else "unknown"


def _duration_ns(value: Any) -> int:
    if not isinstance(value, dict):
        return 0
    total = int(value.get("sec", 0)) * NS_PER_S + int(value.get("nsec", 0))
    return min(total, RMW_DURATION_INFINITE_NS)


def parse_profiles(text_or_list: str | Sequence[dict] | None) -> OfferedProfiles:
    """Parse ``offered_qos_profiles`` from a channel (YAML text) or ``metadata.yaml`` (list).

    Raises:
        RecordingError: when the text is not a YAML list of QoS mappings.
    """
    if not text_or_list:
        return OfferedProfiles()
    if isinstance(text_or_list, str):
        from manip_kin.core.robot_files import parse_yaml
        from manip_kin.errors import ModelFileError

        try:  # a recording's text: parsed within the YAML caps (no alias bombs)
            items = parse_yaml(text_or_list, "offered_qos_profiles")
        except ModelFileError as error:
            raise RecordingError(f"offered_qos_profiles is not valid YAML: {error.field}: {error.problem}") from None
    else:
        items = text_or_list
    if not items:
        return OfferedProfiles()
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise RecordingError(f"offered_qos_profiles must be a list of QoS mappings, got {type(items).__name__}")
    try:
        return OfferedProfiles(tuple(_profile(item) for item in items))
    except (TypeError, ValueError, OverflowError, AttributeError) as error:
        raise RecordingError(f"offered_qos_profiles holds a value of the wrong type ({error})") from None


def _profile(item: dict) -> QosProfileRecord:
    return QosProfileRecord(
        history=_policy(item.get("history", 3), HISTORY_NAMES),
        depth=int(item.get("depth", 0)),
        reliability=_policy(item.get("reliability", 3), RELIABILITY_NAMES),
        durability=_policy(item.get("durability", 3), DURABILITY_NAMES),
        deadline_ns=_duration_ns(item.get("deadline")),
        lifespan_ns=_duration_ns(item.get("lifespan")),
        liveliness=_policy(item.get("liveliness", 4), LIVELINESS_NAMES),
        liveliness_lease_duration_ns=_duration_ns(item.get("liveliness_lease_duration")),
        avoid_ros_namespace_conventions=bool(item.get("avoid_ros_namespace_conventions", False)),
    )


def default_offer(transient_local: bool = False, depth: int = 10) -> OfferedProfiles:
    """What an rclpy publisher with ``QoSProfile(depth=...)`` offers (reliable, volatile).

    Used when messages are written without a live publisher to ask.
    """
    return OfferedProfiles(
        (
            QosProfileRecord(
                history="keep_last",
                depth=depth,
                durability="transient_local" if transient_local else "volatile",
            ),
        )
    )
