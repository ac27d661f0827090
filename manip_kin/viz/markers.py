"""What the ``markers`` topic draws, without ROS: goal axes, planned path, tool trail, limit colours.

The node side (:mod:`manip_kin.ros.nodes.visuals`) copies these numbers into a
``visualization_msgs/MarkerArray``; everything that could be wrong is computed here.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from manip_kin.errors import InvalidArgumentError

# RGBA in [0, 1].
AXIS_COLOURS = ((1.0, 0.1, 0.1, 1.0), (0.1, 0.85, 0.1, 1.0), (0.15, 0.35, 1.0, 1.0))  # x red, y green, z blue
FREE_COLOUR = np.array([0.2, 0.8, 0.3, 1.0])  # green: far from both limits
LIMIT_COLOUR = np.array([0.95, 0.1, 0.1, 1.0])  # red: on a limit
WARN_COLOUR = np.array([1.0, 0.75, 0.0, 1.0])  # amber: inside the warning band


def axes_segments(pose: np.ndarray, length: float) -> tuple[np.ndarray, list[tuple[float, float, float, float]]]:
    """The three axes of ``pose`` (4x4, in base) as line segments ``length`` [m] long.

    Returns:
        ``(points, colours)``: points shape (6, 3) in base, pairs origin → axis tip in the
        order x, y, z; one RGBA per point (a LINE_LIST colours each vertex).
    """
    pose = np.asarray(pose, dtype=float)
    origin = pose[:3, 3]
    points = np.empty((6, 3))
    colours = []
    for axis in range(3):
        points[2 * axis] = origin
        points[2 * axis + 1] = origin + length * pose[:3, axis]
        colours += [AXIS_COLOURS[axis], AXIS_COLOURS[axis]]
    return points, colours


def limit_colours(q, lower, upper, warn_fraction: float = 0.1) -> np.ndarray:
    """One RGBA per joint: green when free, amber to red inside the last ``warn_fraction`` of the range.

    A joint at (or beyond) a limit is pure red; inside the warning band the colour blends
    from amber to red with the distance to the nearer limit. Joints with an infinite range
    (continuous) are always green.

    Returns:
        Shape (n, 4).
    """
    q, lower, upper = (np.asarray(v, dtype=float) for v in (q, lower, upper))
    colours = np.tile(FREE_COLOUR, (q.size, 1))
    for i in range(q.size):
        span = upper[i] - lower[i]
        if not math.isfinite(span):
            continue
        band = warn_fraction * span
        distance = min(q[i] - lower[i], upper[i] - q[i])
        if distance <= 0.0 or band <= 0.0:
            colours[i] = LIMIT_COLOUR
        elif distance < band:
            blend = distance / band  # 1 at the band's edge, 0 on the limit
            colours[i] = blend * WARN_COLOUR + (1.0 - blend) * LIMIT_COLOUR
    return colours


class ToolTrail:
    """The tool positions of the last ``duration_s`` seconds, sampled at most every ``spacing_s``.

    Args:
        duration_s: how far back the trail reaches [s], > 0.
        spacing_s: least time between two kept points [s], >= 0.
    """

    def __init__(self, duration_s: float, spacing_s: float = 0.02):
        if not (duration_s > 0 and math.isfinite(duration_s)) or not spacing_s >= 0:
            raise InvalidArgumentError(
                f"trail duration {duration_s!r} s and spacing {spacing_s!r} s; valid: duration > 0, spacing >= 0"
            )
        self.duration_ns = int(duration_s * 1e9)
        self.spacing_ns = int(spacing_s * 1e9)
        self._points: deque[tuple[int, float, float, float]] = deque()

    def add(self, stamp_ns: int, position) -> None:
        """Add the tool position [m] at ``stamp_ns``; points older than the duration fall off."""
        points = self._points
        if points and stamp_ns < points[-1][0]:
            points.clear()  # time went backwards (a replay restarted): start a new trail
        if points and stamp_ns - points[-1][0] < self.spacing_ns:
            return
        x, y, z = (float(v) for v in position)
        points.append((stamp_ns, x, y, z))
        while points and stamp_ns - points[0][0] > self.duration_ns:
            points.popleft()

    def positions(self) -> np.ndarray:
        """The kept positions, oldest first, shape (m, 3)."""
        return np.array([p[1:] for p in self._points]).reshape(-1, 3)
