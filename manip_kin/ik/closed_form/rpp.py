"""Closed-form position IK of a revolute-prismatic-prismatic (RPP) arm.

Structure (detected from the geometry): joint 1 revolute, joints 2 and 3 prismatic along
non-parallel directions, not both perpendicular to joint 1's axis. In joint 1's frame (its
axis is z) the controlled point is ``Rz(q1) (a + q2 b + q3 c)``: the height fixes one linear
combination of ``q2, q3``, the distance from the axis gives a quadratic along the remaining
line, and ``q1`` is the angle between where the point is and where it must be. Two branches:
the two roots of the quadratic, named by the prismatic joint that differs between them
(``d3=smaller`` / ``d3=larger`` on the bundled rpp).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.core.rotations import invert_transform
from manip_kin.ik.closed_form.geometry import DIRECTION_TOLERANCE, ChainGeometry, parallel

REQUIRED_ROWS = (3, 4, 5)  # position; orientation is whatever the position fixes


@dataclass(frozen=True)
class RppSolver:
    """Precomputed closed form of an RPP arm (see the module docstring).

    Attributes:
        base_to_joint1: inverse of joint 1's frame at q1 = 0, shape (4, 4).
        offset, slide2, slide3: ``a``, ``b``, ``c`` in joint 1's frame, each shape (3,).
        line_point, line_direction: the solutions of the height equation are
            ``(q2, q3) = line_point · h + t · line_direction`` with ``h`` = target height - a_z.
        branch_joint: index (1 or 2) of the prismatic joint naming the branches.
        branch_name: that joint's name.
    """

    base_to_joint1: np.ndarray
    offset: np.ndarray
    slide2: np.ndarray
    slide3: np.ndarray
    line_point: np.ndarray
    line_direction: np.ndarray
    branch_joint: int
    branch_name: str

    structure = "rpp"
    required_rows = REQUIRED_ROWS

    def solve(self, target: np.ndarray, hint: np.ndarray) -> list[tuple[np.ndarray, str]]:
        """Every solution ``(q, branch)`` (limits not applied) for the target position in base."""
        goal = self.base_to_joint1[:3, :3] @ target[:3, 3] + self.base_to_joint1[:3, 3]
        height = goal[2] - self.offset[2]
        start = self.line_point * height
        # Horizontal part of a + q2 b + q3 c along the line: g + t h; |g + t h| = radius.
        g = self.offset[:2] + start[0] * self.slide2[:2] + start[1] * self.slide3[:2]
        h = self.line_direction[0] * self.slide2[:2] + self.line_direction[1] * self.slide3[:2]
        radius_sq = goal[0] ** 2 + goal[1] ** 2
        qa, qb, qc = float(h @ h), float(2.0 * g @ h), float(g @ g - radius_sq)
        discriminant = qb * qb - 4.0 * qa * qc
        if discriminant < -1e-12 * max(1.0, qb * qb):
            return []
        root = math.sqrt(max(0.0, discriminant))
        solutions = []
        for t in ((-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)):
            q23 = start + t * self.line_direction
            point = self.offset + q23[0] * self.slide2 + q23[1] * self.slide3
            if math.hypot(point[0], point[1]) < 1e-12 and math.hypot(goal[0], goal[1]) < 1e-12:
                q1 = float(hint[0])  # the point is on joint 1's axis: any q1 will do
            else:
                q1 = math.atan2(goal[1], goal[0]) - math.atan2(point[1], point[0])
            solutions.append(np.array([q1, q23[0], q23[1]]))
        values = [q[self.branch_joint] for q in solutions]
        names = ("smaller", "larger") if values[0] <= values[1] else ("larger", "smaller")
        return [(q, f"{self.branch_name}={name}") for q, name in zip(solutions, names)]


def detect_rpp(geometry: ChainGeometry) -> RppSolver | None:
    """The RPP closed form when the chain has that structure, else None."""
    revolute = geometry.revolute
    if geometry.dof != 3 or not revolute[0] or revolute[1] or revolute[2]:
        return None
    if parallel(geometry.axes[1], geometry.axes[2]):
        return None
    to_joint1 = invert_transform(geometry.moving_zero[0])
    rotation = to_joint1[:3, :3]
    slide2 = rotation @ geometry.axes[1]
    slide3 = rotation @ geometry.axes[2]
    frame_zero = to_joint1 @ geometry.frame_zero
    offset = frame_zero[:3, 3]  # at q2 = q3 = 0
    vertical = np.array([slide2[2], slide3[2]])
    norm_sq = float(vertical @ vertical)
    if norm_sq < DIRECTION_TOLERANCE**2:
        return None  # both slides horizontal: the height alone cannot be reached by a formula
    line_point = vertical / norm_sq
    line_direction = np.array([slide3[2], -slide2[2]]) / math.sqrt(norm_sq)
    horizontal = line_direction[0] * slide2[:2] + line_direction[1] * slide3[:2]
    if float(np.linalg.norm(horizontal)) < DIRECTION_TOLERANCE:
        return None  # the free direction does not change the distance from the axis
    branch_joint = 1 if abs(line_direction[0]) >= abs(line_direction[1]) else 2
    return RppSolver(
        base_to_joint1=to_joint1,
        offset=offset,
        slide2=slide2,
        slide3=slide3,
        line_point=line_point,
        line_direction=line_direction,
        branch_joint=branch_joint,
        branch_name=geometry.model.joints[branch_joint].name,
    )
