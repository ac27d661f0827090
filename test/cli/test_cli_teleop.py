"""``manip_kin twist``, ``jog`` and ``teleop`` against the topics (no controller: a test subscriber).

The harness node stands in for cartesian_controller: it publishes the genova7 URDF on
robot_description, subscribes ``twist_command`` and ``joint_jog``, and serves
``cartesian_controller/stop`` (std_srvs/Trigger), noting when each arrived. ``teleop`` runs in
a pseudo-terminal (pty.fork), driven by the keys written to it.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import os
import pty
import select
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip_kin.cli.teleop_keys import QUIT_KEYS, STOP_KEYS, TWIST_KEYS, TeleopState, apply_key, nearest_limit
from manip_kin.core.robots import load_robot

MANIP_KIN = str(Path(sys.executable).parent / "manip_kin")
MODEL = load_robot("genova7")


# --- the key map, without a terminal ----------------------------------------------------------


@given(st.lists(st.sampled_from(sorted(set("wsadrfujikolxtm+-=_123456789q ") | {"\x03", "Z", "\x1b"})), max_size=40))
def test_every_key_sequence_gives_one_axis_or_joint_at_the_current_speed(keys):
    state = TeleopState()
    for key in keys:
        previous = state
        state = apply_key(state, key, joint_count=7)
        if key in STOP_KEYS or key in QUIT_KEYS:
            assert not state.moving
        if key in TWIST_KEYS and previous.mode == "twist":
            linear, angular = state.twist()
            axis, sign = TWIST_KEYS[key]
            expected = np.zeros(6)
            expected[axis] = sign * (state.linear_speed if axis < 3 else state.angular_speed)
            np.testing.assert_array_equal(np.concatenate([linear, angular]), expected)
    assert sum(1 for v in state.direction if v) <= 1
    assert 0 <= state.joint < 7
    assert state.mode == "twist" or not any(state.direction)
    assert state.mode == "joint" or state.joint_direction == 0.0


def test_speed_steps_and_mode_changes_stop_the_motion():
    state = apply_key(TeleopState(), "w", 7)
    faster = apply_key(state, "+", 7)
    assert faster.twist()[0][0] == pytest.approx(0.05 * 1.25) and faster.moving
    assert not apply_key(faster, "t", 7).moving and apply_key(faster, "t", 7).tool_frame
    joint = apply_key(apply_key(apply_key(TeleopState(), "m", 7), "3", 7), "s", 7)
    assert (joint.mode, joint.joint, joint.jog()) == ("joint", 2, -0.2)
    assert apply_key(joint, "8", 7).joint == 2  # the arm has 7 joints


def test_nearest_limit_is_the_smallest_share_of_the_range():
    limit = nearest_limit(["a", "b", "c"], [-1.0, 0.0, -np.inf], [1.0, 0.2, np.inf], [0.8, 0.1, 5.0])
    assert (limit.joint, limit.side) == ("a", "upper")
    assert limit.distance == pytest.approx(0.2) and limit.fraction == pytest.approx(0.1)
    assert nearest_limit(["c"], [-np.inf], [np.inf], [0.0]) is None


# --- the commands against a stand-in controller ---------------------------------------------------


@pytest.fixture
def controller():
    from geometry_msgs.msg import TwistStamped
    from node_harness import Harness
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from manip_kin.core.urdf import model_to_urdf

    harness = Harness()
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    harness.node.create_publisher(String, "robot_description", latched).publish(String(data=model_to_urdf(MODEL)))
    harness.received = []  # (monotonic time, topic, message)

    def keep(topic):
        return lambda msg: harness.received.append((time.monotonic(), topic, msg))

    harness.node.create_subscription(TwistStamped, "twist_command", keep("twist_command"), 1000)
    harness.node.create_subscription(JointState, "joint_jog", keep("joint_jog"), 1000)

    def stop(_request, response):
        harness.received.append((time.monotonic(), "stop", None))
        response.success, response.message = True, "halting"
        return response

    harness.node.create_service(Trigger, "cartesian_controller/stop", stop)
    try:
        yield harness
    finally:
        harness.close()


def _run(harness, *arguments) -> subprocess.CompletedProcess:
    """``manip_kin ARGUMENTS`` in this process (discovery within one process takes ~0.1 s, across
    two up to seconds on a loaded machine), the harness spun meanwhile by a thread of its own."""
    from manip_kin.cli import main

    done = threading.Event()
    spinner = threading.Thread(target=lambda: harness.spin_until(done.is_set, 60.0))
    spinner.start()
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(list(arguments))
        time.sleep(0.2)  # the last messages in flight
    finally:
        done.set()
        spinner.join()
    return subprocess.CompletedProcess(arguments, code, out.getvalue(), err.getvalue())


def _on(harness, topic: str) -> list:
    return [msg for _, name, msg in harness.received if name == topic]


def _stamps(messages) -> np.ndarray:
    return np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in messages])


def test_twist_streams_at_the_rate_then_zero_then_stop(controller):
    result = _run(controller, "twist", "--linear", "0.01", "-0.02", "0.03", "--angular", "0", "0", "0.1",
                  "--duration", "0.6", "--rate", "40")  # fmt: skip
    assert result.returncode == 0, result.stderr
    twists = _on(controller, "twist_command")
    *moving, last = twists
    assert 12 <= len(moving) <= 26, len(moving)  # 0.6 s at 40 Hz
    for msg in moving:
        assert msg.header.frame_id == "base_link"  # the URDF's base frame
        assert (msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z) == (0.01, -0.02, 0.03)
        assert (msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z) == (0.0, 0.0, 0.1)
    assert np.median(np.diff(_stamps(moving))) == pytest.approx(1 / 40, rel=0.4)
    assert (last.twist.linear.x, last.twist.linear.y, last.twist.linear.z, last.twist.angular.z) == (0, 0, 0, 0)
    order = [name for _, name, _ in controller.received]
    assert order[-1] == "stop" and order.count("stop") == 1
    assert "stopped: zero on /twist_command; /cartesian_controller/stop: halting" in result.stdout


def test_jog_streams_names_and_velocities_then_zero(controller):
    result = _run(controller, "jog", "--joint", "joint3", "--velocity", "-0.3", "--duration", "0.4", "--json")
    assert result.returncode == 0, result.stderr
    jogs = _on(controller, "joint_jog")
    *moving, last = jogs
    assert len(moving) >= 8
    assert all(list(m.name) == ["joint3"] and list(m.velocity) == [-0.3] and not m.position for m in moving)
    assert list(last.name) == ["joint3"] and list(last.velocity) == [0.0]
    assert '"messages": ' in result.stdout and _on(controller, "stop") == [None]


def test_ctrl_c_during_a_twist_stops_the_arm_and_exits_130(controller, monkeypatch):
    from manip_kin.cli.teleop_streaming import CommandStream

    twist, calls = CommandStream.twist, []

    def interrupted_on_the_fifth(self, *arguments):
        calls.append(arguments)
        if len(calls) == 5:
            raise KeyboardInterrupt  # where Ctrl-C lands in the streaming loop
        twist(self, *arguments)

    monkeypatch.setattr(CommandStream, "twist", interrupted_on_the_fifth)
    result = _run(controller, "twist", "--linear", "0.01", "0", "0", "--duration", "5", "--json")
    assert result.returncode == 130
    twists = _on(controller, "twist_command")
    assert [m.twist.linear.x for m in twists] == [0.01] * 4 + [0.0]
    assert [name for _, name, _ in controller.received][-1] == "stop"
    assert '"messages": 5' in result.stdout


def test_a_twist_in_a_frame_outside_the_chain_is_a_one_line_error(controller):
    result = _run(controller, "twist", "--linear", "0.01", "0", "0", "--frame", "camera", "--duration", "1")
    assert result.returncode == 2
    links = ["base_link", *(f"link{i}" for i in range(1, 8)), "ee", "tool"]
    assert result.stderr.strip().splitlines() == [
        f"manip_kin twist: error: --frame camera: not a frame of the arm's chain; valid: base, tool, {', '.join(links)}"
    ]
    assert _on(controller, "twist_command") == []


def test_jog_of_an_unknown_joint_is_a_one_line_error(controller):
    result = _run(controller, "jog", "--joint", "elbow", "--velocity", "0.1", "--duration", "1")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "manip_kin jog: error: --joint elbow: not a joint of the arm; valid: " + ", ".join(MODEL.joint_names)
    ]
    assert _on(controller, "joint_jog") == []


class _Terminal:
    """``manip_kin teleop`` in a pseudo-terminal: keys in, output collected."""

    def __init__(self, harness, *arguments):
        self.harness = harness
        self.pid, self.master = pty.fork()
        if self.pid == 0:  # the child: nothing but exec (the parent runs rclpy threads)
            os.execv(MANIP_KIN, [MANIP_KIN, "teleop", "--rate", "40", *arguments])
        fcntl.ioctl(self.master, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 250, 0, 0))  # rows, columns
        self.settings = termios.tcgetattr(self.master)
        self.output = ""
        self.status: int | None = None
        self.every = None  # called every 50 ms while waiting (to publish the arm's state)

    def pump(self) -> None:
        while select.select([self.master], [], [], 0)[0]:
            try:
                chunk = os.read(self.master, 4096)
            except OSError:  # the child closed the terminal
                return
            if not chunk:
                return
            self.output += chunk.decode(errors="replace")

    def wait(self, predicate, timeout: float = 20.0):
        def check():
            self.pump()
            if self.status is None:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
                if pid:
                    self.status = os.waitstatus_to_exitcode(status)
            return predicate()

        value = self.harness.spin_until(check, timeout, every=self.every, period=0.05)
        assert value, f"timed out; terminal output:\n{self.output[-3000:]}"
        return value

    def press(self, keys: str, until) -> None:
        os.write(self.master, keys.encode())
        self.wait(until)

    def close(self) -> None:
        if self.status is None:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        os.close(self.master)


def _newest(harness, topic: str, after: int = 0):
    messages = _on(harness, topic)[after:]
    return messages[-1] if messages else None


@pytest.fixture
def terminal(controller):
    terminals = []

    def start(*arguments):
        terminals.append(_Terminal(controller, *arguments))
        return terminals[-1]

    yield start
    for opened in terminals:
        opened.close()


def _arm_state_publisher(harness):
    """Publish the genova7 start state: joint_states, tool_pose and a controller status."""
    from sensor_msgs.msg import JointState

    from manip_kin.core.kinematics import frame_pose
    from manip_kin.ros.wire.diagnostics import make_diagnostic_array, make_diagnostic_status
    from manip_kin.ros.wire.messages import make_pose_stamped

    q = MODEL.start_configuration()
    pose = make_pose_stamped(frame_pose(MODEL, q, "tool"), "base_link", harness.node.get_clock().now().to_msg())
    joints = JointState(name=list(MODEL.joint_names), position=[float(v) for v in q])
    status = make_diagnostic_array(
        pose.header.stamp, [make_diagnostic_status("cartesian_controller", "ok", "tracking", "genova7", [])]
    )

    def publish():
        harness.publish("joint_states", joints)
        harness.publish("tool_pose", pose)
        harness.publish("/diagnostics", status)

    return publish


def test_teleop_keys_drive_the_topics_and_the_terminal_is_restored(controller, terminal):
    tty = terminal()
    tty.every = _arm_state_publisher(controller)
    tty.wait(lambda: "tool frame tool" in tty.output and "\x1b[K" in tty.output)  # the first status line
    tty.press("w", lambda: (m := _newest(controller, "twist_command")) and m.twist.linear.x == 0.05)
    assert _newest(controller, "twist_command").header.frame_id == "base_link"
    count = len(_on(controller, "twist_command"))
    tty.press(" ", lambda: (m := _newest(controller, "twist_command", count)) and m.twist.linear.x == 0.0)
    zero = _newest(controller, "twist_command")
    assert (zero.twist.linear.x, zero.twist.linear.y, zero.twist.linear.z) == (0.0, 0.0, 0.0)
    tty.press("t+o", lambda: (m := _newest(controller, "twist_command")) and m.twist.angular.z > 0)
    turn = _newest(controller, "twist_command")
    assert turn.header.frame_id == "tool" and turn.twist.angular.z == pytest.approx(0.2 * 1.25)
    tty.press("m2s", lambda: _newest(controller, "joint_jog") is not None)
    jog = _newest(controller, "joint_jog")
    assert list(jog.name) == ["joint2"] and list(jog.velocity) == [pytest.approx(-0.2 * 1.25)]
    # Leaving twist mode zeroed the turn in the tool frame first.
    after_mode = _on(controller, "twist_command")[-1]
    assert after_mode.header.frame_id == "tool" and after_mode.twist.angular.z == 0.0
    # The status line (redrawn at 10 Hz): the command, the tool pose, the controller, the nearest limit.
    tty.wait(
        lambda: (
            "joint joint2 -0.250 | speed 0.25 | xyz [-0.000 -1.137 +0.233] rpy [-1.047 +1.100 -1.571] | "
            "controller tracking | nearest limit joint1 upper 1.571 (25%)" in tty.output
        )
    )
    tty.press("q", lambda: tty.status is not None)
    assert tty.status == 0
    assert list(_on(controller, "joint_jog")[-1].velocity) == [0.0]
    assert _on(controller, "stop") == [None]
    assert termios.tcgetattr(tty.master) == tty.settings


def test_teleop_ctrl_c_stops_the_arm_and_restores_the_terminal(controller, terminal):
    tty = terminal()
    tty.wait(lambda: "tool frame tool" in tty.output and "\x1b[K" in tty.output)  # the first status line
    tty.press("a", lambda: (m := _newest(controller, "twist_command")) and m.twist.linear.y == 0.05)
    assert termios.tcgetattr(tty.master) != tty.settings  # cbreak while it runs
    tty.press("\x03", lambda: tty.status is not None)
    assert tty.status == 130
    assert _on(controller, "twist_command")[-1].twist.linear.y == 0.0
    assert _on(controller, "stop") == [None]
    assert termios.tcgetattr(tty.master) == tty.settings


def test_a_stalled_stream_resumes_at_its_rate_without_a_burst(monkeypatch):
    from manip_kin.cli import teleop_streaming

    clock = [100.0]
    monkeypatch.setattr(teleop_streaming.time, "monotonic", lambda: clock[0])

    class StallingClient:
        spins = 0

        def spin_for(self, seconds):
            self.spins += 1
            clock[0] += seconds + (0.3 if self.spins == 5 else 0.0)  # one 0.3 s stall

    sent = []
    streamed = teleop_streaming.stream_for(StallingClient(), lambda: sent.append(clock[0]), 1.0, 40.0)
    gaps = np.diff(sent)
    assert streamed == pytest.approx(1.0, abs=0.03)
    # 40 Hz apart, but for the stall and the one message sent at once after it.
    assert np.count_nonzero(np.abs(gaps - 0.025) > 1e-9) == 2, gaps
    assert gaps.max() == pytest.approx(0.325) and gaps.min() == pytest.approx(0.0)
    # 5 sends before the stall (0 to 0.1 s), 2 at 0.425 s, then every 25 ms below 1 s.
    assert len(sent) == 5 + 2 + len(np.arange(0.45, 1.0 - 1e-9, 0.025))
