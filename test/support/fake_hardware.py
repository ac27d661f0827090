"""A ros2_control-style fake arm for tests: what a real robot's ROS side looks like to manip_kin.

Like ``robot_state_publisher`` + ros2_control's fake hardware with a
``forward_velocity_controller`` (JointGroupVelocityController), it

* publishes the robot's URDF text on ``robot_description`` (transient local, once);
* publishes ``joint_states`` for every joint it has: the arm's, plus a gripper finger joint
  that is not part of any arm chain, in a fixed order of its own;
* integrates the velocities of ``/forward_velocity_controller/commands``
  (std_msgs/Float64MultiArray, one value per arm joint in its ``joints`` order) over real time,
  each from its arrival until the next (a zero-order hold), and holds still when no command is
  fresh; with ``command_timeout=math.inf`` it holds the last
  command forever, as JointGroupVelocityController does (the arm keeps moving on it).

Every command received is kept with its arrival time (:attr:`commands`).

The arm joints are read from the URDF here (every revolute/prismatic joint, file order), not
from manip_kin. It runs in its own rclpy context and spins in a thread of its own.
"""

from __future__ import annotations

import threading
import time
import xml.etree.ElementTree as ET

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

COMMAND_TOPIC = "/forward_velocity_controller/commands"
GRIPPER_JOINT = "gripper_finger_joint"


def urdf_arm_joints(urdf_text: str) -> list[str]:
    """Names of the revolute and prismatic joints of a URDF, in file order."""
    root = ET.fromstring(urdf_text)
    return [j.get("name") for j in root.findall("joint") if j.get("type") in ("revolute", "prismatic", "continuous")]


class FakeHardware:
    """The fake arm; see the module docstring.

    Args:
        urdf_text: the URDF it publishes.
        q0: start positions of the arm joints (URDF order).
        rate_hz: integration and joint-state rate [Hz].
        command_timeout: a command older than this counts as zero [s] (math.inf: held forever).
        command_topic: where the commands come from.
        namespace: the node's namespace (relative topics resolve in it).
    """

    def __init__(
        self,
        urdf_text: str,
        q0,
        rate_hz: float = 200.0,
        command_timeout: float = 0.1,
        command_topic: str = COMMAND_TOPIC,
        namespace: str = "/",
    ):
        self.joint_names = urdf_arm_joints(urdf_text)
        self.q = np.array(q0, dtype=float)
        assert self.q.shape == (len(self.joint_names),)
        self.gripper = 0.02  # [m], never commanded
        self.commands_received = 0
        self.rejected_commands = 0
        #: Every valid command received, in order: ``(time.monotonic(), values)``.
        self.commands: list[tuple[float, np.ndarray]] = []
        self._command: np.ndarray | None = None
        self._command_time = 0.0
        self._timeout = command_timeout
        self._lock = threading.Lock()
        #: False: no joint_states go out (the arm's driver went quiet), the arm still moves.
        self.publishing = True
        #: The arm joint positions after each integration step: the path the arm took, and
        #: when (time.monotonic()).
        self.history: list[np.ndarray] = []
        self.history_times: list[float] = []
        self._context = rclpy.Context()
        rclpy.init(context=self._context, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        self.node = rclpy.create_node("fake_hardware", namespace=namespace, context=self._context)
        latched = QoSProfile(
            depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
        )
        self.node.create_publisher(String, "robot_description", latched).publish(String(data=urdf_text))
        self._joint_states = self.node.create_publisher(JointState, "joint_states", 10)
        # Deep: the tests check every command of the stream, none may be dropped.
        self.node.create_subscription(Float64MultiArray, command_topic, self._on_command, 1000)
        self._dt = 1.0 / rate_hz
        self._last = time.monotonic()
        self.node.create_timer(self._dt, self._step)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self._executor.spin_once(timeout_sec=0.05)

    def _on_command(self, msg: Float64MultiArray) -> None:
        values = np.array(msg.data, dtype=float)
        with self._lock:
            if values.shape != self.q.shape or not np.all(np.isfinite(values)):
                self.rejected_commands += 1
                return
            now = time.monotonic()
            self._advance(now)  # the previous command moved the arm until now
            self._command = values
            self._command_time = now
            self.commands_received += 1
            self.commands.append((self._command_time, values))

    def _advance(self, now: float) -> None:
        """Integrate the held command from the last integration to ``now`` [s, monotonic]: the
        whole real interval, as an arm moves on it even when this thread was held up (a stall
        that dropped motion would make the arm lag, then catch up faster than commanded)."""
        if self._command is not None:
            moving_until = min(now, self._command_time + self._timeout)
            if moving_until > self._last:
                self.q = self.q + self._command * (moving_until - self._last)
        self._last = now

    def _step(self) -> None:
        now = time.monotonic()
        with self._lock:
            self._advance(now)
            q = self.q.copy()
            self.history.append(q)
            self.history_times.append(now)
        if not self.publishing:
            return
        msg = JointState()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        # The hardware's own order: the gripper first, the arm joints reversed.
        msg.name = [GRIPPER_JOINT, *reversed(self.joint_names)]
        msg.position = [self.gripper, *reversed(q.tolist())]
        self._joint_states.publish(msg)

    def positions(self) -> np.ndarray:
        """Arm joint positions now (URDF order)."""
        with self._lock:
            return self.q.copy()

    def held_command(self) -> np.ndarray | None:
        """The command the arm moves on now (the last one while it is fresh), or None."""
        with self._lock:
            if self._command is None or time.monotonic() - self._command_time > self._timeout:
                return None
            return self._command.copy()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self._context.try_shutdown()
