"""In-process harness for node tests: one rclpy context, the node under test, a test node.

The node under test runs its own loop thread; the harness spins only its test node
(subscriptions collecting what the node publishes) with a SingleThreadedExecutor.
"""

from __future__ import annotations

import itertools
import os
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

_names = itertools.count()


class Harness:
    def __init__(self):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f"test_harness_{os.getpid()}_{next(_names)}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.nodes = []
        self._publishers = {}

    def start(self, node_class, namespace: str | None = None, cli_args: list[str] | None = None, **parameters):
        """Start ``node_class`` with these parameters, in ``namespace`` if given, with ``cli_args``
        (``["--ros-args", "--params-file", PATH]``) if given."""
        overrides = [Parameter(name, value=value) for name, value in parameters.items()]
        extra = {"namespace": namespace} if namespace else {}
        if cli_args:
            extra["cli_args"] = list(cli_args)
        node = node_class(context=self.context, parameter_overrides=overrides, **extra)
        self.nodes.append(node)
        return node

    def collect(self, msg_type, topic: str, latched: bool = False) -> list:
        received = []
        qos = (
            QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
            if latched
            # Deep: the nodes under test run in this process and compete for the GIL; when this
            # executor falls behind a 100-deep queue dropped the oldest messages (a line's start).
            else 10000
        )
        self.node.create_subscription(msg_type, topic, received.append, qos)
        return received

    def publisher(self, msg_type, topic: str):
        if topic not in self._publishers:
            self._publishers[topic] = self.node.create_publisher(msg_type, topic, 10)
        return self._publishers[topic]

    def publish(self, topic: str, msg) -> None:
        self.publisher(type(msg), topic).publish(msg)

    def wait_matched(self, topic: str, msg_type, timeout: float = 15.0) -> None:
        publisher = self.publisher(msg_type, topic)
        assert self.spin_until(lambda: publisher.get_subscription_count() > 0, timeout), f"nobody subscribes {topic}"

    def spin_for(self, seconds: float, every=None, period: float = 0.01) -> None:
        """Spin for ``seconds``; call ``every()`` each ``period`` (to stream inputs)."""
        deadline = time.monotonic() + seconds
        next_call = time.monotonic()
        while time.monotonic() < deadline:
            if every is not None and time.monotonic() >= next_call:
                every()
                next_call += period
            self.executor.spin_once(timeout_sec=0.002)

    def spin_until(self, predicate, timeout: float = 5.0, every=None, period: float = 0.01):
        deadline = time.monotonic() + timeout
        next_call = time.monotonic()
        while time.monotonic() < deadline:
            if every is not None and time.monotonic() >= next_call:
                every()
                next_call += period
            value = predicate()
            if value:
                return value
            self.executor.spin_once(timeout_sec=0.002)
        return predicate()

    def logged(self, node, capfd, timeout: float = 5.0, every=None) -> str:
        """Everything written to stderr so far, read once ``node``'s loop finished the cycle it runs now.

        A node counts a rejection and then logs it, in its loop thread. Polling
        ``capfd.readouterr()`` meanwhile can lose the line: pytest reads the capture file and
        then truncates it, and a line written in between is gone (a test failed so once).
        """

        def cycles_begun_or_ended() -> int:
            stats = node.loop.stats()
            return (
                stats.cycles + stats.woken
            )  # every cycle but the first adds one: at its start if woken, else at its end

        start = cycles_begun_or_ended()
        # Two more: the cycle running at the start has ended, however each was counted.
        assert self.spin_until(lambda: cycles_begun_or_ended() >= start + 2, timeout, every=every), "the loop stalled"
        return capfd.readouterr().err

    def close(self) -> None:
        for node in self.nodes:
            node.stop()
        for node in self.nodes:
            node.destroy_node()
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()


def statuses(diagnostics: list, name: str) -> list:
    """The DiagnosticStatus entries named ``name`` in received DiagnosticArrays."""
    return [status for msg in diagnostics for status in msg.status if status.name == name]


def without_acceleration_limits(joint_names) -> dict:
    """Parameters that switch the command filter's acceleration and jerk limits off for every
    joint: the commands are then the control law's own (tests of the law's values)."""
    values = {}
    for joint in joint_names:
        values[f"joint_limits.{joint}.has_acceleration_limits"] = False
        values[f"joint_limits.{joint}.has_jerk_limits"] = False
    return values
