"""Publishing a one-shot message so that it is not lost: every known reader matched, every
reader's acknowledgement, and the recorders of all topics given time to join (see
:meth:`DeliveringClient.publish_delivered`). A mixin of
:class:`~manip_kin.pipeline.client.PipelineClient`, which provides ``node``, ``_executor``,
``_publishers``, ``spin_for`` and ``spin_until``.
"""

from __future__ import annotations

import sys
import time

from manip_kin.pipeline.errors import PipelineError
from manip_kin.pipeline.recorders import ASK_TIMEOUT_S, recorder_nodes, recorders_without, records_a_list

#: Seconds a one-shot message waits for a recorder in the graph to subscribe to its topic: a few
#: of the recorder's discovery periods (0.5 s), for a loaded machine.
RECORDER_JOIN_S = 3.0


class DeliveringClient:
    """Reliable publishers and delivered one-shot messages for a client node."""

    def publisher(self, msg_type, topic: str, latched: bool = False):
        """A reliable publisher on ``topic`` (relative names resolve in the namespace; created once).

        ``latched``: transient local, depth 1, for a one-shot message (a goal, a line target):
        a recorder that subscribes after it went out still gets it. Otherwise volatile, depth 10
        (streams).
        """
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        key = f"{topic}:{msg_type.__name__}:{'latched' if latched else 'volatile'}"
        if key not in self._publishers:
            qos = QoSProfile(
                depth=1 if latched else 10,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
            )
            self._publishers[key] = self.node.create_publisher(msg_type, topic, qos)
        return self._publishers[key]

    def wait_subscribers(
        self, msg_type, topic: str, timeout: float = 10.0, subscribers: int = 1, latched: bool = False
    ):
        """The publisher on ``topic`` (see :meth:`publisher`) once every known subscription (at
        least ``subscribers``) matched it.

        Raises:
            PipelineError: no subscriber within ``timeout``.
        """
        publisher = self.publisher(msg_type, topic, latched)
        matched = self.spin_until(lambda: self._all_matched(publisher, subscribers), timeout)
        if not matched:
            raise PipelineError(
                f"no subscriber on {publisher.topic_name} after {timeout:g} s "
                "(is the node running, same ROS_DOMAIN_ID and namespace?)"
            )
        return publisher

    def _all_matched(self, publisher, subscribers: int = 1) -> bool:
        # Every subscription the graph knows must be matched, not just the first one:
        # with a recorder running, it may match before the controller does.
        known = len(self.node.get_subscriptions_info_by_topic(publisher.topic_name))
        return publisher.get_subscription_count() >= max(subscribers, known)

    def publish_delivered(self, topic: str, msg, timeout: float = 10.0, subscribers: int = 1) -> int:
        """Publish ``msg`` (latched, see :meth:`publisher`) once every known subscriber is
        matched, and wait until every reader has acknowledged it, recorders included.

        A recorder of all topics (``recorder -p all_topics:=true``, ``ros2 bag record -a``)
        subscribes only once it discovers this client's publisher, often after the message
        went out: it gets the message from the latched publisher, so this waits, at most
        :data:`RECORDER_JOIN_S` (and ``timeout``), for each recorder in the graph that may
        record this topic to subscribe and acknowledge (:mod:`manip_kin.pipeline.recorders`).

        Returns:
            The number of matched subscriptions.

        Raises:
            PipelineError: no subscriber within ``timeout`` or no acknowledgement.
        """
        publisher = self.wait_subscribers(type(msg), topic, timeout, subscribers, latched=True)
        # Discovery is two-sided: give the subscriber's side a moment to match our writer too,
        # or a reliable sample can be sent before the reader accepts it.
        self.spin_for(0.05)
        publisher.publish(msg)
        deadline = time.monotonic() + timeout
        self._wait_acknowledged(publisher, deadline, timeout)
        join_deadline = min(deadline, time.monotonic() + RECORDER_JOIN_S)
        recorders = recorders_without(self.node, publisher.topic_name, self._possible_recorders())
        while recorders and time.monotonic() < join_deadline:
            self._executor.spin_once(timeout_sec=0.02)
            recorders = recorders_without(self.node, publisher.topic_name, recorders)
        if recorders:
            names = ", ".join(f"{ns.rstrip('/')}/{name}" for name, ns in sorted(recorders))
            print(
                f"warning: {names} did not subscribe to {publisher.topic_name} within {RECORDER_JOIN_S:g} s: "
                "its recording may lack this message",
                file=sys.stderr,
            )
        self.spin_until(lambda: self._all_matched(publisher), max(join_deadline - time.monotonic(), 0.0))
        self._wait_acknowledged(publisher, deadline, timeout)
        return publisher.get_subscription_count()

    def _possible_recorders(self) -> set[tuple[str, str]]:
        """The recorders of the graph that may record a topic they have not subscribed yet."""
        return {
            node
            for node in recorder_nodes(self.node)
            if not records_a_list(self.node, *node, lambda future: self.spin_until(future.done, ASK_TIMEOUT_S))
        }

    def _wait_acknowledged(self, publisher, deadline: float, timeout: float) -> None:
        """Spin until every matched reader acknowledged what ``publisher`` sent."""
        from rclpy.duration import Duration

        # Fast DDS acknowledges at the writer's next heartbeat (20 ms with the client profile of
        # use_prompt_acknowledgements, 3 s where a caller's own profile keeps the default): keep
        # spinning meanwhile, or the statuses of that time (a goal reached before its
        # acknowledgement) would be taken in late, with late arrival times.
        while not publisher.wait_for_all_acked(Duration(seconds=0)):
            if time.monotonic() > deadline:
                raise PipelineError(f"message on {publisher.topic_name} was not acknowledged within {timeout:g} s")
            self._executor.spin_once(timeout_sec=0.01)
