"""``robot_state``: a simulated arm driven by joint-rate commands that publishes its state.

The node holds one plant (:mod:`manip_kin.plant`, chosen by parameter ``plant``: the
kinematic integrator, or MuJoCo physics with a velocity servo per joint) and, every cycle
of its :class:`~manip_kin.ros.runtime.rate_loop.RateLoop`, hands it the latest command and
publishes ``joint_states``, ``ee_pose``, ``tool_pose``, ``ee_twist`` and ``tool_twist``.
``robot_description`` is published once, transient local: the URDF file as given (as
robot_state_publisher does), or one generated for a robot YAML.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from visualization_msgs.msg import MarkerArray

from manip_kin.core.bounds import InputBounds
from manip_kin.core.model import RobotModel
from manip_kin.core.robot_files import is_urdf_file
from manip_kin.core.robots import resolve_robot_path
from manip_kin.core.scene import Scene
from manip_kin.core.urdf import model_to_urdf, with_chain_hint
from manip_kin.errors import InvalidArgumentError, JointCountError
from manip_kin.plant.held_commands import HeldCommand, held_segments
from manip_kin.ros.nodes.physics_params import make_plant
from manip_kin.ros.nodes.robot_model import load_node_model
from manip_kin.ros.nodes.robot_state_interface import NODE_NAME, USAGE, RobotStateParams
from manip_kin.ros.nodes.visuals import RobotVisuals
from manip_kin.ros.runtime.declared_params import LiveParameters, declare_parameters
from manip_kin.ros.runtime.looping_node import LoopingNode
from manip_kin.ros.runtime.params import (
    period_ns,
)
from manip_kin.ros.runtime.polling import PolledSubscription
from manip_kin.ros.runtime.rate_loop import stats_key_values
from manip_kin.ros.runtime.runner import run_node
from manip_kin.ros.runtime.throttled_log import ThrottledLog
from manip_kin.ros.wire.cdr import JointStateCdr, PoseStampedCdr, TwistStampedCdr, decode_float64_array
from manip_kin.ros.wire.scene_messages import TOPIC as COLLISION_OBJECTS
from manip_kin.ros.wire.scene_messages import apply_marker_array
from manip_kin.ros.wire.topics import STREAM_DEPTH, latest_state_qos
from manip_kin.ros.wire.validation import command_problem


def initial_positions(model: RobotModel, values) -> np.ndarray:
    """The ``initial_positions`` parameter checked against the model (default: start configuration)."""
    if values is None or len(values) == 0:
        return model.start_configuration()
    if len(values) != model.dof:
        raise JointCountError("parameter initial_positions", len(values), model.dof)
    q = model.check_q(values, "initial_positions")
    if not model.within_limits(q):
        raise InvalidArgumentError(
            f"parameter initial_positions {np.round(q, 4).tolist()} is outside the joint limits "
            f"lower {np.round(model.lower, 4).tolist()}, upper {np.round(model.upper, 4).tolist()}"
        )
    return q


#: Commands kept between two cycles: a stall this many periods long replays all it missed.
COMMAND_DEPTH = 200


class RobotStateNode(LoopingNode):
    """ROS handles around one plant (:mod:`manip_kin.plant`)."""

    def __init__(self, **node_kwargs):
        super().__init__(NODE_NAME, **node_kwargs)
        params = declare_parameters(self, RobotStateParams)
        self.model = load_node_model(self, params)
        self.urdf_text = self._description_text(params)
        q0 = initial_positions(self.model, params.initial_positions)
        self.plant = make_plant(self.model, q0, params, self.urdf_text if self._from_urdf else None)
        for note in getattr(self.plant, "notes", ()):
            self.get_logger().info(f"plant {self.plant.name}: {note}")
        self.scene = Scene()
        self.base_frame = params.base_frame or self.model.base_frame
        self.rate_hz = params.rate_hz
        self._set_parameters(params)
        LiveParameters(self, params, self._set_parameters)

        self._max_command = InputBounds.of(self.model).max_command
        # Deep enough to replay a stall's commands at their own cycles (see plant.held_commands).
        self._command_sub = PolledSubscription(
            self, Float64MultiArray, "joint_velocity_commands", latest_state_qos(COMMAND_DEPTH), timed=True
        )
        self._joint_state_pub = self.create_publisher(JointState, "joint_states", STREAM_DEPTH)
        self._ee_pose_pub = self.create_publisher(PoseStamped, "ee_pose", STREAM_DEPTH)
        self._tool_pose_pub = self.create_publisher(PoseStamped, "tool_pose", STREAM_DEPTH)
        self._ee_twist_pub = self.create_publisher(TwistStamped, "ee_twist", STREAM_DEPTH)
        self._tool_twist_pub = self.create_publisher(TwistStamped, "tool_twist", STREAM_DEPTH)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        latched = QoSProfile(
            depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
        )
        self._description_pub = self.create_publisher(String, "robot_description", latched)

        # Messages go out pre-serialised (see conversions.PoseStampedCdr): half the publish cost.
        self._joint_state_cdr = JointStateCdr(self.model.joint_names)
        self._pose_cdr = PoseStampedCdr(self.base_frame)
        self._twist_cdr = TwistStampedCdr(self.base_frame)

        self._held: HeldCommand | None = None
        self._period_ns = period_ns(self.rate_hz)
        self._last_cycle_ns = 0
        self._last_diagnostics_ns = 0
        self.rejected_commands = 0
        self._warn = ThrottledLog(self.get_logger().warning, 1.0)
        self._with_effort = self.plant.effort_values is not None
        if self._with_effort:
            self._joint_state_cdr = JointStateCdr(self.model.joint_names, with_effort=True)
            self._scene_sub = PolledSubscription(self, MarkerArray, COLLISION_OBJECTS, 10)
        self._contact = None  # the strongest contact since the last diagnostics
        self._in_contact = False
        self.contact_events = 0

        self._description_pub.publish(String(data=self.urdf_text))
        self.visuals = RobotVisuals(
            self,
            self.model,
            self.urdf_text,
            params.frame_prefix,
            params.tf_rate_hz,
            params.markers_rate_hz,
            params.trail_duration,
        )
        self.visuals.publish_static(time.time_ns())
        self.get_logger().info(self.visuals.tf_log)
        self.get_logger().info(
            f"robot {self.model.name} ({self.model.dof} joints) at {self.rate_hz:g} Hz, plant {self.plant.name}, "
            f"q0 = {np.round(self.plant.q, 4).tolist()}, frame {self.base_frame!r}"
        )
        self.start_loop(self.rate_hz, self._cycle, params.realtime_priority, params.scheduler_slice)

    def _set_parameters(self, params: RobotStateParams) -> None:
        """The tunable parameters of ``params`` (at start, and on a live change: the next cycle uses them)."""
        self.command_timeout_ns = int(params.command_timeout * 1e9)
        self._diagnostics_period_ns = period_ns(params.diagnostics_rate_hz)

    def _description_text(self, params: RobotStateParams) -> str:
        """The URDF to publish: the file as given, as robot_state_publisher does (with one element naming the
        chain when ``tip_link``/``tool_link`` chose it), or one generated from a robot YAML."""
        path = resolve_robot_path(params.robot) if params.robot else None
        self._from_urdf = path is not None and is_urdf_file(path)
        if not self._from_urdf:
            return model_to_urdf(self.model)
        text = path.read_text(encoding="utf-8", errors="replace")
        if params.tip_link or params.tool_link:
            from manip_kin.core.urdf.document import UrdfTree

            tip = params.tip_link or UrdfTree(text, str(path)).default_tip(self.model.base_frame)
            text = with_chain_hint(text, tip, params.tool_link or None)
        return text

    def _take_commands(self, now_ns: int) -> list[tuple[int, np.ndarray]]:
        """The valid commands queued since the last cycle, oldest first, each with the loop time
        it was sent at (from the middleware's source timestamp; now where there is none)."""
        dof, arrived = self.model.dof, []
        system_to_loop = time.monotonic_ns() - time.time_ns()
        while (taken := self._command_sub.take_timed(raw=True)) is not None:
            values = decode_float64_array(taken[0])
            problem = command_problem(values, dof, max_abs=self._max_command)
            if problem is not None:
                self.rejected_commands += 1
                self._warn(
                    problem.kind,
                    f"rejected {self._command_sub.subscription.topic_name}: {problem}; keeping the previous command",
                )
                continue
            arrived.append((taken[1] + system_to_loop if taken[1] else now_ns, values))
        return arrived

    def publish_safe_output(self) -> None:
        """After a failed cycle: hold position (drop the command; the state again, at zero velocity)."""
        self._held = None
        plant = self.plant
        stamp_ns = self.ros_time_ns()
        zeros = [0.0] * self.model.dof
        self._joint_state_pub.publish(
            self._joint_state_cdr.encode_values(stamp_ns, plant.q_values, zeros, plant.effort_values and zeros)
        )

    def _cycle(self, now_ns: int) -> None:
        arrived = self._take_commands(now_ns)
        # Through a stall of this process the arm moves as hardware taking each command at its
        # own cycle would: the stall's queued commands replayed on the loop's schedule, each
        # until it times out (plant.held_commands).
        last_ns, self._last_cycle_ns = self._last_cycle_ns, now_ns
        segments, self._held = held_segments(
            last_ns or now_ns, now_ns, self._period_ns, self._held, arrived, self.command_timeout_ns
        )
        plant = self.plant
        if self._with_effort:
            self._take_scene()
        for segment in segments:
            plant.step(segment.values, segment.seconds)
        if self._with_effort:
            self._note_contact(plant.take_contact())

        # The state is the arm's at the cycle's start (integrated up to it): stamped with that
        # time, not the publishing time, which is later by a varying delay (under load, up to
        # 0.5 ms: 0.2 mm at 0.4 m/s, which a controller predicting from the stamp took for error).
        stamp_ns = self.ros_time_at(now_ns)
        self._joint_state_pub.publish(
            self._joint_state_cdr.encode_values(stamp_ns, plant.q_values, plant.qdot_values, plant.effort_values)
        )
        self._ee_pose_pub.publish(self._pose_cdr.encode_values(stamp_ns, plant.ee_values))
        self._tool_pose_pub.publish(self._pose_cdr.encode_values(stamp_ns, plant.tool_values))
        self._ee_twist_pub.publish(self._twist_cdr.encode_values(stamp_ns, plant.ee_twist_values))
        self._tool_twist_pub.publish(self._twist_cdr.encode_values(stamp_ns, plant.tool_twist_values))
        self.visuals.cycle(now_ns, stamp_ns, plant.q_values, plant.tool_values)

        if self._diagnostics_period_ns and now_ns - self._last_diagnostics_ns >= self._diagnostics_period_ns:
            self._last_diagnostics_ns = now_ns
            self._publish_diagnostics(stamp_ns, now_ns)

    def _take_scene(self) -> None:
        """Apply new collision_objects arrays; the plant rebuilds its scene when it changed."""
        changed = False
        while (msg := self._scene_sub.take()) is not None:
            changed = True
            for problem in apply_marker_array(self.scene, msg, self.base_frame):
                self._warn("scene", f"{self._scene_sub.subscription.topic_name}: {problem}")
        if not changed:
            return
        try:
            if self.plant.set_scene(self.scene):
                self.get_logger().info(f"scene: {len(self.scene)} obstacle(s) placed in the physics model")
        except ValueError as error:  # MuJoCo refused to compile it (a degenerate mesh...): the old scene stays
            self._warn("scene", f"the scene could not be placed in the physics model: {error}")

    def _note_contact(self, report) -> None:
        """Keep the strongest contact until the next diagnostics; count contact onsets."""
        if report is None:
            self._in_contact = False
            return
        if not self._in_contact:
            self.contact_events += 1
            self._in_contact = True
        if self._contact is None or report.force > self._contact.force:
            self._contact = report

    def _contact_values(self) -> tuple[list[tuple[str, str]], str]:
        """The contact keys of /diagnostics (none for the kinematic plant) and the pair in contact ("" when none)."""
        if not self._with_effort:
            return [], ""
        contact, self._contact = self._contact, None
        pair = f"{contact.link} | {contact.obstacle}" if contact else ""
        return [
            ("contact_force_max", f"{contact.force:.3f}" if contact else "0"),
            ("contact_pair", pair),
            ("contact_events", str(self.contact_events)),
            ("obstacles", str(len(self.scene))),
            ("efforts", ",".join(f"{e:.3f}" for e in self.plant.effort_values)),
        ], pair

    def _publish_diagnostics(self, stamp_ns: int, now_ns: int) -> None:
        plant, held = self.plant, self._held
        if held is None:
            command_state = "none yet"
        else:
            command_state = "fresh" if now_ns - held.taken_ns <= self.command_timeout_ns else "stale (counted as zero)"
        limited = [self.model.joint_names[i] for i in np.flatnonzero(plant.at_limit)]
        values = [
            ("robot", self.model.name),
            ("command", command_state),
            ("command_age_s", f"{(now_ns - held.taken_ns) * 1e-9:.4f}" if held is not None else "inf"),
            ("rejected_commands", str(self.rejected_commands)),
            ("joints_at_limit", ",".join(limited)),
            ("velocity_scale", f"{plant.velocity_scale:.4f}"),
            ("loop_error", self.loop_error()),
            ("plant", self.plant.name),
        ]
        contact, pair = self._contact_values()
        values += contact + stats_key_values(self.loop.stats())
        level = self.diagnostic_level("warn" if limited or self.rejected_commands or pair else "ok")
        message = f"{command_state}; contact {pair}" if pair else command_state
        self.publish_status(level, message, values, stamp_ns)


def main(argv=None) -> int:
    """Entry point of the ``robot_state`` executable."""
    return run_node(RobotStateNode, USAGE, argv, on_shutdown=lambda node: node.stop())


if __name__ == "__main__":
    sys.exit(main())
