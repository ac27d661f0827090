"""Warm starts for IK restarts: a table of configurations ranked by pose distance to a target.

Random restarts from anywhere in the joint space mostly end against a joint limit on arms
like the Panda. Starting instead from the sampled configurations whose frame pose is nearest
the target (a fixed table per robot, frame and task) roughly halves the iterations per
target. The pose distance is ``|Δp|² + (ORIENTATION_SCALE·reach)²·|ΔR|²_F`` over the task's
components (``|ΔR|²_F = 4 (1 - cos θ)``, θ the angle between the orientations).
"""

from __future__ import annotations

import math

import numpy as np

from manip_kin.core.kinematics import batch_frame_pose
from manip_kin.core.model import RobotModel

TABLE_SIZE = 3000
ORIENTATION_SCALE = 0.3
# The table's own random stream: a fixed constant of its own, so that it never replays the
# stream of a seed a caller uses for targets (default_rng(0) draws would put the targets'
# own configurations in the table).
TABLE_STREAM = 0x1C5EED7AB1E


class SeedTable:
    """TABLE_SIZE uniform samples within the limits and their frame poses, built on first use.

    Args:
        model, frame_index: the robot and the frame IK solves for.
        sample_low, sample_span: per joint, the sampled range's lower end and width
            [rad | m] (finite stand-ins for continuous joints).
        position, orientation: whether the task constrains the position / orientation.
        reach: an upper bound of the frame's distance from the first joint [m].
    """

    def __init__(
        self,
        model: RobotModel,
        frame_index: int,
        sample_low: list,
        sample_span: list,
        position: bool,
        orientation: bool,
        reach: float,
    ):
        self._build = (model, frame_index, sample_low, sample_span, position, orientation, reach)
        self._table: tuple[np.ndarray, ...] | None = None

    def _built(self) -> tuple[np.ndarray, ...]:
        if self._table is None:
            model, frame_index, sample_low, sample_span, position, orientation, reach = self._build
            samples = np.random.default_rng(TABLE_STREAM).random((TABLE_SIZE, model.dof))
            configurations = np.array(sample_low) + samples * np.array(sample_span)
            poses = batch_frame_pose(model, configurations, frame_index)
            weights = np.array([1.0 if position else 0.0] * 3 + [ORIENTATION_SCALE * reach if orientation else 0.0] * 9)
            features = np.hstack([poses[:, :3, 3], poses[:, :3, :3].reshape(-1, 9)]) * weights
            # float32: ranking needs no more, and the product over the table is ~30 % cheaper
            self._table = (
                configurations,
                features.astype(np.float32),
                (0.5 * np.square(features).sum(axis=1)).astype(np.float32),
                weights.astype(np.float32),
            )
        return self._table

    @property
    def configurations(self) -> np.ndarray:
        """The table's configurations, shape (TABLE_SIZE, n)."""
        return self._built()[0]

    def distances(self, goal: list) -> np.ndarray:
        """Pose distance of every entry to ``goal`` (4x4 nested lists), up to a constant;
        :meth:`pop_nearest` takes entries from it, nearest first."""
        _, features, half_norms, weights = self._built()
        target = np.array([goal[0][3], goal[1][3], goal[2][3], *goal[0][:3], *goal[1][:3], *goal[2][:3]])
        # A goal beyond float32's range (3e38 m) ranks as one 1e18 m away: far from every entry alike.
        target = np.clip(target, -1e18, 1e18).astype(np.float32)
        # ½|f - t|² - ½|t|²: one matrix-vector product ranks the table.
        return half_norms - features @ (target * weights)

    def pop_nearest(self, distances: np.ndarray) -> list:
        """The not yet used entry nearest the goal of ``distances`` (then marked as used)."""
        index = int(distances.argmin())
        distances[index] = math.inf
        return self._built()[0][index].tolist()

    def nearest(self, goal: list, count: int) -> list[list]:
        """The ``count`` entries nearest ``goal``, nearest first."""
        distances = self.distances(goal)
        return [self.pop_nearest(distances) for _ in range(min(count, len(distances)))]
