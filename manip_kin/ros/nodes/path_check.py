"""``trajectory_generator``'s collision check of a planned motion (parameter ``collision_check``).

A line's configurations come from the reach check (:func:`~manip_kin.motion.line_reach.check_line_reachable`,
a sample every centimetre and 0.05 rad), a joint trajectory is sampled every 0.01 rad (or m)
of its largest joint's travel; :func:`~manip_kin.collision.path.first_collision_along` finds
the first sample nearer than ``collision_safety_distance``, and the refusal says at what
percentage of the way and which pair.

An arm resting nearer than the safety distance (the controller holds it at about that
distance before an obstacle) could not start any motion: the clearance is then the start's
own distance less 1 mm, so a motion may leave that spot but not come closer, and never touch.
"""

from __future__ import annotations

import math

import numpy as np

from manip_kin.collision.path import first_collision_along
from manip_kin.ros.nodes.scene_input import SceneInput, node_collision_checker, node_collision_model
from manip_kin.ros.runtime.param_struct import ParamStruct

#: Joint travel between two samples of a joint trajectory [rad | m], and the most samples.
JOINT_STEP = 0.01
MAX_SAMPLES = 5000
#: A start nearer than the safety distance: the clearance is its distance less this [m].
START_SLACK = 1e-3


class PathCheck:
    """The generator's collision check (the loop thread only).

    Args:
        node: the generator node (``model``, ``base_frame`` are read).
        params: its checked parameters.
        warn: a :class:`~manip_kin.ros.runtime.throttled_log.ThrottledLog`.

    Raises:
        ManipKinError: no URDF for collision_check, a bad SRDF or a mesh not found (exit 2).
    """

    def __init__(self, node, params: ParamStruct, warn):
        self.enabled = bool(params.collision_check)
        self.safety_distance = params.collision_safety_distance
        self.scene_input: SceneInput | None = None
        if not self.enabled:
            return
        self.collision_model = node_collision_model(node, params, "collision_check")
        self.checker = node_collision_checker(node, self.collision_model, params)
        self.scene_input = SceneInput(node, self.checker, warn)
        node.get_logger().info(
            f"collision check of every motion: {len(self.collision_model.pairs.checked)} link pairs, "
            f"obstacles on {self.scene_input.topic}, clearance collision_safety_distance"
        )

    def take(self) -> None:
        """Apply the queued ``collision_objects``."""
        if self.scene_input is not None:
            self.scene_input.take()

    def problem(self, configurations: np.ndarray, progress: np.ndarray, what: str) -> str | None:
        """Why the motion through ``configurations`` (shape (N, n)) is refused, or None.

        Args:
            configurations: the samples, in order.
            progress: how far along each sample is, 0..1, shape (N,).
            what: ``line`` or ``joint trajectory``, for the message.
        """
        if not self.enabled or len(configurations) == 0:
            return None
        start = self.checker.pair_distances(configurations[0], self.safety_distance)
        clearance = self.safety_distance
        if start:
            clearance = max(min(pair.distance for pair in start) - START_SLACK, 0.0)
        hit = first_collision_along(
            self.checker.model, self.collision_model, None, configurations, clearance, self.checker
        )
        if hit is None:
            return None
        where = hit._replace(fraction=float(progress[hit.index]))
        return f"{what} not free of collision: {where.reason} (clearance {clearance:.3f} m)"


def joint_path(plan) -> tuple[np.ndarray, np.ndarray]:
    """Samples of a :class:`~manip_kin.motion.joint_trajectory.JointTrajectoryPlan` and their time fractions."""
    coarse = np.array([plan.sample(t)[0] for t in np.linspace(0.0, plan.duration, 50)])
    travel = float(np.abs(np.diff(coarse, axis=0)).max(axis=1).sum()) if len(coarse) > 1 else 0.0
    count = int(min(max(math.ceil(travel / JOINT_STEP) + 1, 50), MAX_SAMPLES))
    fractions = np.linspace(0.0, 1.0, count)
    return np.array([plan.sample(f * plan.duration)[0] for f in fractions]), fractions
