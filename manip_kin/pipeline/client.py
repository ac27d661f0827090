"""A small rclpy node to drive and observe a running pipeline (``manip_kin goal``/``line``, demo, tests).

:class:`PipelineClient` lives in its own rclpy context, in the namespace of the pipeline it
talks to: it sends a goal or a line target, waits until the controller reports the goal
converged (matched by the goal's stamp in ``/diagnostics``), and reads ``joint_states`` and
``tool_pose``. Topic names are relative, so ``PipelineClient(namespace="/left")`` talks to
the pipeline started with ``-r __ns:=/left``; ``/diagnostics`` is global, and each node's
status there is named ``<namespace>/<node>`` (see :func:`status_name`).

rclpy is imported when a client is made, not when this module is imported (test/conftest.py
sets the environment before rclpy loads).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping

import numpy as np

from manip_kin.pipeline.delivery import DeliveringClient
from manip_kin.pipeline.domain import ensure_ros_isolation, use_prompt_acknowledgements
from manip_kin.pipeline.errors import PipelineError
from manip_kin.pipeline.status import Status, normalize_namespace, status_name
from manip_kin.pipeline.waiting import SentTarget, WaitingClient
from manip_kin.ros.wire.messages import stamp_to_ns


class PipelineClient(DeliveringClient, WaitingClient):
    """A small rclpy node (own context) to drive and observe the pipeline.

    Args:
        env: environment whose ``ROS_DOMAIN_ID`` to use (default: this process's, completed by
            :func:`ensure_ros_isolation`).
        watch_state: subscribe to ``joint_states`` and ``tool_pose`` now (otherwise on the
            first :meth:`current_positions` / :meth:`current_tool_pose`: each subscriber costs
            the 1 kHz publisher a little, so the client only listens when asked).
        base_frame: frame id put on goals.
        node_name: this node's name.
        namespace: the pipeline's namespace (``""``: the root namespace). Topics resolve in
            it, and node names given to the ``wait_*``/``latest_status`` methods are looked
            up as ``namespace/name``.
    """

    def __init__(
        self,
        env: Mapping[str, str] | None = None,
        watch_state: bool = False,
        base_frame: str = "base_link",
        node_name: str = "",
        namespace: str = "",
    ):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseStamped
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState

        self._state_types = (JointState, PoseStamped)
        environ = ensure_ros_isolation() if env is None else env
        use_prompt_acknowledgements()  # before this process's first participant
        domain = int(environ.get("ROS_DOMAIN_ID", os.environ.get("ROS_DOMAIN_ID", "0")))
        # rclpy reads the discovery range from this process's environment.
        os.environ.setdefault(
            "ROS_AUTOMATIC_DISCOVERY_RANGE", environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        )
        self.base_frame = base_frame
        self._context = rclpy.Context()
        # No signal handlers: Ctrl-C stays a KeyboardInterrupt for the program using the client.
        rclpy.init(
            context=self._context, domain_id=domain, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO
        )
        self.namespace = normalize_namespace(namespace)
        self.node = rclpy.create_node(
            node_name or f"manip_kin_client_{os.getpid()}", namespace=self.namespace or "/", context=self._context
        )
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._publishers: dict[str, object] = {}
        self._statuses: dict[str, Status] = {}
        # The first status of each (status name, goal stamp) that said converged.
        self._first_converged: dict[tuple[str, str], Status] = {}
        # The newest goal and line target this client sent, by topic (see _resend_unreported).
        self._newest_sent: dict[str, SentTarget] = {}
        self.joint_state: JointState | None = None
        self.tool_pose: PoseStamped | None = None
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)
        self._watching = False
        if watch_state:
            self.watch_state()
        self._closed = False

    def watch_state(self) -> None:
        """Subscribe to ``joint_states`` and ``tool_pose`` (once)."""
        if not self._watching:
            joint_state_type, pose_type = self._state_types
            self._state_subscriptions = [
                self.node.create_subscription(joint_state_type, "joint_states", self._on_joint_state, 1),
                self.node.create_subscription(pose_type, "tool_pose", self._on_tool_pose, 1),
            ]
            self._watching = True

    def unwatch_state(self) -> None:
        """Drop the ``joint_states`` and ``tool_pose`` subscriptions: two reliable 1 kHz readers
        that cost robot_state (and this process) CPU while a measurement runs."""
        if self._watching:
            for subscription in self._state_subscriptions:
                self.node.destroy_subscription(subscription)
            self._state_subscriptions = []
            self._watching = False

    # --- plumbing --------------------------------------------------------------------------------

    def now_ns(self) -> int:
        """``time.monotonic_ns()``: the clock of :attr:`Status.received_ns`."""
        return time.monotonic_ns()

    def spin_for(self, seconds: float) -> None:
        """Process incoming messages for ``seconds``."""
        deadline = time.monotonic() + seconds
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return
            self._executor.spin_once(timeout_sec=min(remaining, 0.05))

    def spin_until(self, predicate: Callable[[], object], timeout: float):
        """Spin until ``predicate()`` is truthy (returned) or ``timeout`` passes (returns None)."""
        deadline = time.monotonic() + timeout
        while True:
            value = predicate()
            if value:
                return value
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            self._executor.spin_once(timeout_sec=min(remaining, 0.02))

    def node_names(self) -> list[str]:
        """Node names currently in the graph."""
        return self.node.get_node_names()

    def _on_diagnostics(self, msg) -> None:
        now = time.monotonic_ns()
        stamp_ns = stamp_to_ns(msg.header.stamp)
        for status in msg.status:
            entry = Status(status.name, status.message, {kv.key: kv.value for kv in status.values}, now, stamp_ns)
            self._statuses[status.name] = entry
            if status.message == "converged" and (goal_stamp := entry.values.get("goal_stamp")):
                self._first_converged.setdefault((status.name, goal_stamp), entry)

    def _on_joint_state(self, msg) -> None:
        self.joint_state = msg

    def _on_tool_pose(self, msg) -> None:
        self.tool_pose = msg

    def status_name(self, node_name: str) -> str:
        """The ``/diagnostics`` status name of node ``node_name`` of this client's namespace."""
        return status_name(node_name, self.namespace)

    def latest_status(self, name: str) -> Status | None:
        """Newest ``/diagnostics`` status of node ``name`` (in this namespace) received so far."""
        return self._statuses.get(self.status_name(name))

    def topic(self, name: str) -> str:
        """``name`` resolved in this client's namespace (``goal_pose`` → ``/left/goal_pose``)."""
        return self.node.resolve_topic_name(name)

    def close(self) -> None:
        """Destroy the node and shut its context down."""
        if self._closed:
            return
        self._closed = True
        self._executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self._context.try_shutdown()

    def __enter__(self) -> PipelineClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def pose_msg(self, pose: np.ndarray, frame_id: str | None = None):
        """A ``PoseStamped`` of a 4x4 pose stamped now (the stamp identifies it in /diagnostics)."""
        from manip_kin.ros.wire.messages import make_pose_stamped

        return make_pose_stamped(pose, frame_id or self.base_frame, self.node.get_clock().now().to_msg())

    def send_goal(self, pose: np.ndarray, frame_id: str | None = None, timeout: float = 10.0) -> str:
        """Publish a goal pose on ``goal_pose``; returns its stamp key (see :meth:`wait_converged`)."""
        return self._send_pose_target("goal_pose", pose, frame_id, timeout)

    def send_line(self, pose: np.ndarray, frame_id: str | None = None, timeout: float = 10.0) -> str:
        """Publish a line target on ``line_target``; returns its stamp key (see :meth:`wait_line_done`)."""
        return self._send_pose_target("line_target", pose, frame_id, timeout)

    def _send_pose_target(self, topic: str, pose: np.ndarray, frame_id: str | None, timeout: float) -> str:
        """Publish ``pose`` stamped now on ``topic`` once delivered; remembered as the newest
        target of ``topic`` (see :meth:`_resend_unreported`); returns its stamp key."""
        from manip_kin.ros.wire.messages import stamp_key

        msg = self.pose_msg(pose, frame_id)
        self.publish_delivered(topic, msg, timeout)
        key = stamp_key(msg.header.stamp)
        self._newest_sent[topic] = SentTarget(key, msg, time.monotonic())
        return key

    def resends(self, stamp: str) -> int:
        """Times the newest goal or line target stamped ``stamp`` was sent again (0 if none)."""
        return next((sent.resends for sent in self._newest_sent.values() if sent.stamp == stamp), 0)

    def send_joint_trajectory(self, msg, timeout: float = 10.0) -> str:
        """Stamp a ``JointTrajectory`` now and publish it on ``joint_trajectory``; returns its stamp key."""
        from manip_kin.ros.wire.messages import stamp_key

        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.publish_delivered("joint_trajectory", msg, timeout)
        return stamp_key(msg.header.stamp)

    def robot_description(self, timeout: float = 10.0) -> str:
        """The URDF on ``robot_description`` (transient local: the latched one), waiting for it."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from std_msgs.msg import String

        received: list[str] = []
        qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
        subscription = self.node.create_subscription(
            String, "robot_description", lambda m: received.append(m.data), qos
        )
        try:
            if not self.spin_until(lambda: received, timeout):
                raise PipelineError(
                    f"no {self.topic('robot_description')} within {timeout:g} s (is robot_state running? "
                    "or give --robot)"
                )
        finally:
            self.node.destroy_subscription(subscription)
        return received[-1]

    def set_parameter(self, node_name: str, name: str, value, timeout: float = 10.0) -> None:
        """Set parameter ``name`` of node ``node_name`` (in this namespace) through its parameter service.

        Raises:
            PipelineError: no service within ``timeout``, or the node refused (with its reason).
        """
        from rclpy.parameter import Parameter
        from rclpy.parameter_client import AsyncParameterClient

        remote = f"{self.namespace}/{node_name}" if self.namespace else node_name
        parameters = AsyncParameterClient(self.node, remote)
        if not parameters.wait_for_services(timeout_sec=timeout):
            raise PipelineError(f"no parameter service of {remote} within {timeout:g} s")
        future = parameters.set_parameters([Parameter(name, value=value)])
        if not self.spin_until(future.done, timeout):
            raise PipelineError(f"{remote} did not answer setting {name} within {timeout:g} s")
        result = future.result().results[0]
        if not result.successful:
            raise PipelineError(f"{remote} refused {name} = {value!r}: {result.reason}")

    def call_trigger(self, node_name: str, service: str, value: bool | None = None, timeout: float = 5.0) -> str:
        """Call ``<namespace>/<node_name>/<service>``: std_srvs/Trigger, or std_srvs/SetBool with
        ``value``; returns the node's message.

        Raises:
            PipelineError: no such service within ``timeout``, no answer, or the node refused.
        """
        from std_srvs.srv import SetBool, Trigger

        name = f"{self.namespace}/{node_name}/{service}" if self.namespace else f"/{node_name}/{service}"
        srv_type = Trigger if value is None else SetBool
        client = self.node.create_client(srv_type, name)
        try:
            if not client.wait_for_service(timeout_sec=timeout):
                raise PipelineError(f"no service {name} within {timeout:g} s (is {node_name} running?)")
            request = srv_type.Request() if value is None else SetBool.Request(data=bool(value))
            future = client.call_async(request)
            if not self.spin_until(future.done, timeout):
                raise PipelineError(f"{name} did not answer within {timeout:g} s")
            response = future.result()
            if not response.success:
                raise PipelineError(f"{name} refused: {response.message}")
            return response.message
        finally:
            self.node.destroy_client(client)

    def current_positions(self, timeout: float = 5.0) -> np.ndarray:
        """Newest ``joint_states`` positions (message order), waiting for one if needed."""
        self.watch_state()
        self.joint_state = None
        msg = self.spin_until(lambda: self.joint_state, timeout)
        if msg is None:
            raise PipelineError(f"no {self.topic('joint_states')} within {timeout:g} s")
        return np.array(msg.position)

    def current_tool_pose(self, timeout: float = 5.0) -> np.ndarray:
        """Newest ``tool_pose`` as a 4x4 pose, waiting for one if needed."""
        from manip_kin.ros.wire.messages import pose_stamped_to_matrix

        self.watch_state()
        self.tool_pose = None
        msg = self.spin_until(lambda: self.tool_pose, timeout)
        if msg is None:
            raise PipelineError(f"no {self.topic('tool_pose')} within {timeout:g} s")
        return pose_stamped_to_matrix(msg)
