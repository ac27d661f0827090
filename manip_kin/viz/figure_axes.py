"""One rule for the 3D figures (plots, sweeps, animations): equal scales on x, y and z."""

from __future__ import annotations

import numpy as np

#: Smallest half-width of the cube [m], so that a single point still gets a readable plot.
MIN_HALF_WIDTH_M = 0.05


def equal_3d_axes(axis, points: np.ndarray) -> None:
    """Fit ``axis`` (a matplotlib 3D axis) to a cube around ``points`` (shape (N, 3), metres).

    Equal scales keep a straight line straight and the arm's proportions true; the axes are
    labelled in metres.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    centre = (points.max(axis=0) + points.min(axis=0)) / 2
    half = max(float((points.max(axis=0) - points.min(axis=0)).max()) / 2, MIN_HALF_WIDTH_M)
    axis.set_xlim(centre[0] - half, centre[0] + half)
    axis.set_ylim(centre[1] - half, centre[1] + half)
    axis.set_zlim(centre[2] - half, centre[2] + half)
    axis.set_box_aspect((1, 1, 1))
    axis.set_xlabel("x [m]")
    axis.set_ylabel("y [m]")
    axis.set_zlabel("z [m]")
