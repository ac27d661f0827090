"""``manip_kin teleop``: drive the arm from the keyboard, in a terminal (works over ssh).

The terminal is put in cbreak mode (keys arrive one by one, not echoed; Ctrl-C still
signals) and read with ``select``; the keys (:data:`manip_kin.cli.teleop_keys.KEY_HELP`) set the
velocity, which is streamed at ``--rate`` on ``twist_command`` (twist mode) or ``joint_jog``
(joint mode) until space or another key. A status line shows the command, the tool pose
(``tool_pose``), the controller's state (its ``/diagnostics``) and the joint nearest to a
limit (``joint_states`` and the limits of ``robot_description``). On any exit (q, Ctrl-C,
SIGTERM, SIGHUP from a dropped ssh session, an error) the arm is stopped (zero command and
``cartesian_controller/stop``) and the terminal's settings are restored.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import select
import signal
import sys
import termios
import time
import tty

import numpy as np

from manip_kin.cli.common import add_namespace_argument, namespace_from_args
from manip_kin.cli.teleop_keys import KEY_HELP, TeleopState, apply_key, nearest_limit, status_line
from manip_kin.cli.teleop_streaming import JOG_TOPIC, TWIST_TOPIC, CommandStream, arm_frames, frames_from_urdf
from manip_kin.errors import EXIT_INTERRUPTED, InvalidArgumentError

STATUS_PERIOD_S = 0.1
# Escape sequences (arrow and function keys) are dropped whole: their letters are not commands.
_ESCAPE_SEQUENCE = re.compile(r"\x1b(\[[0-9;?]*[ -/]*[@-~]|O.|.)?")


def register(subparsers) -> None:
    """Add ``teleop``."""
    parser = subparsers.add_parser(
        "teleop",
        help="keyboard teleoperation in the terminal: twist or joint jog of the running arm",
        description="Drive the running arm from the keyboard, as teleop_twist_keyboard does: a key sets a "
        "velocity of the controlled frame (twist_command, base or tool frame) or of one joint (joint_jog), "
        "streamed at --rate until space or another key. Needs a terminal (works over ssh); the terminal is "
        "restored and the arm stopped on any exit.",
        epilog=KEY_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--linear-speed", type=float, default=0.05, metavar="M/S", help="start linear speed")
    parser.add_argument("--angular-speed", type=float, default=0.2, metavar="RAD/S", help="start angular speed")
    parser.add_argument("--joint-speed", type=float, default=0.2, metavar="V", help="start joint speed")
    parser.add_argument("--rate", type=float, default=50.0, metavar="HZ", help="messages per second (default 50)")
    parser.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to wait for the controller (default 10)"
    )
    add_namespace_argument(parser)
    parser.set_defaults(run=run_teleop)


@contextlib.contextmanager
def cbreak_terminal(fd: int):
    """The terminal ``fd`` in cbreak mode; its settings restored on leaving, however that happens.

    SIGTERM and SIGHUP (the ssh session gone) become SystemExit meanwhile, so the restore runs
    for them too; SIGINT stays a KeyboardInterrupt.
    """
    saved = termios.tcgetattr(fd)
    previous = {}

    def leave(signal_number, _frame):
        raise SystemExit(128 + signal_number)

    for signal_number in (signal.SIGTERM, signal.SIGHUP):
        previous[signal_number] = signal.signal(signal_number, leave)
    try:
        tty.setcbreak(fd, termios.TCSANOW)
        yield
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        for signal_number, handler in previous.items():
            signal.signal(signal_number, handler)


def read_keys(fd: int, timeout: float) -> str:
    """Keys typed within ``timeout`` seconds ("" when none), escape sequences removed."""
    ready, _, _ = select.select([fd], [], [], max(0.0, timeout))
    if not ready:
        return ""
    data = os.read(fd, 64)
    if not data:
        raise EOFError("the terminal closed")
    return _ESCAPE_SEQUENCE.sub("", data.decode("utf-8", errors="ignore"))


class _Teleop:
    """The loop's state: the stream, what was last sent, the arm's frames and names."""

    def __init__(self, client, stream: CommandStream, frames, state: TeleopState):
        self.client, self.stream, self.frames, self.state = client, stream, frames, state
        self.sent_moving = False

    def follow_description(self) -> None:
        """Take the arm's frames, names and limits from ``robot_description`` once it is published."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from std_msgs.msg import String

        from manip_kin.errors import ManipKinError

        def take(msg) -> None:
            try:
                self.frames = frames_from_urdf(msg.data, self.client.topic("robot_description"))
            except ManipKinError:
                pass  # not a usable URDF: the defaults stay (the status shows no limit)

        qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
        self.client.node.create_subscription(String, "robot_description", take, qos)

    def joint_names(self) -> list[str]:
        if self.frames.joint_names:
            return list(self.frames.joint_names)
        message = self.client.joint_state
        return list(message.name) if message is not None else []

    def send(self) -> None:
        """The state's command (while it moves), or one zero after it stopped."""
        state = self.state
        if not state.moving and not self.sent_moving:
            return
        if state.mode == "joint":
            names = self.joint_names()
            if state.joint < len(names):
                self.stream.jog([names[state.joint]], [state.jog()])
        else:
            linear, angular = state.twist()
            frame = self.frames.tool_frame if state.tool_frame else self.frames.base_frame
            self.stream.twist(linear, angular, frame)
        self.sent_moving = state.moving

    def key(self, key: str) -> None:
        before = self.state
        self.state = apply_key(before, key, len(self.joint_names()) or 9)
        if before.moving and (self.state.mode, self.state.tool_frame, self.state.joint) != (
            before.mode,
            before.tool_frame,
            before.joint,
        ):
            # The zero goes out in the mode and frame it stops, before the new ones apply.
            self.state, now = before.stopped(), self.state
            self.send()
            self.state = now

    def status(self) -> str:
        from manip_kin.ros.wire.messages import pose_stamped_to_matrix

        client, model = self.client, self.frames.model
        pose = pose_stamped_to_matrix(client.tool_pose) if client.tool_pose is not None else None
        controller = client.latest_status("cartesian_controller")
        limit = None
        if model is not None and client.joint_state is not None:
            by_name = dict(zip(client.joint_state.name, client.joint_state.position, strict=False))
            positions = [by_name.get(name, np.nan) for name in model.joint_names]
            limit = nearest_limit(model.joint_names, model.lower, model.upper, positions)
        return status_line(self.state, self.joint_names(), pose, controller.message if controller else "", limit)


def _draw(line: str) -> None:
    try:  # the terminal's own width (COLUMNS in the environment may be stale)
        width = os.get_terminal_size(sys.stdout.fileno()).columns or 120
    except OSError:
        width = 120
    sys.stdout.write("\r" + line[: max(10, width - 1)] + "\x1b[K")
    sys.stdout.flush()


def run_teleop(args: argparse.Namespace) -> int:
    """``manip_kin teleop``."""
    from manip_kin.pipeline import PipelineClient, PipelineError

    for flag in ("linear_speed", "angular_speed", "joint_speed", "rate", "timeout"):
        value = getattr(args, flag)
        if not (np.isfinite(value) and value > 0):
            raise InvalidArgumentError(f"--{flag.replace('_', '-')} {value}; valid: a number > 0")
    fd = sys.stdin.fileno()
    if not os.isatty(fd):
        raise InvalidArgumentError(
            "teleop reads keys from a terminal, and stdin is not one; in scripts use twist or jog"
        )
    namespace = namespace_from_args(args)
    with PipelineClient(namespace=namespace, watch_state=True) as client:
        stream = CommandStream(client)
        try:
            stream.wait_subscriber(TWIST_TOPIC, args.timeout)
        except PipelineError as error:
            print(f"manip_kin teleop: error: {error} (is cartesian_controller running?)", file=sys.stderr)
            return 2
        frames = arm_frames(client)
        state = TeleopState(
            linear_speed=args.linear_speed, angular_speed=args.angular_speed, joint_speed=args.joint_speed
        )
        teleop = _Teleop(client, stream, frames, state)
        if frames.model is None:  # robot_state may come later: take its URDF when it does
            teleop.follow_description()
        print(f"{KEY_HELP}\nbase frame {frames.base_frame}, tool frame {frames.tool_frame}", flush=True)
        code = 0
        try:
            with cbreak_terminal(fd):
                code = _loop(teleop, fd, 1.0 / args.rate)
        except KeyboardInterrupt:
            code = EXIT_INTERRUPTED
        except SystemExit as leaving:
            code = int(leaving.code or 0)
        finally:
            stopped = stream.stop()
            sys.stdout.write("\n")
        topics = ", ".join(f"{client.topic(t)} {stream.published[t]}" for t in (TWIST_TOPIC, JOG_TOPIC))
        print(f"teleop: messages sent: {topics}; stopped: {stopped}", flush=True)
        return code


def _loop(teleop: _Teleop, fd: int, period: float) -> int:
    next_send = next_status = time.monotonic()
    while True:
        now = time.monotonic()
        for key in read_keys(fd, min(next_send, next_status) - now):
            teleop.key(key)
            if teleop.state.quit:
                return 0
        now = time.monotonic()
        if now >= next_send:
            teleop.send()
            next_send = max(next_send + period, now)
        if now >= next_status:
            teleop.client.spin_for(0.005)  # take in the newest joint state, pose and status
            _draw(teleop.status())
            next_status = now + STATUS_PERIOD_S
