"""What a node with collision checking shares: its collision model and the ``collision_objects`` it polls.

* :func:`node_collision_model`: the robot's collision model from the URDF the node's model
  came from (the ``robot`` file, or the text on ``robot_description``); a bundled robot or a
  robot YAML has no geometry and is refused;
* :func:`node_collision_checker`: its checker, with a log line of the narrow phase it runs;
* :class:`SceneInput`: ``collision_objects`` polled by the loop thread, every queued array
  applied in order (markers are incremental: ADD, DELETE, DELETEALL), refusals logged
  throttled, and the checker given the scene in the same thread (nothing in a callback touches
  the scene or the checker).
"""

from __future__ import annotations

import time
from pathlib import Path

from visualization_msgs.msg import MarkerArray

from manip_kin.collision.collision_model import CollisionModel, load_collision_model
from manip_kin.collision.distances import CollisionChecker
from manip_kin.collision.narrow_phase import native_build_pending
from manip_kin.core.robot_files import is_urdf_file
from manip_kin.core.scene import Scene
from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.runtime.param_struct import ParamStruct
from manip_kin.ros.runtime.polling import PolledSubscription
from manip_kin.ros.wire.messages import stamp_key
from manip_kin.ros.wire.scene_messages import TOPIC, apply_marker_array

#: Queued ``collision_objects`` arrays kept for the loop (markers are incremental: keep them all).
SCENE_DEPTH = 50
#: How often the loop polls ``collision_objects`` [ns]: a scene changes at a person's pace, and
#: an empty poll in a 1 kHz loop cost the collision-aware controller 5 % of its cycle (its
#: caches are cold between cycles). 10 ms leaves room for SCENE_DEPTH arrays per poll.
SCENE_POLL_NS = 10_000_000
#: The ``/diagnostics`` keys of a scene's verdict (:meth:`SceneInput.report`).
SCENE_VERDICT_KEYS = ("obstacles_stamp", "rejected_obstacles_stamp", "last_obstacle_rejection")


def robot_urdf(params: ParamStruct, description_text: str | None, feature: str) -> str | Path:
    """The URDF the collision geometry comes from: the ``robot`` file, or the description's text.

    Raises:
        InvalidArgumentError: ``robot`` names a bundled robot or a robot YAML (no geometry).
    """
    robot = params.robot
    if not robot:
        return description_text
    if Path(robot).is_file() and is_urdf_file(robot):
        return Path(robot)
    raise InvalidArgumentError(
        f"{feature} needs the robot's URDF <collision> geometry; robot {robot!r} is not a URDF file; "
        "valid: a URDF path, or robot '' (the URDF on robot_description)"
    )


def node_collision_model(node, params: ParamStruct, feature: str, samples: int | None = None) -> CollisionModel:
    """The collision model of ``node.model`` with the node's ``srdf`` and ``mesh_search_path``.

    Raises:
        ManipKinError: no URDF, a bad SRDF, a mesh not found (the node exits with code 2).
    """
    options = {"samples": samples} if samples is not None else {}
    return load_collision_model(
        node.model,
        robot_urdf(params, getattr(node, "robot_description_text", None), feature),
        srdf=params.srdf or None,
        mesh_search_path=params.mesh_search_path,
        **options,
    )


def node_collision_checker(node, collision_model: CollisionModel, params: ParamStruct) -> CollisionChecker:
    """The node's :class:`CollisionChecker`, and a log line saying which narrow phase it runs
    (the native one is compiled first where it has not been yet: about 10 s, once per machine)."""
    logger = node.get_logger()
    if native_build_pending():
        logger.info("compiling the native collision narrow phase (once per machine, about 10 s)")
    checker = CollisionChecker(node.model, collision_model, params.mesh_search_path)
    problem = checker.narrow_phase_problem
    logger.info(f"collision narrow phase: {checker.narrow_phase.name}" + (f" ({problem})" if problem else ""))
    return checker


class SceneInput:
    """``collision_objects`` into a :class:`~manip_kin.core.scene.Scene` and a checker (the loop thread only).

    Args:
        node: the node (its ``base_frame`` is read each time: obstacles must carry it).
        checker: the checker that takes the scene.
        warn: a :class:`~manip_kin.ros.runtime.throttled_log.ThrottledLog`.
    """

    def __init__(self, node, checker: CollisionChecker, warn):
        self.node = node
        self.checker = checker
        self.scene = Scene()
        #: Markers refused so far.
        self.refused = 0
        #: The stamp (:func:`~manip_kin.ros.wire.messages.stamp_key`) of the newest array taken,
        #: of its first marker; and of the newest array with a marker refused, with the reasons.
        self.taken_stamp = ""
        self.refused_stamp = ""
        self.last_refusal = ""
        self._warn = warn
        self.subscription = PolledSubscription(node, MarkerArray, TOPIC, SCENE_DEPTH)
        self._next_poll_ns = 0

    @property
    def topic(self) -> str:
        """The resolved topic name."""
        return self.subscription.subscription.topic_name

    def take(self) -> bool:
        """Every :data:`SCENE_POLL_NS`: apply every queued array in order; the checker takes the
        scene if it changed. True when an array was taken (its verdict is news to report)."""
        now_ns = time.monotonic_ns()
        if now_ns < self._next_poll_ns:
            return False
        self._next_poll_ns = now_ns + SCENE_POLL_NS
        taken = False
        while (msg := self.subscription.take()) is not None:
            taken = True
            stamp = stamp_key(msg.markers[0].header.stamp) if msg.markers else ""
            self.taken_stamp = stamp
            problems = apply_marker_array(self.scene, msg, self.node.base_frame)
            if problems:
                self.refused += len(problems)
                self.refused_stamp, self.last_refusal = stamp, "; ".join(problems)[:400]
                self._warn("collision_objects", f"refused on {self.topic}: {self.last_refusal}")
        if self.checker.update_scene(self.scene) and self.checker.scene_problems:
            self._warn("collision_scene", f"obstacles left out: {'; '.join(self.checker.scene_problems)[:400]}")
        return taken

    def report(self) -> list[tuple[str, str]]:
        """The scene's ``/diagnostics`` values: what was taken and what refused, and why."""
        verdict = (self.taken_stamp, self.refused_stamp, self.last_refusal)
        return [("obstacles", str(len(self.scene))), ("rejected_obstacles", str(self.refused))] + list(
            zip(SCENE_VERDICT_KEYS, verdict)
        )
