"""Subscriptions a node's loop thread polls, and the one module that uses rclpy internals.

The loops read their inputs at the start of each cycle instead of through executor
callbacks (see :mod:`manip_kin.ros.runtime.rate_loop` for the measured reason). Two ways to
do that:

* **fast** (rclpy internals): a subscription in a callback group the executor never
  runs, drained with ``subscription.handle.take_message``; the loop thread waits on an
  rcl wait set holding the subscriptions that should wake it (a new goal), so a goal is
  acted on at once instead of at the next tick. ``handle`` and ``_rclpy.WaitSet`` are
  not public API: they are used only here, only on the rclpy versions listed in
  :data:`CHECKED_RCLPY`, and only while they have the attributes used.
* **public**: ``create_subscription(..., raw=True)`` with a callback run by the node's
  executor (``run_node``'s spin thread) that stores the newest messages in a bounded
  queue and wakes the loop through a ``threading.Event``. Same behaviour, more CPU (the
  Python executor wakes for every message).

The recorder's :class:`RawSubscription` works the same two ways for its intake thread
(serialized messages with their middleware info, and message-lost counts). On the public
path its last drain (the executor has stopped) also tries the internal take, guarded: the
messages the middleware still holds then would otherwise be lost from the recording.

The fast path is chosen when available; ``MANIP_KIN_PUBLIC_RCLPY=1`` forces the public
one (tests run the nodes and the recorder that way).
"""

from __future__ import annotations

import collections
import os
import threading
import time
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import QoSSubscriptionEventType, SubscriptionEventCallbacks
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message

#: rclpy releases whose ``Subscription.handle.take_message`` and ``_rclpy.WaitSet`` were checked.
CHECKED_RCLPY = ("7.1.",)


def _rclpy_version() -> str:
    try:
        from importlib.metadata import version

        return version("rclpy")
    except Exception:  # noqa: BLE001 - unknown version: treated as unchecked
        return ""


def fast_path_problem() -> str:
    """Why the fast path is not used ("" when it is)."""
    if os.environ.get("MANIP_KIN_PUBLIC_RCLPY", "") not in ("", "0"):
        return "MANIP_KIN_PUBLIC_RCLPY is set"
    version = _rclpy_version()
    if not version.startswith(CHECKED_RCLPY):
        return f"rclpy {version or '(unknown version)'} is not one of the checked releases {CHECKED_RCLPY}"
    try:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        wait_set = _rclpy.WaitSet
        missing = [
            name
            for name in ("clear_entities", "add_subscription", "wait", "get_ready_entities")
            if not hasattr(wait_set, name)
        ]
        if missing:
            return f"rclpy's WaitSet lacks {missing}"
    except (ImportError, AttributeError) as error:
        return f"rclpy internals not found: {error}"
    return ""


class _NeverExecutedGroup(CallbackGroup):
    """A callback group the executor never waits on: its entities are polled by hand."""

    def can_execute(self, entity) -> bool:  # noqa: D102 - rclpy API
        return False

    def beginning_execution(self, entity) -> bool:  # noqa: D102 - rclpy API
        return False

    def ending_execution(self, entity) -> None:  # noqa: D102 - rclpy API
        return None


def _ignore(_msg) -> None:
    return None


class PolledSubscription:
    """A subscription read with :meth:`take` from the loop thread.

    Args:
        node: the node that owns it.
        msg_type: message class.
        topic: topic name (remappable like any other).
        qos: QoS profile or depth.
        public: force the public-API path (default: the fast path when available).
        timed: keep each message's source timestamp for :meth:`take_timed`.
    """

    def __init__(
        self,
        node: Node,
        msg_type,
        topic: str,
        qos: QoSProfile | int = 10,
        public: bool | None = None,
        timed: bool = False,
    ):
        self._msg_type = msg_type
        self.timed = timed
        self.fast = not public and not fast_path_problem()
        self.wake_event: threading.Event | None = None  # set on arrival (public path), see LoopWaiter
        if self.fast:
            self._subscription = node.create_subscription(
                msg_type, topic, _ignore, qos, callback_group=_NeverExecutedGroup()
            )
            self._queue = None
        else:
            depth = qos.depth if isinstance(qos, QoSProfile) else int(qos)
            self._queue: collections.deque | None = collections.deque(maxlen=max(1, depth))
            store = self._store_timed if timed else self._store
            self._subscription = node.create_subscription(msg_type, topic, store, qos, raw=True)

    @property
    def subscription(self):
        """The underlying rclpy subscription (topic name, publisher count)."""
        return self._subscription

    def _store(self, data: bytes) -> None:
        self._queue.append(data)
        event = self.wake_event
        if event is not None:
            event.set()

    def _store_timed(self, data: bytes, info: Any) -> None:
        self._store((data, _source_timestamp(info)))

    def take_timed(self, raw: bool = False) -> tuple[Any, int] | None:
        """As :meth:`take`, with the time the writer sent the message: its middleware source
        timestamp [ns, system clock], 0 where the middleware gives none. Needs ``timed``."""
        if self._queue is not None:
            try:
                data, sent_ns = self._queue.popleft()
            except IndexError:
                return None
            return (data if raw else deserialize_message(data, self._msg_type)), sent_ns
        taken = self._take_message(raw)
        return None if taken is None else (taken[0], _source_timestamp(taken[1]))

    def _take_message(self, raw: bool):
        """The fast path's take: ``(message, info)`` or None."""
        handle = self._subscription.handle
        with handle:
            return handle.take_message(self._msg_type, raw)

    def take(self, raw: bool = False):
        """The oldest unread message (its CDR ``bytes`` with ``raw``), or None. Never blocks."""
        if self.timed:
            taken = self.take_timed(raw)
            return None if taken is None else taken[0]
        if self._queue is not None:
            try:
                data = self._queue.popleft()
            except IndexError:
                return None
            return data if raw else deserialize_message(data, self._msg_type)
        taken = self._take_message(raw)
        return None if taken is None else taken[0]


class LoopWaiter:
    """Sleeps the loop thread until a deadline, waking early when a message arrives.

    Args:
        node: the node (its context owns the wait set).
        subscriptions: the :class:`PolledSubscription` s whose messages should wake the loop.

    :meth:`wait` returns True when it returned early because one of them has data. While
    :attr:`enabled` is False it just sleeps (a node turns waking off while messages stream
    in at its own rate anyway: there is nothing to gain then, and the cycle is better kept
    on its own schedule).
    """

    def __init__(self, node: Node, subscriptions: list[PolledSubscription]):
        self.enabled = True
        self._subscriptions = list(subscriptions)
        self._event = threading.Event()
        self._wait_set = None
        fast = [s for s in self._subscriptions if s.fast]
        for subscription in self._subscriptions:
            if not subscription.fast:
                subscription.wake_event = self._event
        if fast:
            from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

            self._wait_set = _rclpy.WaitSet(len(fast), 0, 0, 0, 0, 0, node.context.handle)
            self._handles = [s.subscription.handle for s in fast]

    def wake(self) -> None:
        """Wake the loop now (thread-safe)."""
        self._event.set()

    def wait(self, timeout_ns: int) -> bool:
        """Block up to ``timeout_ns``; True when woken early by a message or :meth:`wake`."""
        if timeout_ns <= 0:
            return False
        if not self.enabled:
            time.sleep(timeout_ns * 1e-9)
            return False
        event = self._event
        if event.is_set():
            event.clear()
            return True
        if self._wait_set is None:
            woken = event.wait(timeout_ns * 1e-9)
            event.clear()
            return woken
        wait_set = self._wait_set
        wait_set.clear_entities()
        for handle in self._handles:
            wait_set.add_subscription(handle)
        wait_set.wait(timeout_ns)
        if wait_set.get_ready_entities("subscription"):
            return True
        if event.is_set():
            event.clear()
            return True
        return False


def sleep_ns(timeout_ns: int) -> bool:
    """Plain sleep (the loop without a waiter); never woken early."""
    if timeout_ns > 0:
        time.sleep(timeout_ns * 1e-9)
    return False


def _source_timestamp(info: Any) -> int:
    """The writer's send time in rclpy's MessageInfo [ns], 0 where there is none."""
    try:
        return int(info["source_timestamp"])
    except (KeyError, TypeError, ValueError):
        return 0


def _info_dict(info: Any) -> dict:
    """rclpy's MessageInfo (a dict on the fast path, a dict-like on the public one) as a dict."""
    return dict(info) if info is not None else {}


class RawSubscription:
    """A subscription the recorder's intake thread drains: CDR bytes with their message info.

    Fast path: in the never-run group, taken with ``handle.take_message``, message-lost
    counts from an ``_rclpy.EventHandle`` polled by the same thread. Public path: an
    executor callback stores ``(data, info)`` (rclpy passes MessageInfo to a two-argument
    callback) in a bounded queue, and ``SubscriptionEventCallbacks(message_lost=...)``
    counts losses.

    Args:
        node: the recorder node.
        message_type: the rclpy class of the topic's type.
        topic: topic name.
        qos: the requested profile.
        fast: use the fast path (default: when :func:`fast_path_problem` finds none).
        queue_depth: messages the public path holds between two intake passes.

    Attributes:
        reports_losses: the middleware reports lost messages for this subscription.
    """

    def __init__(
        self, node: Node, message_type: type, topic: str, qos: QoSProfile, fast: bool | None = None, queue_depth=4000
    ):
        self.fast = (not fast_path_problem()) if fast is None else fast
        self._message_type = message_type
        self._lost_total = 0
        self._lock = threading.Lock()
        self._lost_event = None
        if self.fast:
            self._queue = None
            self.subscription = node.create_subscription(
                message_type, topic, _ignore, qos, callback_group=_NeverExecutedGroup(), raw=True
            )
            from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

            try:  # the event handler rclpy makes would sit in the never-run group: poll the event here
                self._lost_event = _rclpy.EventHandle(
                    self.subscription.handle, QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST
                )
            except (AttributeError, _rclpy.UnsupportedEventTypeError):
                self._lost_event = None
            self.reports_losses = self._lost_event is not None
        else:
            callbacks = SubscriptionEventCallbacks(message_lost=self._count_lost, use_default_callbacks=False)
            self._queue: collections.deque | None = collections.deque(maxlen=queue_depth)
            self.subscription = node.create_subscription(
                message_type, topic, self._store, qos, event_callbacks=callbacks, raw=True
            )
            self.reports_losses = any(
                h.event_type == QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST
                for h in self.subscription.event_handlers
            )

    def _store(self, data: bytes, info: Any) -> None:
        self._queue.append((data, _info_dict(info)))

    def _count_lost(self, status: Any) -> None:
        with self._lock:
            self._lost_total += int(status.total_count_change)

    def take(self, final: bool = False) -> tuple[bytes, dict] | None:
        """The oldest message not yet taken, ``(CDR bytes, message info)``, or None. Never blocks.

        ``final``: the executor has stopped (the recorder's last drain). On the public path the
        messages the middleware still holds never reach the callback then; they are taken
        from the subscription directly, where this rclpy offers that (best effort).
        """
        if self._queue is not None:
            try:
                return self._queue.popleft()
            except IndexError:
                return self._take_left_over() if final else None
        return self._take_from_handle()

    def _take_left_over(self) -> tuple[bytes, dict] | None:
        try:
            return self._take_from_handle()
        except Exception:  # noqa: BLE001 - an rclpy without the internal take: nothing more to get
            return None

    def _take_from_handle(self) -> tuple[bytes, dict] | None:
        handle = self.subscription.handle
        try:
            with handle:
                taken = handle.take_message(self._message_type, True)
        except InvalidHandle:  # destroyed meanwhile (a resubscription): nothing more to take
            return None
        return None if taken is None else (taken[0], _info_dict(taken[1]))

    def take_lost(self) -> int:
        """Messages the middleware reported lost since the last call."""
        if self._lost_event is not None:
            try:
                with self._lost_event:
                    status = self._lost_event.take_event()
            except InvalidHandle:
                status = None
            if status is not None:
                self._lost_total += int(status.total_count_change)
        with self._lock:
            lost, self._lost_total = self._lost_total, 0
        return lost

    def destroy(self, node: Node) -> None:
        """Remove the subscription (and its event handlers) from the node."""
        if self._lost_event is not None:
            self._lost_event.destroy_when_not_in_use()
            self._lost_event = None
        node.destroy_subscription(self.subscription)
