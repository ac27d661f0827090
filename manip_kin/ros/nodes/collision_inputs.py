"""``cartesian_controller``'s collision avoidance: ``collision_objects``, the QP law, ``blocked``, status.

With ``collision_avoidance`` (or a ``posture_reference``) the controller steps
:class:`~manip_kin.control.qp.law.QpController` for pose goals and twist commands instead of the plain
:class:`~manip_kin.control.resolved_rate.CartesianController` (whose fast path stays as it is otherwise);
with ``collision_avoidance`` also for joint references and jogs
(:meth:`~manip_kin.control.qp.law.QpController.joint_step`, instead of
:func:`~manip_kin.control.joint_tracking.joint_tracking_step`), so no command kind bypasses the
collision limit:

* the collision model is built once at start from the robot's URDF (the ``robot`` file, or
  the text on ``robot_description``), with ``srdf`` and ``mesh_search_path``;
* ``collision_objects`` (visualization_msgs/MarkerArray in the base frame) is polled by the
  loop: every queued array is applied in order (markers are incremental), refusals are
  logged throttled; the checker takes the scene in the loop thread, so nothing in a callback
  touches the scene or the checker;
* every ~50 ms, :func:`~manip_kin.control.qp.blocked.blocked_by` over the last 0.3 s of pose steps
  (:func:`~manip_kin.control.qp.blocked.joint_blocked_by` over joint-reference steps) says
  whether a collision constraint holds the arm off its goal: the supervisor then halts in
  ``blocked`` (the commands come to rest through the command filter) until a new goal; twist
  commands and jogs are only held at the safety distance (a velocity command has no goal to block);
* ``/diagnostics`` gets ``nearest_pair``, ``nearest_distance``, ``qp_status``,
  ``qp_fallbacks``, ``active_constraints``, and ``markers`` a LINE_LIST between the nearest
  pair's witness points (namespace ``collision``), green at the influence distance, red at
  the safety distance.

The QP's own acceleration box stays off: the command filter limits acceleration and jerk of
every command the node publishes.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.collision.distances import CollisionChecker
from manip_kin.control.joint_limits import JointLimits
from manip_kin.control.qp.blocked import Blocked, blocked_by, joint_blocked_by
from manip_kin.control.qp.law import QpConfig, QpController, QpJointOutput, QpOutput, QpReport
from manip_kin.control.qp.tasks import PostureTask
from manip_kin.control.resolved_rate import CartesianController
from manip_kin.core.scene import Scene
from manip_kin.ros.nodes.scene_input import SCENE_VERDICT_KEYS, SceneInput, node_collision_checker, node_collision_model
from manip_kin.ros.runtime.param_struct import ParamStruct

#: Seconds of pose (or joint) steps :func:`blocked_by` looks at, and how often it looks [ns].
BLOCKED_WINDOW_S = 0.3
BLOCKED_EVERY_NS = 50_000_000
#: Pose steps further apart than this are not one history (a halt or other commands between);
#: a loaded machine's late cycles (tens of ms) are not such a gap [ns].
HISTORY_GAP_NS = 100_000_000
MARKER_NS = "collision"


class CollisionLaw:
    """The QP law with the plain law's interface (``step(q, goal, twist, horizon)``, ``frame_index``,
    ``task``, ``config``), so pose goals and twist commands call either the same way; and
    :meth:`joint_step` for joint references and jogs. ``command_state()`` gives the node's
    command filter state, which the dampers count the filter's braking from."""

    def __init__(self, qp: QpController, plain: CartesianController, dt: float, command_state):
        self.qp = qp
        self.plain = plain
        self.dt = dt
        self.command_state = command_state
        self.frame_index = plain.frame_index
        self.task = plain.task
        self.config = plain.config

    def step(self, q, goal_pose, goal_twist=None, horizon=None) -> QpOutput:
        """One QP step over the control period (the QP's position limit has its own gain, not a horizon)."""
        return self.qp.step(q, goal_pose, goal_twist, self.dt, self.command_state())

    def joint_step(self, q, q_reference, qdot_reference, gain: float) -> QpJointOutput:
        """One QP step towards a joint reference over the control period."""
        return self.qp.joint_step(q, q_reference, qdot_reference, gain, self.dt, self.command_state())


class CollisionInputs:
    """The collision side of one controller node (its loop thread only, but :meth:`configure`).

    Args:
        node: the controller node (its ``model``, ``base_frame``, ``rate_hz`` are read).
        params: the node's checked parameters.
        warn: a :class:`~manip_kin.ros.runtime.throttled_log.ThrottledLog` for refusals.

    Raises:
        ManipKinError: no URDF for collision_avoidance, a bad SRDF or a mesh not found (the
            node exits with code 2 and the message).
    """

    def __init__(self, node, params: ParamStruct, warn):
        self.node = node
        self.enabled = bool(params.collision_avoidance)
        self.checker: CollisionChecker | None = None
        self.scene_input: SceneInput | None = None
        self._history: deque[QpOutput] = deque(maxlen=max(2, int(BLOCKED_WINDOW_S * node.rate_hz)))
        self._last_check_ns = 0
        self._last_record_ns = 0
        self._marker_pub = None
        self._marker_shown = False
        if not self.enabled:
            return
        collision_model = node_collision_model(node, params, "collision_avoidance", params.collision_pair_samples)
        self.checker = node_collision_checker(node, collision_model, params)
        self.scene_input = SceneInput(node, self.checker, warn)
        self._marker_pub = node.create_publisher(MarkerArray, "markers", 10)
        node.get_logger().info(
            f"collision avoidance: {len(collision_model.geometries)} shapes on {len(collision_model.links)} links, "
            f"{len(collision_model.pairs.checked)} link pairs checked "
            f"({'SRDF ' + params.srdf if params.srdf else 'pairs by sampling'}); obstacles on "
            f"{self.scene_input.topic}"
        )

    @property
    def law(self) -> CollisionLaw | None:
        """The QP law the node steps now, or None (the plain law)."""
        law = getattr(self.node, "law", None)
        return law if isinstance(law, CollisionLaw) else None

    @property
    def joint_law(self) -> CollisionLaw | None:
        """The QP law for joint references and jogs while collision avoidance is on, or None
        (the plain joint tracking law: a posture alone has nothing to add to a joint reference)."""
        return self.law if self.enabled else None  # off: one attribute test on the fast path

    @property
    def scene(self) -> Scene:
        """The obstacles taken so far (empty without collision avoidance)."""
        return self.scene_input.scene if self.scene_input is not None else Scene()

    # --- configuration --------------------------------------------------------------------------

    def configure(self, model, params: ParamStruct, plain: CartesianController, dt: float, limits: JointLimits):
        """The law the controller is to step: the QP (collision avoidance or a posture), else
        ``plain``. Nothing changes here: the node swaps its ``law`` once its whole
        configuration is built (a refused change keeps the old one). ``limits``: the command
        filter's, whose braking the dampers count.

        Raises:
            ManipKinError: a posture of the wrong length, distances that do not fit (the
                influence distance not above the safety distance).
        """
        reference = params.posture_reference
        posture = None
        if reference:
            posture = PostureTask(np.array(reference, dtype=float), params.posture_gain, params.posture_weight)
        if not (self.enabled or posture is not None):
            return plain
        config = QpConfig(
            controller=plain.config,
            position_margin=params.position_limit_margin,
            max_acceleration=None,  # the command filter limits acceleration and jerk
            posture=posture,
            collision_safety_distance=params.collision_safety_distance,
            influence_distance=params.collision_influence_distance,
            collision_gain=params.collision_gain,
            braking=limits,
        )
        qp = QpController(model, config, self.checker)
        if qp.collision_limit is not None:
            self.node.get_logger().info(
                f"collision damper: a command held up to {qp.collision_limit.hold_time:.3g} s (a stalled loop, the arm "
                "moving on the last command until its timeout) cannot take a pair within collision_safety_distance; "
                "keep the arm's command timeout below it"
            )
        if self.law is not None:
            qp.fallback_count = self.law.qp.fallback_count  # counted over the node's life
        return CollisionLaw(qp, plain, dt, lambda: self.node.command_filter.state)

    def switch_problem(self) -> str | None:
        """Why ``~/reload_robot_description`` cannot switch models (the geometry is built at start)."""
        if self.enabled:
            return "collision_avoidance: the collision geometry was built at start; restart the node for a new URDF"
        return None

    # --- each cycle -----------------------------------------------------------------------------

    def take(self) -> bool:
        """Apply the queued ``collision_objects`` (see :class:`~manip_kin.ros.nodes.scene_input.SceneInput`);
        True when an array was taken."""
        return self.scene_input is not None and self.scene_input.take()

    def pose_step_done(self, output, now_ns: int) -> Blocked | None:
        """Keep a pose step's output; every ~50 ms, the blocking pair over the last 0.3 s, if any
        (the goal's tolerances are the node's; a component the task does not control never stalls)."""
        if not isinstance(output, QpOutput):
            return None
        node = self.node
        tolerances = (
            node.position_tolerance if node.controller.task.position_rows else math.inf,
            node.orientation_tolerance if node.controller.task.orientation_rows else math.inf,
        )
        return self._blocked(
            output,
            now_ns,
            lambda history: blocked_by(history, position_tolerance=tolerances[0], orientation_tolerance=tolerances[1]),
        )

    def joint_step_done(self, output, now_ns: int) -> Blocked | None:
        """As :meth:`pose_step_done` for a joint-reference step (the node's ``joint_tolerance``)."""
        if not isinstance(output, QpJointOutput):
            return None
        tolerance = self.node.joint_tolerance
        return self._blocked(output, now_ns, lambda history: joint_blocked_by(history, tolerance=tolerance))

    def _blocked(self, output: QpReport, now_ns: int, judge) -> Blocked | None:
        history = self._history
        # The steps must be consecutive and of one kind: a halt or another command came between.
        if now_ns - self._last_record_ns > HISTORY_GAP_NS or (history and type(history[-1]) is not type(output)):
            history.clear()
        self._last_record_ns = now_ns
        history.append(output)
        if len(history) < history.maxlen or now_ns - self._last_check_ns < BLOCKED_EVERY_NS:
            return None
        self._last_check_ns = now_ns
        blocked = judge(history)
        if blocked is not None:
            history.clear()
        return blocked

    def restart(self) -> None:
        """A new goal after a quiet spell: progress is measured from it on."""
        self._history.clear()

    # --- status ---------------------------------------------------------------------------------

    def report(self, stamp, output) -> list[tuple[str, str]]:
        """The ``/diagnostics`` values of the last step's ``output`` (empty strings without the QP
        law), and the nearest pair's marker on ``markers`` (deleted once no pair is near any more)."""
        if self.scene_input is not None:
            scene = self.scene_input.report()
        else:  # no scene is taken: the same keys, nothing in them
            scene = [("obstacles", "0"), ("rejected_obstacles", "0")] + [(key, "") for key in SCENE_VERDICT_KEYS]
        if self.law is None or not isinstance(output, QpReport):
            keys = ("nearest_pair", "nearest_distance", "nearest_points", "qp_status", "qp_fallbacks", "narrow_phase")
            return [(key, "") for key in (*keys, "active_constraints", "collision_safety_distance")] + scene
        nearest = self._nearest(output)
        self._publish_marker(stamp, nearest)
        points = "" if nearest is None else " ".join(f"{v:.5f}" for v in (*nearest.point_first, *nearest.point_second))
        return [
            ("nearest_pair", "-".join(output.nearest_pair) if output.nearest_pair else ""),
            ("nearest_distance", f"{output.nearest_distance:.6f}" if math.isfinite(output.nearest_distance) else ""),
            ("nearest_points", points),
            ("qp_status", str(output.status)),
            ("qp_fallbacks", str(output.fallback_count)),
            ("narrow_phase", self.checker.narrow_phase.name if self.checker is not None else ""),
            ("active_constraints", ",".join(output.active_constraints)),
            ("collision_safety_distance", f"{self.law.qp.config.collision_safety_distance:g}"),
            *scene,
        ]

    def _publish_marker(self, stamp, nearest) -> None:
        if self._marker_pub is None or (nearest is None and not self._marker_shown):
            return
        self._marker_shown = nearest is not None
        marker = Marker()
        marker.header.stamp = stamp
        marker.header.frame_id = self.node.base_frame
        marker.ns, marker.id = MARKER_NS, 0
        if nearest is None:
            marker.action = Marker.DELETE
        else:
            marker.type, marker.action = Marker.LINE_LIST, Marker.ADD
            marker.pose.orientation.w = 1.0
            marker.scale.x = 0.005
            marker.points = [_point(nearest.point_first), _point(nearest.point_second)]
            config = self.law.qp.config
            red, green = distance_colour(nearest.distance, config.collision_safety_distance, config.influence_distance)
            marker.color.r, marker.color.g, marker.color.a = red, green, 1.0
        self._marker_pub.publish(MarkerArray(markers=[marker]))

    def _nearest(self, output):
        """The nearest pair with its witness points at the node's newest ``q`` (computed again at
        the status rate: the step's output keeps only the pair's names), or None."""
        if self.checker is None or self.node.inputs.q is None or output.nearest_pair is None:
            return None
        near = self.checker.pair_distances(self.node.inputs.q, self.law.qp.config.influence_distance)
        return min(near, key=lambda pair: pair.distance) if near else None


def distance_colour(distance: float, safety: float, influence: float) -> tuple[float, float]:
    """``(red, green)`` in 0..1: red at or below ``safety``, green at or beyond ``influence``."""
    share = min(max((distance - safety) / (influence - safety), 0.0), 1.0)
    return 1.0 - share, share


def _point(xyz):
    from geometry_msgs.msg import Point

    return Point(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
