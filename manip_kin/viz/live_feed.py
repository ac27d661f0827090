"""What the live view sends to its Foxglove clients, decided without ROS or sockets.

:class:`LiveFeed` takes the serialized (CDR) messages the ``live_view`` node receives and
returns the messages to send, each still CDR, on a channel named like its ROS topic:

* **streams** (``joint_states``, ``ee_pose``, ``tool_pose``, ``joint_velocity_commands``,
  1 kHz in the pipeline) are thinned to at most ``rate_hz`` by receive time, with the same
  :class:`~manip_kin.core.tf_tree.StampDecimator` rule that picks ``/tf``: a viewer refreshes at
  30-60 Hz, and 1 kHz per client would cost the node and the network for nothing seen;
* **events** (``markers``, ``/diagnostics``, ``goal_pose``, ``planned_path``,
  ``collision_objects``) pass whole: each message can carry something the next one does not
  (another node's status, another marker namespace);
* **latched** ones (``robot_description`` and the synthesised ``/tf_static``) pass and are
  kept, to be sent again when a client subscribes later (:meth:`LiveFeed.latched`), as a
  transient-local topic gives its last message to a late subscriber.

``/tf`` and ``/tf_static`` are made from ``joint_states`` and ``robot_description`` by the
recorder's :class:`~manip_kin.recording.tf_synthesis.TfSynthesizer` (same frames, stamps and
bytes as a recording's), until :meth:`LiveFeed.use_live_tf` says a node publishes ``/tf``;
then the live ``/tf`` topics are forwarded as events instead.

The schemas are the ``ros2msg`` texts rosbag2 writes (:func:`~manip_kin.recording.msgdef.full_definition_text`),
the messages ``cdr``: what Foxglove reads from a recording, so the README's layout works live.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from manip_kin.core.tf_tree import StampDecimator
from manip_kin.recording.tf_message import TF_MESSAGE_TYPE, TF_STATIC_TOPIC, TF_TOPIC
from manip_kin.recording.tf_synthesis import TfSynthesizer

#: Default rate of ``/tf`` and of each stream sent to clients [Hz].
DEFAULT_VIEW_RATE_HZ = 50.0


class Delivery(enum.Enum):
    """How a topic's messages reach the clients (see the module docstring)."""

    STREAM = "stream"
    EVENT = "event"
    LATCHED = "latched"


@dataclass(frozen=True)
class ViewTopic:
    """One ROS topic the live view subscribes to.

    Attributes:
        name: relative name (resolved in the node's namespace), or absolute (``/diagnostics``).
        type_name: ``pkg/msg/Type``.
        delivery: how its messages are sent on.
    """

    name: str
    type_name: str
    delivery: Delivery


#: The topics of a manip_kin pipeline the live view shows (the README layout's and the arm's).
VIEW_TOPICS = (
    ViewTopic("robot_description", "std_msgs/msg/String", Delivery.LATCHED),
    ViewTopic("joint_states", "sensor_msgs/msg/JointState", Delivery.STREAM),
    ViewTopic("ee_pose", "geometry_msgs/msg/PoseStamped", Delivery.STREAM),
    ViewTopic("tool_pose", "geometry_msgs/msg/PoseStamped", Delivery.STREAM),
    ViewTopic("joint_velocity_commands", "std_msgs/msg/Float64MultiArray", Delivery.STREAM),
    ViewTopic("markers", "visualization_msgs/msg/MarkerArray", Delivery.EVENT),
    ViewTopic("collision_objects", "visualization_msgs/msg/MarkerArray", Delivery.EVENT),
    ViewTopic("goal_pose", "geometry_msgs/msg/PoseStamped", Delivery.EVENT),
    ViewTopic("planned_path", "nav_msgs/msg/Path", Delivery.EVENT),
    ViewTopic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", Delivery.EVENT),
)

#: The live TF topics, forwarded once a node publishes ``/tf`` (where tf2_msgs imports).
LIVE_TF_TOPICS = (
    ViewTopic(TF_TOPIC, TF_MESSAGE_TYPE, Delivery.EVENT),
    ViewTopic(TF_STATIC_TOPIC, TF_MESSAGE_TYPE, Delivery.LATCHED),
)


@dataclass(frozen=True)
class Outgoing:
    """One message for the clients: ``data`` (CDR) on channel ``topic``, logged at ``log_time_ns``."""

    topic: str
    data: bytes
    log_time_ns: int


@dataclass
class LiveFeed:
    """Turns received messages into the messages sent to clients (see the module docstring).

    Args:
        rate_hz: highest rate of ``/tf`` and of each stream [Hz], > 0.
        frame_prefix: prefix of the synthesised TF frame ids (robot_state's ``frame_prefix``).

    Attributes:
        forwarded: messages returned so far, by channel topic.
        thinned: stream messages left out by the rate, by topic.
        tf_failures: messages whose TF could not be made (they are still forwarded themselves).
        last_tf_failure: why the last one failed ("" when none did).
    """

    rate_hz: float = DEFAULT_VIEW_RATE_HZ
    frame_prefix: str = ""
    forwarded: dict[str, int] = field(default_factory=dict)
    thinned: dict[str, int] = field(default_factory=dict)
    tf_failures: int = 0
    last_tf_failure: str = ""
    _tf: TfSynthesizer | None = None
    _live_tf: bool = False
    _decimators: dict[str, StampDecimator] = field(default_factory=dict)
    _latched: dict[str, Outgoing] = field(default_factory=dict)

    def __post_init__(self) -> None:
        StampDecimator(self.rate_hz)  # a bad rate fails here, with its value
        self._tf = TfSynthesizer(self.rate_hz, self.frame_prefix)

    @property
    def live_tf(self) -> bool:
        """True once :meth:`use_live_tf` was called."""
        return self._live_tf

    @property
    def tf_source(self) -> str:
        """Where ``/tf`` comes from, in words (for the status)."""
        if self._live_tf:
            return "live /tf forwarded"
        return self._tf.status() if self._tf is not None else "none"

    def use_live_tf(self) -> None:
        """A node publishes ``/tf``: stop synthesising it (the live topics are forwarded from now)."""
        self._live_tf = True
        self._tf = None

    def feed(self, topic: str, type_name: str, delivery: Delivery, data: bytes, received_ns: int) -> list[Outgoing]:
        """Take one received message of ``topic`` (resolved name); return what to send now.

        Args:
            topic: the resolved ROS topic name, also the channel's name.
            type_name: ``pkg/msg/Type``.
            delivery: the topic's :class:`Delivery`.
            data: the CDR bytes as received.
            received_ns: receive time [ns since the epoch].
        """
        out: list[Outgoing] = []
        if delivery is Delivery.STREAM:
            decimator = self._decimators.setdefault(topic, StampDecimator(self.rate_hz))
            if decimator.due(received_ns):
                out.append(Outgoing(topic, data, received_ns))
            else:
                self.thinned[topic] = self.thinned.get(topic, 0) + 1
        else:
            out.append(Outgoing(topic, data, received_ns))
        if self._tf is not None:
            # The synthesiser takes every joint state and picks /tf by stamp at rate_hz itself.
            try:
                made = self._tf.feed(topic, type_name, data, received_ns)
            except Exception as error:  # noqa: BLE001 - a message it cannot read: no TF from it, the rest goes on
                self.tf_failures += 1
                self.last_tf_failure = f"no /tf from a {topic} message: {type(error).__name__}: {error}"
                made = []
            out += [Outgoing(t.topic, t.data, t.log_time_ns) for t in made]
        for message in out:
            self.forwarded[message.topic] = self.forwarded.get(message.topic, 0) + 1
            if (delivery is Delivery.LATCHED and message.topic == topic) or message.topic == TF_STATIC_TOPIC:
                self._latched[message.topic] = message
        return out

    def latched(self, topic: str) -> Outgoing | None:
        """The last message of a latched channel (for a client that subscribes now), or None."""
        return self._latched.get(topic)
