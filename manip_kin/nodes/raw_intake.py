"""The recorder's subscriptions: serialized messages with their middleware info, taken by its intake thread.

Both ways subscribe through the public API (``create_subscription(..., raw=True)`` with
``SubscriptionEventCallbacks(message_lost=...)``); they differ in who takes the messages:

* **fast**: the subscription sits in a callback group the executor never runs, and the
  recorder's intake thread drains it with ``subscription.handle.take_message`` (measured
  ~2 µs a message against ~400 µs through the executor, which rebuilds its wait set for
  every message); the message-lost counts come from an ``_rclpy.EventHandle`` polled by
  the same thread (the event handler rclpy makes lives in the never-run group too).
  These two internal calls are made only here, only on the rclpy releases in
  :data:`CHECKED_RCLPY` and only while they exist.
* **public**: the executor runs a callback that stores ``(data, info)`` in a bounded
  queue the intake thread drains; the message-lost callback adds to a counter. Same
  file, more CPU. ``MANIP_KIN_PUBLIC_RCLPY=1`` forces it (a test records that way).
"""

from __future__ import annotations

import collections
import os
import threading
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import QoSSubscriptionEventType, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile

#: rclpy releases whose ``Subscription.handle.take_message`` was checked.
CHECKED_RCLPY = ("7.1.",)


def _rclpy_version() -> str:
    try:
        from importlib.metadata import version

        return version("rclpy")
    except Exception:  # noqa: BLE001 - an unknown version counts as unchecked
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

        if not hasattr(_rclpy.Subscription, "take_message") or not hasattr(_rclpy, "EventHandle"):
            return "rclpy's subscription handle has no take_message, or _rclpy has no EventHandle"
    except (ImportError, AttributeError) as error:
        return f"rclpy internals not found: {error}"
    return ""


class _NeverExecuted(CallbackGroup):
    """A callback group the executor never waits on: its entities are drained by hand."""

    def can_execute(self, entity) -> bool:  # noqa: D102 - rclpy API
        return False

    def beginning_execution(self, entity) -> bool:  # noqa: D102 - rclpy API
        return False

    def ending_execution(self, entity) -> None:  # noqa: D102 - rclpy API
        return None


def _ignore(*_args) -> None:
    return None


def _info_dict(info: Any) -> dict:
    """rclpy's MessageInfo (a dict on the fast path, a dict-like on the public one) as a dict."""
    return dict(info) if info is not None else {}


class RawSubscription:
    """One recorded topic's subscription (see the module docstring).

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
                message_type, topic, _ignore, qos, callback_group=_NeverExecuted(), raw=True
            )
            from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

            try:
                self._lost_event = _rclpy.EventHandle(
                    self.subscription.handle, QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST
                )
            except _rclpy.UnsupportedEventTypeError:
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

    def take(self) -> tuple[bytes, dict] | None:
        """The oldest message not yet taken, ``(CDR bytes, message info)``, or None. Never blocks."""
        if self._queue is not None:
            try:
                return self._queue.popleft()
            except IndexError:
                return None
        handle = self.subscription.handle
        with handle:
            taken = handle.take_message(self._message_type, True)
        return None if taken is None else (taken[0], _info_dict(taken[1]))

    def take_lost(self) -> int:
        """Messages the middleware reported lost since the last call."""
        if self._lost_event is not None:
            with self._lost_event:
                status = self._lost_event.take_event()
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
