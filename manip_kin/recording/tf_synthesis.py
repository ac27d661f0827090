"""``/tf`` and ``/tf_static`` for a recording, from its ``joint_states`` and ``robot_description``.

A recording made where no node publishes TF (``tf2_msgs`` is not on PyPI) would open in
Foxglove without a placed link. :class:`TfSynthesizer` is fed the recorded messages in
order (by the recorder as they arrive, by :func:`add_tf` for an older file) and returns
the TF messages the live ``robot_state`` would have published: the fixed joints once on
``/tf_static`` per description, and the movable joints on ``/tf`` for the joint states
that :class:`~manip_kin.core.tf_tree.StampDecimator` picks at ``rate_hz``, stamped with the
joint state's header stamp and written at its receive time.

Pairing: ``NS/joint_states`` goes with ``NS/robot_description`` (same namespace). A joint
state before any description, names the URDF does not know, and a description that does
not parse are skipped; :meth:`TfSynthesizer.status` says why nothing was synthesised.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from manip_kin.core.tf_tree import LinkTree, StampDecimator, joint_positions, moving_transforms, static_transforms
from manip_kin.errors import ManipKinError
from manip_kin.recording.cdr_measure import header_stamp_ns
from manip_kin.recording.errors import RecordingError
from manip_kin.recording.tf_message import (
    TF_MESSAGE_TYPE,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    encode_tf_message,
    tf_offer,
)

DEFAULT_TF_RATE_HZ = 50.0
JOINT_STATES = "joint_states"
ROBOT_DESCRIPTION = "robot_description"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
STRING_TYPE = "std_msgs/msg/String"
TF_TOPICS = (TF_TOPIC, TF_STATIC_TOPIC)


@dataclass(frozen=True)
class TfOutput:
    """One synthesised message: write ``data`` on ``topic`` at ``log_time_ns`` (publish time ``stamp_ns``)."""

    topic: str
    data: bytes
    log_time_ns: int
    stamp_ns: int


def _namespace_of(topic: str, leaf: str) -> str | None:
    """``/arm`` for ``/arm/joint_states`` (``""`` for ``/joint_states``); None for other topics."""
    if topic == f"/{leaf}":
        return ""
    if topic.endswith(f"/{leaf}"):
        return topic[: -len(leaf) - 1]
    return None


@dataclass
class _Arm:
    tree: LinkTree | None = None
    decimator: StampDecimator | None = None
    joint_states: int = 0
    problem: str = ""
    static_log_time_ns: int = 0  # when its /tf_static was logged: no /tf before it


@dataclass
class TfSynthesizer:
    """Turns recorded joint states into TF messages (see the module docstring).

    Args:
        rate_hz: highest ``/tf`` rate [Hz] (the live ``tf_rate_hz``).
        frame_prefix: prepended to every frame id (the live ``frame_prefix``).
    """

    rate_hz: float = DEFAULT_TF_RATE_HZ
    frame_prefix: str = ""
    tf_count: int = 0
    static_count: int = 0
    _arms: dict[str, _Arm] = field(default_factory=dict)

    def __post_init__(self) -> None:
        StampDecimator(self.rate_hz)  # validates the rate now, not at the first joint state

    def feed(self, topic: str, type_name: str, data: bytes, log_time_ns: int) -> list[TfOutput]:
        """Take one recorded message; return the TF messages it gives (often none)."""
        if type_name == STRING_TYPE and (namespace := _namespace_of(topic, ROBOT_DESCRIPTION)) is not None:
            return self._description(namespace, data, log_time_ns)
        if type_name == JOINT_STATE_TYPE and (namespace := _namespace_of(topic, JOINT_STATES)) is not None:
            return self._joint_state(namespace, data, log_time_ns)
        return []

    def _description(self, namespace: str, data: bytes, log_time_ns: int) -> list[TfOutput]:
        from rclpy.serialization import deserialize_message
        from std_msgs.msg import String

        arm = self._arms.setdefault(namespace, _Arm())
        try:
            arm.tree = LinkTree.from_urdf(deserialize_message(data, String).data, f"{namespace}/{ROBOT_DESCRIPTION}")
        except ManipKinError as error:
            arm.tree, arm.problem = None, f"its robot_description is not a usable URDF ({error})"
            return []
        arm.decimator = StampDecimator(self.rate_hz)
        arm.problem = ""
        arm.static_log_time_ns = log_time_ns
        self.static_count += 1
        data = encode_tf_message(log_time_ns, static_transforms(arm.tree, self.frame_prefix))
        return [TfOutput(TF_STATIC_TOPIC, data, log_time_ns, log_time_ns)]

    def _joint_state(self, namespace: str, data: bytes, log_time_ns: int) -> list[TfOutput]:
        arm = self._arms.setdefault(namespace, _Arm())
        arm.joint_states += 1
        if arm.tree is None or arm.decimator is None:
            return []
        if log_time_ns < arm.static_log_time_ns:
            # Received before the description, taken after it (the recorder drains topic by
            # topic): a /tf logged before its /tf_static would name frames a reader, going by
            # log time, cannot place yet.
            return []
        stamp_ns = header_stamp_ns(data) or log_time_ns
        if not arm.decimator.due(stamp_ns):
            return []
        from rclpy.serialization import deserialize_message
        from sensor_msgs.msg import JointState

        message = deserialize_message(data, JointState)
        positions = joint_positions(message.name, message.position)
        transforms = moving_transforms(arm.tree, positions, self.frame_prefix)
        if not transforms:
            return []
        self.tf_count += 1
        return [TfOutput(TF_TOPIC, encode_tf_message(stamp_ns, transforms), log_time_ns, stamp_ns)]

    def status(self) -> str:
        """One line: what was synthesised, or why nothing was."""
        if self.tf_count:
            return f"/tf synthesised from joint_states ({self.tf_count} messages, {self.static_count} on /tf_static)"
        if not self._arms:
            return "no /tf synthesised: neither robot_description nor joint_states was recorded"
        reasons = []
        for namespace, arm in sorted(self._arms.items()):
            where = f"{namespace}/" if namespace else "/"
            if arm.problem:
                reasons.append(f"{where}: {arm.problem}")
            elif arm.tree is None:
                reasons.append(f"no {where}{ROBOT_DESCRIPTION} was recorded")
            elif not arm.joint_states:
                reasons.append(f"no {where}{JOINT_STATES} was recorded")
            else:
                reasons.append(f"no joint in {where}{JOINT_STATES} is a movable joint of the URDF")
        return "no /tf synthesised: " + "; ".join(reasons)


def add_tf(source: str | Path, output: str | Path, rate_hz: float = DEFAULT_TF_RATE_HZ, frame_prefix: str = ""):
    """Copy a complete recording into ``output`` with ``/tf`` and ``/tf_static`` synthesised.

    A recording that already has ``/tf`` is copied as it is (its TF is the live one).

    Returns:
        ``(summary, status line)``: the :class:`~manip_kin.recording.summary.RecordingSummary`
        of ``output`` and :meth:`TfSynthesizer.status`.

    Raises:
        RecordingError: ``output`` is the source, or the source is unreadable.
    """
    from manip_kin.recording.files import recording_files
    from manip_kin.recording.info import read_info
    from manip_kin.recording.reader import iter_raw_messages
    from manip_kin.recording.writer import RecordingWriter

    source, output = Path(source), Path(output)
    if output.resolve() == source.resolve() or any(output.resolve() == f.resolve() for f in recording_files(source)):
        raise RecordingError(f"output {output} must differ from the recording {source}")
    info = read_info(source)
    has_live_tf = any(t.name == TF_TOPIC for t in info.topics)
    synthesizer = TfSynthesizer(rate_hz, frame_prefix)
    with RecordingWriter(output) as writer:
        for topic in info.topics:
            writer.add_topic(topic.name, topic.type, offered_qos_profiles=topic.offered_qos_profiles)
        for raw in iter_raw_messages(source):
            writer.write_raw(raw.topic, raw.data, raw.log_time_ns, raw.publish_time_ns)
            if has_live_tf:
                continue
            for out in synthesizer.feed(raw.topic, raw.type, raw.data, raw.log_time_ns):
                write_tf(writer, out)
    status = "the recording already has /tf: copied unchanged" if has_live_tf else synthesizer.status()
    return writer.close(), status


def write_tf(writer, out: TfOutput) -> None:
    """Write one synthesised message, registering ``/tf`` or ``/tf_static`` on first use."""
    if not writer.has_topic(out.topic):
        writer.add_topic(out.topic, TF_MESSAGE_TYPE, offered_qos_profiles=tf_offer(out.topic == TF_STATIC_TOPIC))
    writer.write_raw(out.topic, out.data, out.log_time_ns, publish_time_ns=out.stamp_ns)
