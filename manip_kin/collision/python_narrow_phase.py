"""The narrow phase through coal's Python bindings: the fallback where the native one cannot be
built, and the reference the tests hold it to (:mod:`manip_kin.collision.narrow_phase` describes
both and the columns they return)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from manip_kin.collision.geometry import CollisionShape

#: Columns per pair of :meth:`PythonNarrowPhase.compute` (their layout: :mod:`manip_kin.collision.narrow_phase`).
ROW_WIDTH = 22
_UNSET = [0.0] * (ROW_WIDTH - 1)


class PythonNarrowPhase:
    """The narrow phase through coal's Python bindings (see :mod:`manip_kin.collision.narrow_phase`).

    Args:
        robot_shapes: the robot's shapes, placed at each :meth:`compute`.
    """

    name = "python"

    def __init__(self, robot_shapes: Sequence[CollisionShape]):
        import coal

        self._coal = coal
        self._robot_shapes = list(robot_shapes)
        self._robot_count = len(self._robot_shapes)
        self._robot_transforms = [coal.Transform3s() for _ in self._robot_shapes]
        self._request, self._result = coal.DistanceRequest(), coal.DistanceResult()
        self.set_scene([], np.zeros((0, 4, 4)), np.zeros((0, 2), dtype=int))

    def set_scene(self, obstacle_shapes: Sequence[CollisionShape], obstacle_poses: np.ndarray, pairs) -> None:
        """The obstacles, their poses in base (shape (m, 4, 4)) and the pairs :meth:`compute` is
        asked for: shape indices ``(first, second)``, robot shapes first, then the obstacles,
        shape (P, 2). Replaces the previous scene."""
        coal = self._coal
        # Kept: a functor holds bare pointers to its two shapes, not references.
        self._shapes = shapes = self._robot_shapes + list(obstacle_shapes)
        self._transforms = self._robot_transforms + [
            coal.Transform3s(pose[:3, :3], pose[:3, 3]) for pose in np.asarray(obstacle_poses).reshape(-1, 4, 4)
        ]
        self._first, self._second = np.asarray(pairs, dtype=int).reshape(-1, 2).T.tolist()
        self._functors = [
            coal.ComputeDistance(shapes[a].coal_shape, shapes[b].coal_shape) for a, b in zip(self._first, self._second)
        ]

    def compute(self, placed: np.ndarray, rows: Sequence[int], cutoff: float) -> np.ndarray:
        """The :data:`ROW_WIDTH` columns of each pair in ``rows``, shape (len(rows), 22); only the
        distance (column 0) is filled for a pair at ``cutoff`` or beyond.

        Args:
            placed: the robot shapes' ``[R | t | c]`` in base, shape (G, 3, 5).
            rows: pair indices.
            cutoff: [m].
        """
        transforms, count = self._transforms, self._robot_count
        done = [False] * count
        first, second = self._first, self._second
        functors, request, result = self._functors, self._request, self._result
        lines = []
        for row in rows:
            a, b = first[row], second[row]
            if not done[a]:
                transforms[a].setTransform(placed[a, :, :3], placed[a, :, 3])
                done[a] = True
            if b < count and not done[b]:
                transforms[b].setTransform(placed[b, :, :3], placed[b, :, 3])
                done[b] = True
            result.clear()
            distance = functors[row](transforms[a], transforms[b], request, result)
            if distance >= cutoff:
                lines.append([distance] + _UNSET)
                continue
            # Plain floats: a handful of products per pair cost less than numpy calls.
            ax, ay, az = result.getNearestPoint1().tolist()
            bx, by, bz = result.getNearestPoint2().tolist()
            nx, ny, nz = result.normal.tolist()
            lines.append(
                [distance, ax, ay, az, bx, by, bz, nx, ny, nz]
                + [ay * nz - az * ny, az * nx - ax * nz, ax * ny - ay * nx, nx, ny, nz]
                + [by * nz - bz * ny, bz * nx - bx * nz, bx * ny - by * nx, nx, ny, nz]
            )
        return np.array(lines, dtype=float).reshape(len(lines), ROW_WIDTH)
