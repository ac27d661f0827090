"""``manip_kin twist`` and ``manip_kin jog``: stream a velocity command to cartesian_controller for a while.

Both publish at a steady ``--rate`` (default 50 Hz, well inside the controller's
``command_timeout``) for ``--duration`` seconds: ``twist`` a geometry_msgs/TwistStamped on
``twist_command``, ``jog`` a sensor_msgs/JointState (names and velocities only) on
``joint_jog``. At the end, and on Ctrl-C, they stop the arm: one zero command, then the
controller's ``cartesian_controller/stop`` service (std_srvs/Trigger) when it is there.
:class:`CommandStream` is that plumbing, shared with ``manip_kin teleop``.

Exit codes: 0 streamed and stopped; 2 bad input or nobody subscribed within ``--timeout``;
130 after Ctrl-C (the arm was stopped first).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass

from manip_kin.cli.common import add_json_argument, add_namespace_argument, namespace_from_args, print_json
from manip_kin.errors import EXIT_INTERRUPTED, InvalidArgumentError

TWIST_TOPIC = "twist_command"
JOG_TOPIC = "joint_jog"
STOP_SERVICE = "cartesian_controller/stop"
#: Seconds a robot_description is waited for (frames and joint names); without one the
#: defaults apply (base_link, names unchecked).
DESCRIPTION_WAIT_S = 2.0
STOP_SERVICE_WAIT_S = 0.5
ZERO_ACK_WAIT_S = 1.0
#: How long the zeros may hold back the stop service call [s] (see :meth:`CommandStream.stop`).
ZERO_BEFORE_STOP_S = 0.1


@dataclass(frozen=True)
class ArmFrames:
    """What the commands need to know of the arm, from its ``robot_description``.

    Attributes:
        base_frame: frame id of the base.
        tool_frame: frame id of the controlled frame (the tool link, else the chain's tip).
        joint_names: the chain's joints, model order (empty when unknown).
        links: the frame ids a twist may be expressed in: base, chain links, tip, tool (empty
            when unknown: then any is sent).
        model: the model (None without a description).
    """

    base_frame: str = "base_link"
    tool_frame: str = "tool"
    joint_names: tuple[str, ...] = ()
    links: tuple[str, ...] = ()
    model: object = None


def arm_frames(client, timeout: float = DESCRIPTION_WAIT_S) -> ArmFrames:
    """The arm's frames from ``robot_description`` (transient local); defaults when there is none."""
    from manip_kin.pipeline import PipelineError

    try:
        text = client.robot_description(timeout)
    except PipelineError:
        return ArmFrames()
    return frames_from_urdf(text, client.topic("robot_description"))


def frames_from_urdf(text: str, source: str) -> ArmFrames:
    """The frames of the arm a URDF describes (its ``manip_kin_chain`` hint, else its unbranched chain).

    Raises:
        ModelFileError: the text is not a usable URDF (the message names ``source``).
    """
    from manip_kin.core.urdf import load_urdf_string
    from manip_kin.core.urdf.document import UrdfTree

    model = load_urdf_string(text, source=source)
    hint = UrdfTree(text, source).chain_hint
    tip = hint.get("tip_link") or (model.joints[-1].link_name if model.joints else model.base_frame)
    tool = hint.get("tool_link") or tip
    links = dict.fromkeys([model.base_frame, *(j.link_name for j in model.joints if j.link_name), tip, tool])
    return ArmFrames(model.base_frame, tool, tuple(model.joint_names), tuple(links), model)


class CommandStream:
    """Publishers of ``twist_command`` and ``joint_jog`` in a :class:`~manip_kin.pipeline.PipelineClient`,
    and the stop (a zero command, then ``cartesian_controller/stop`` when available)."""

    def __init__(self, client):
        from geometry_msgs.msg import TwistStamped
        from sensor_msgs.msg import JointState

        self.client = client
        self._types = {TWIST_TOPIC: TwistStamped, JOG_TOPIC: JointState}
        self.published = {TWIST_TOPIC: 0, JOG_TOPIC: 0}
        self._last: dict[str, object] = {}

    def wait_subscriber(self, topic: str, timeout: float) -> None:
        """Wait until someone subscribes ``topic`` (PipelineError after ``timeout``)."""
        self.client.wait_subscribers(self._types[topic], topic, timeout)

    def twist(self, linear: Sequence[float], angular: Sequence[float], frame: str) -> None:
        """Publish one TwistStamped stamped now: ``linear`` [m/s], ``angular`` [rad/s] in ``frame``."""
        msg = self._types[TWIST_TOPIC]()
        msg.header.stamp = self.client.node.get_clock().now().to_msg()
        msg.header.frame_id = frame
        msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (float(v) for v in linear)
        msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = (float(v) for v in angular)
        self._publish(TWIST_TOPIC, msg)

    def jog(self, names: Sequence[str], velocities: Sequence[float]) -> None:
        """Publish one JointState stamped now with ``names`` and ``velocities`` [rad/s | m/s] only."""
        msg = self._types[JOG_TOPIC]()
        msg.header.stamp = self.client.node.get_clock().now().to_msg()
        msg.name = list(names)
        msg.velocity = [float(v) for v in velocities]
        self._publish(JOG_TOPIC, msg)

    def _publish(self, topic: str, msg) -> None:
        # Noted before it goes out: a Ctrl-C lands when publish() returns, and the stop must
        # still know this topic needs its zero.
        self._last[topic] = msg
        self.client.publisher(self._types[topic], topic).publish(msg)
        self.published[topic] += 1

    def stop(self) -> str:
        """Zero what was streamed, then call the controller's stop service if it is there; what was done."""
        from std_srvs.srv import Trigger

        done = []
        for topic, msg in self._last.items():
            if topic == TWIST_TOPIC:
                self.twist((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), msg.header.frame_id)
            else:
                self.jog(msg.name, [0.0] * len(msg.name))
            done.append(f"zero on {self.client.topic(topic)}")
        # Topics and services are not ordered with each other: the zero, sent first, could reach
        # the controller after its stop. Its acknowledgement first, for a few of the client's
        # 20 ms heartbeats at most: the stop, which brings the arm to rest too, is not held back longer.
        self._wait_for_zeros(time.monotonic() + ZERO_BEFORE_STOP_S)
        service = self.client.node.create_client(Trigger, STOP_SERVICE)
        name = self.client.node.resolve_service_name(STOP_SERVICE)
        try:
            if service.wait_for_service(timeout_sec=STOP_SERVICE_WAIT_S):
                future = service.call_async(Trigger.Request())
                response = self.client.spin_until(future.done, 2.0) and future.result()
                done.append(
                    f"{name}: {response.message or 'ok'}"
                    if response and response.success
                    else f"{name} did not confirm ({response.message if response else 'no answer'})"
                )
            else:
                done.append(f"no {name} service")
        finally:
            self.client.node.destroy_client(service)
        # The zeros went out with publish(); a lost one is sent again while the process lives, so
        # it stays up to ZERO_ACK_WAIT_S for the acknowledgement (at the client's 20 ms heartbeat).
        self._wait_for_zeros(time.monotonic() + ZERO_ACK_WAIT_S)
        return "; ".join(done)

    def _wait_for_zeros(self, deadline: float) -> None:
        """Until every streamed topic's messages are acknowledged, or ``deadline`` [monotonic s]."""
        from rclpy.duration import Duration

        for topic in self._last:
            publisher = self.client.publisher(self._types[topic], topic)
            publisher.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))


def stream_for(client, send, duration: float, rate_hz: float) -> float:
    """Call ``send()`` at ``rate_hz`` for ``duration`` seconds (spinning meanwhile); the seconds streamed."""
    start = time.monotonic()
    period = 1.0 / rate_hz
    next_send = start
    while True:
        now = time.monotonic()
        if now - start >= duration:
            return now - start
        send()
        # Behind schedule (a stalled process), the stream goes on at its rate from now: no burst
        # of the missed periods' messages.
        next_send = max(next_send + period, time.monotonic())
        client.spin_for(max(0.0, next_send - time.monotonic()))


def _positive(value: float, flag: str, unit: str) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InvalidArgumentError(f"{flag} {value}; valid: {unit} > 0")


def _finite(values: Sequence[float], flag: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise InvalidArgumentError(f"{flag} contains NaN or infinity; valid: finite numbers")


def register(subparsers) -> None:
    """Add ``twist`` and ``jog``."""
    twist = subparsers.add_parser(
        "twist",
        help="stream a twist of the controlled frame on twist_command for --duration s, then stop the arm",
        description="Publish a geometry_msgs/TwistStamped on twist_command (in --namespace) at --rate for "
        "--duration seconds; then, and on Ctrl-C, a zero twist and the controller's cartesian_controller/stop "
        "service when it is there. The velocity is that of the controlled frame, expressed in --frame. "
        "Example: manip_kin twist --linear 0 0.05 0 --angular 0 0 0 --duration 2",
        epilog="exit status: 0 streamed and stopped, 2 bad input or no subscriber, 130 Ctrl-C (arm stopped)",
    )
    twist.add_argument("--linear", nargs=3, type=float, metavar=("X", "Y", "Z"), default=[0.0, 0.0, 0.0])
    twist.add_argument("--angular", nargs=3, type=float, metavar=("X", "Y", "Z"), default=[0.0, 0.0, 0.0])
    twist.add_argument(
        "--frame",
        default=None,
        help="frame_id the twist is expressed in: the base frame, the controlled frame or a chain link; "
        "'base' and 'tool' name the arm's (default: the base frame, from robot_description)",
    )
    _add_stream_arguments(twist)
    twist.set_defaults(run=run_twist)
    jog = subparsers.add_parser(
        "jog",
        help="stream a joint velocity on joint_jog for --duration s, then stop the arm",
        description="Publish a sensor_msgs/JointState with the joint names and velocities (no positions) on "
        "joint_jog (in --namespace) at --rate for --duration seconds; then, and on Ctrl-C, zero velocities "
        "and the controller's cartesian_controller/stop service when it is there. "
        "Example: manip_kin jog --joint joint1 --velocity 0.2 --duration 1.5",
        epilog="exit status: 0 streamed and stopped, 2 bad input or no subscriber, 130 Ctrl-C (arm stopped)",
    )
    jog.add_argument("--joint", nargs="+", required=True, metavar="NAME", help="joint name(s)")
    jog.add_argument(
        "--velocity", nargs="+", type=float, required=True, metavar="V", help="velocity per joint [rad/s | m/s]"
    )
    _add_stream_arguments(jog)
    jog.set_defaults(run=run_jog)


def _add_stream_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, required=True, metavar="S", help="how long to stream [s]")
    parser.add_argument("--rate", type=float, default=50.0, metavar="HZ", help="messages per second (default 50)")
    parser.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to wait for a subscriber (default 10)"
    )
    add_namespace_argument(parser)
    add_json_argument(parser)


def _check_stream_arguments(args) -> None:
    _positive(args.duration, "--duration", "seconds")
    _positive(args.rate, "--rate", "Hz")
    _positive(args.timeout, "--timeout", "seconds")


def _run_stream(args, topic: str, prepare, describe) -> int:
    """Wait for a subscriber, stream ``send`` (from ``prepare(frames)``), stop; report."""
    from manip_kin.pipeline import PipelineClient, PipelineError

    namespace = namespace_from_args(args)
    with PipelineClient(namespace=namespace) as client:
        stream = CommandStream(client)
        try:
            stream.wait_subscriber(topic, args.timeout)
        except PipelineError as error:
            print(f"manip_kin {args.command}: error: {error}", file=sys.stderr)
            return 2
        send, payload = prepare(stream, arm_frames(client))
        code, streamed = 0, 0.0
        started = time.monotonic()
        try:
            streamed = stream_for(client, send, args.duration, args.rate)
        except KeyboardInterrupt:
            code, streamed = EXIT_INTERRUPTED, time.monotonic() - started
        finally:
            stopped = stream.stop()
        payload.update(topic=client.topic(topic), messages=stream.published[topic], seconds=streamed, stopped=stopped)
        if args.json:
            print_json(payload)
        else:
            print(
                f"{describe(payload)}: {payload['messages']} messages in {streamed:.2f} s on {payload['topic']}; "
                f"stopped: {stopped}"
            )
        return code


def run_twist(args: argparse.Namespace) -> int:
    """``manip_kin twist``."""
    _check_stream_arguments(args)
    _finite(args.linear + args.angular, "--linear/--angular")

    def prepare(stream: CommandStream, frames: ArmFrames):
        frame = {"base": frames.base_frame, "tool": frames.tool_frame, None: frames.base_frame}.get(
            args.frame, args.frame
        )
        if frames.links and frame not in frames.links:
            raise InvalidArgumentError(
                f"--frame {frame}: not a frame of the arm's chain; valid: base, tool, {', '.join(frames.links)}"
            )
        return (lambda: stream.twist(args.linear, args.angular, frame)), {
            "linear": args.linear,
            "angular": args.angular,
            "frame": frame,
        }

    return _run_stream(
        args, TWIST_TOPIC, prepare, lambda p: f"twist {p['linear']} m/s {p['angular']} rad/s in {p['frame']}"
    )


def run_jog(args: argparse.Namespace) -> int:
    """``manip_kin jog``."""
    _check_stream_arguments(args)
    if len(args.joint) != len(args.velocity):
        raise InvalidArgumentError(
            f"--joint has {len(args.joint)} names and --velocity {len(args.velocity)} values; valid: one value per joint"
        )
    _finite(args.velocity, "--velocity")

    def prepare(stream: CommandStream, frames: ArmFrames):
        unknown = [name for name in args.joint if frames.joint_names and name not in frames.joint_names]
        if unknown:
            raise InvalidArgumentError(
                f"--joint {' '.join(unknown)}: not a joint of the arm; valid: {', '.join(frames.joint_names)}"
            )
        return (lambda: stream.jog(args.joint, args.velocity)), {"joints": args.joint, "velocities": args.velocity}

    return _run_stream(
        args, JOG_TOPIC, prepare, lambda p: f"jog {dict(zip(p['joints'], p['velocities'], strict=True))}"
    )
