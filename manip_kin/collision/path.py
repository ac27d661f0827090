"""Where a planned path first comes too close: for the generator's reach check."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from manip_kin.collision.collision_model import CollisionModel
from manip_kin.collision.distances import CollisionChecker
from manip_kin.collision.pair_distance import PairDistance
from manip_kin.core.model import RobotModel
from manip_kin.core.scene import Scene


class PathCollision(NamedTuple):
    """The first configuration of a path closer than the clearance.

    Attributes:
        fraction: where along the path, 0 (start) .. 1 (end), by configuration index.
        pair: the pair, as ``(link, link or obstacle:ns/id)``.
        distance: its distance there [m] (negative: penetration).
        index: the configuration's index in the path.
    """

    fraction: float
    pair: tuple[str, str]
    distance: float
    index: int

    @property
    def reason(self) -> str:
        """The refusal in words, e.g. ``at 42 % of the way panda_hand-obstacle:cell/1 are 0.003 m apart``."""
        where = f"at {100.0 * self.fraction:.0f} % of the way"
        if self.distance < 0.0:
            return f"{where} {self.pair[0]} and {self.pair[1]} collide ({-self.distance:.3f} m deep)"
        return f"{where} {self.pair[0]} and {self.pair[1]} are {self.distance:.3f} m apart"


def first_collision_along(
    model: RobotModel,
    collision_model: CollisionModel,
    scene: Scene | None,
    configurations,
    clearance: float = 0.0,
    checker: CollisionChecker | None = None,
) -> PathCollision | None:
    """The first of ``configurations`` where a checked pair is nearer than ``clearance``, or None.

    Args:
        model: the robot.
        collision_model: its shapes and pairs.
        scene: obstacles (None: self-collision only).
        configurations: the path, sampled densely enough that no obstacle fits between two
            samples (the caller's choice: e.g. every 5 mm of tool travel), shape (N, n).
        clearance: the distance below which a pair counts [m] (0: contact;
            ``collision_safety_distance`` for the controller's margin).
        checker: a checker to reuse (its scene is updated from ``scene``); default: a new one.
    """
    path = np.asarray(configurations, dtype=float)
    if path.ndim != 2 or path.shape[1] != model.dof:
        from manip_kin.errors import InvalidArgumentError

        raise InvalidArgumentError(f"configurations have shape {path.shape}; valid: (N, {model.dof})")
    checker = checker or CollisionChecker(model, collision_model)
    if scene is not None:
        checker.update_scene(scene)
    last = max(len(path) - 1, 1)
    for index, q in enumerate(path):
        near: list[PairDistance] = checker.pair_distances(q, clearance)
        if near:
            nearest = min(near, key=lambda pair: pair.distance)
            return PathCollision(index / last, nearest.pair, nearest.distance, index)
    return None
