"""``live_view``: the arm live in Foxglove, over the Foxglove WebSocket protocol (foxglove-sdk).

The node subscribes to the pipeline's topics in its namespace (:data:`~manip_kin.viz.live_feed.VIEW_TOPICS`)
and serves them to every connected Foxglove client on ``ws://address:port``, plus ``/tf`` and
``/tf_static`` made from ``joint_states`` and ``robot_description`` where no node publishes TF
(:class:`~manip_kin.viz.live_feed.LiveFeed`, the recorder's synthesis). Messages stay CDR from the
middleware to the socket, with rosbag2's ``ros2msg`` schemas: Foxglove decodes them as it
decodes a recording, and the README's layout (``config/foxglove_layout.json``) applies.

Why an intake thread, as in the recorder: rclpy's executor costs ~0.4 ms per message, and
four 1 kHz streams would take more than a core. The thread drains every subscription every
``INTAKE_PERIOD_S`` with the raw take (:class:`~manip_kin.ros.runtime.polling.RawSubscription`).

Slow clients: foxglove-sdk queues at most ``message_backlog`` messages per client and drops a
slow client's oldest ones (its control messages too: once that queue is full the client is
disconnected). ``Channel.log`` never waits for a socket, so a client that stops reading costs
the node nothing but that bounded queue (measured in ``make bench``).
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from manip_kin.errors import OperationError
from manip_kin.recording.msgdef import full_definition_text
from manip_kin.recording.reader import message_class
from manip_kin.recording.tf_message import TF_STATIC_TOPIC, TF_TOPIC, tf_message_class
from manip_kin.ros.runtime.declared_params import declare_parameters
from manip_kin.ros.runtime.param_struct import param_struct
from manip_kin.ros.runtime.params import ParamSpec
from manip_kin.ros.runtime.polling import RawSubscription, fast_path_problem
from manip_kin.ros.runtime.runner import run_node
from manip_kin.ros.runtime.throttled_log import ThrottledLog
from manip_kin.ros.runtime.usage import usage_text
from manip_kin.ros.wire.diagnostics import diagnostic_array_cdr
from manip_kin.ros.wire.topics import latest_state_qos
from manip_kin.viz.live_feed import DEFAULT_VIEW_RATE_HZ, LIVE_TF_TOPICS, VIEW_TOPICS, Delivery, LiveFeed, ViewTopic

NODE_NAME = "live_view"
INTAKE_PERIOD_S = 0.005
STATUS_PERIOD_S = 1.0
#: Messages a stream subscription holds between two intake passes (5 ms of 1 kHz, with room).
STREAM_QUEUE_DEPTH = 50
EVENT_QUEUE_DEPTH = 100

PARAMETERS = (
    ParamSpec("address", "str", "127.0.0.1", "address the WebSocket server listens on (0.0.0.0: every interface)"),
    ParamSpec(
        "port",
        "int",
        8765,
        "TCP port of the WebSocket server (0: any free port, logged)",
        minimum=0,
        maximum=65535,
    ),
    ParamSpec(
        "rate_hz",
        "float",
        DEFAULT_VIEW_RATE_HZ,
        "highest rate of /tf and of each stream (joint_states, ee_pose, tool_pose, joint_velocity_commands) "
        "sent to clients",
        "Hz",
        minimum=0.1,
        maximum=1e3,  # no viewer draws faster; a tiny rate (1e-300) is refused, not an infinite period
    ),
    ParamSpec("frame_prefix", "str", "", "prefix of the synthesised TF frame ids (as robot_state's frame_prefix)"),
    ParamSpec(
        "message_backlog",
        "int",
        256,
        "messages queued per client; a client that reads slower loses its oldest (about 1 s at the default rates)",
        minimum=1,
        maximum=100_000,  # a bounded queue: at most this many messages held per slow client
    ),
)

#: The parameters as a typed struct (what the node reads).
LiveViewParams = param_struct("LiveViewParams", PARAMETERS, "live_view's parameters, typed (docs/interfaces.md).")

USAGE = usage_text(
    NODE_NAME,
    "Serve the arm live to Foxglove (the Foxglove WebSocket protocol, foxglove-sdk): open Foxglove,\n"
    "Open connection -> Foxglove WebSocket -> ws://127.0.0.1:8765, then import config/foxglove_layout.json.\n"
    "Messages are sent as received (CDR, ros2msg schemas); the streams at most rate_hz. Where no node\n"
    "publishes /tf, /tf and /tf_static are made from joint_states and robot_description. Several\n"
    "clients may connect; a slow one loses its oldest messages, never slows the node.",
    PARAMETERS,
    subscribes=[(t.name, t.type_name, t.delivery.value) for t in VIEW_TOPICS]
    + [("/tf, /tf_static", "tf2_msgs/TFMessage", "forwarded when a node publishes them (needs tf2_msgs)")],
    publishes=[
        ("ws://address:port", "Foxglove WebSocket", "a channel per topic above, plus /tf and /tf_static"),
        ("/diagnostics", "diagnostic_msgs/DiagnosticArray", "address, port, clients, messages sent, TF source"),
    ],
    example=f"{NODE_NAME} --ros-args -p port:=8765 -p rate_hz:=30",
)


@dataclass
class _Intake:
    """A subscribed topic: its resolved name, the view entry, the raw subscription."""

    topic: str
    view: ViewTopic
    subscription: RawSubscription


def _qos(view: ViewTopic) -> QoSProfile:
    if view.delivery is Delivery.STREAM:
        return latest_state_qos(STREAM_QUEUE_DEPTH)  # best effort: no resends of stale states
    latched = view.delivery is Delivery.LATCHED
    return QoSProfile(
        depth=1 if latched else EVENT_QUEUE_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class _SubscribeListener:
    """foxglove-sdk's server listener: notes which latched channels a client just subscribed to."""

    def __init__(self, latched_ids: dict[int, str]):
        self._latched_ids = latched_ids
        self.pending: set[str] = set()
        self.lock = threading.Lock()
        self._subscriptions: dict[int, set[int]] = {}  # client id -> channel ids

    def on_subscribe(self, client, channel) -> None:  # noqa: D102 - foxglove-sdk API
        with self.lock:
            self._subscriptions.setdefault(client.id, set()).add(channel.id)
            if channel.id in self._latched_ids:
                self.pending.add(self._latched_ids[channel.id])

    def on_unsubscribe(self, client, channel) -> None:  # noqa: D102 - foxglove-sdk API
        with self.lock:
            channels = self._subscriptions.get(client.id, set())
            channels.discard(channel.id)
            if not channels:
                self._subscriptions.pop(client.id, None)

    def subscribed_clients(self) -> int:
        """Clients subscribed to at least one channel (a disconnect unsubscribes them all)."""
        with self.lock:
            return len(self._subscriptions)


class LiveViewNode(Node):
    """The ``live_view`` node: see the module docstring and ``live_view --help``."""

    def __init__(self, **node_kwargs) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        import foxglove

        params = declare_parameters(self, LiveViewParams)
        self._feed = LiveFeed(params.rate_hz, params.frame_prefix)
        self._problems = ThrottledLog(self.get_logger().warning, 5.0)
        self._lock = threading.Lock()  # the feed: intake thread vs. executor (status, live TF)
        self._foxglove_context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self._latched_ids: dict[int, str] = {}
        self._intakes: list[_Intake] = []
        for view in VIEW_TOPICS:
            self._subscribe(view)
        self._add_channel(TF_TOPIC, "tf2_msgs/msg/TFMessage", latched=False)
        self._add_channel(TF_STATIC_TOPIC, "tf2_msgs/msg/TFMessage", latched=True)
        self._listener = _SubscribeListener(self._latched_ids)
        self.address = params.address
        try:
            self._server = foxglove.start_server(
                name=f"manip_kin {self.get_fully_qualified_name()}",
                host=self.address,
                port=params.port,
                context=self._foxglove_context,
                server_listener=self._listener,
                message_backlog_size=params.message_backlog,
            )
        except Exception as error:  # noqa: BLE001 - the SDK raises its own error types
            raise OperationError(f"cannot serve on {self.address}:{params.port}: {error}") from None
        self.port = int(self._server.port)
        self._sent = 0
        self._tf_failures_logged = 0
        self._tf_class = tf_message_class()
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(STATUS_PERIOD_S, self._on_status)
        self._stopping = threading.Event()
        self._intake_thread = threading.Thread(target=self._intake_loop, name="live_view_intake", daemon=True)
        self._intake_thread.start()
        problem = fast_path_problem()
        intake = "raw takes in the intake thread" if not problem else f"public rclpy API ({problem})"
        self.get_logger().info(
            f"serving ws://{self.address}:{self.port} (Foxglove WebSocket), streams and /tf at most "
            f"{params.rate_hz:g} Hz; intake: {intake}"
        )

    # -- set-up ------------------------------------------------------------------------------

    def _add_channel(self, topic: str, type_name: str, latched: bool) -> None:
        import foxglove

        schema = foxglove.Schema(name=type_name, encoding="ros2msg", data=full_definition_text(type_name).encode())
        channel = foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self._foxglove_context)
        self._channels[topic] = channel
        if latched:
            self._latched_ids[channel.id()] = topic

    def _subscribe(self, view: ViewTopic, message_type=None) -> None:
        topic = self.resolve_topic_name(view.name)
        message_type = message_type or message_class(view.type_name)
        if topic not in self._channels:
            self._add_channel(topic, view.type_name, latched=view.delivery is Delivery.LATCHED)
        subscription = RawSubscription(self, message_type, topic, _qos(view))
        with self._lock:
            self._intakes.append(_Intake(topic, view, subscription))

    # -- intake (its own thread) -------------------------------------------------------------

    def _intake_loop(self) -> None:
        while not self._stopping.is_set():
            started = time.monotonic()
            try:
                self._drain()
            except Exception as error:  # noqa: BLE001 - one bad message must not end the view
                self._problems("intake", f"live_view: a message was dropped: {type(error).__name__}: {error}")
            time.sleep(max(0.0, INTAKE_PERIOD_S - (time.monotonic() - started)))

    def _drain(self) -> None:
        with self._listener.lock:
            resend, self._listener.pending = self._listener.pending, set()
        with self._lock:
            for topic in resend:
                if (message := self._feed.latched(topic)) is not None:
                    self._send(message)
            intakes = list(self._intakes)
        for intake in intakes:
            while (taken := intake.subscription.take()) is not None:
                data, info = taken
                received = info.get("received_timestamp") or time.time_ns()
                try:
                    with self._lock:
                        out = self._feed.feed(intake.topic, intake.view.type_name, intake.view.delivery, data, received)
                except Exception as error:  # noqa: BLE001 - a malformed message: skip it, keep the rest
                    self._problems(
                        f"feed:{intake.topic}",
                        f"live_view: a {intake.topic} message was not shown: {type(error).__name__}: {error}",
                    )
                    continue
                for message in out:
                    self._send(message)
                if self._feed.tf_failures != self._tf_failures_logged:
                    self._tf_failures_logged = self._feed.tf_failures
                    self._problems("tf", f"live_view: {self._feed.last_tf_failure}")

    def _send(self, message) -> None:
        channel = self._channels.get(message.topic)
        if channel is not None:
            channel.log(message.data, log_time=message.log_time_ns)
            self._sent += 1

    # -- executor ----------------------------------------------------------------------------

    def _on_status(self) -> None:
        self._check_live_tf()
        with self._lock:
            forwarded = dict(self._feed.forwarded)
            thinned = sum(self._feed.thinned.values())
            tf_source = self._feed.tf_source
        values = [
            ("address", self.address),
            ("port", self.port),
            ("subscribed_clients", self._listener.subscribed_clients()),
            ("messages_sent", self._sent),
            ("stream_messages_thinned", thinned),
            ("tf_source", tf_source),
            ("tf_failures", self._feed.tf_failures),
        ] + [(f"sent:{topic}", count) for topic, count in sorted(forwarded.items())]
        self._diagnostics_pub.publish(
            diagnostic_array_cdr(
                self.get_clock().now().nanoseconds,
                self.get_fully_qualified_name().lstrip("/"),
                "ok",
                "serving",
                "live_view",
                values,
            )
        )

    def _check_live_tf(self) -> None:
        """Forward a node's own /tf (and stop synthesising) once one is published and tf2_msgs imports."""
        if self._tf_class is None or self._feed.live_tf:
            return
        if not self.get_publishers_info_by_topic(TF_TOPIC):
            return
        self.get_logger().info("a node publishes /tf: forwarding it, no longer making /tf from joint_states")
        with self._lock:
            self._feed.use_live_tf()
        for view in LIVE_TF_TOPICS:
            self._subscribe(view, self._tf_class)

    def stop(self) -> None:
        """Stop the intake and the server (before the node is destroyed)."""
        if self._stopping.is_set():
            return
        self._stopping.set()
        self._intake_thread.join(timeout=2.0)
        self._server.stop()


def _stop(node: Node) -> None:
    node.stop()  # type: ignore[attr-defined]


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``live_view`` executable."""
    return run_node(LiveViewNode, USAGE, argv, on_shutdown=_stop)


if __name__ == "__main__":
    sys.exit(main())
