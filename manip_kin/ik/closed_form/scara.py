"""Closed-form IK of a SCARA: three revolute joints and one prismatic joint, all along base z.

Structure (detected from the geometry, in any joint order): every axis parallel to the base z
axis. The prismatic joint then commutes with the revolute ones, so the problem splits:

* yaw: the tool turns about z by the sum of the (signed) revolute angles, chosen to best match
  the target rotation (exact when the target is reachable);
* plane: the last revolute axis must sit where the tool offset, turned by that yaw, leaves it;
  the first two revolute joints reach it as a planar two-link arm (two elbows);
* height: the prismatic travel.

Branches: ``elbow=right`` / ``elbow=left``, the side of the line from the first axis to the
last on which the middle axis lies, seen from above (+z looking down).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.ik.closed_form.geometry import ChainGeometry, parallel, planar_two_link

REQUIRED_ROWS = (2, 3, 4, 5)  # rz, x, y, z

_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class ScaraSolver:
    """Precomputed closed form of a SCARA (see the module docstring).

    Attributes:
        revolute_joints: indices of the three revolute joints, in chain order.
        prismatic_joint: index of the prismatic joint.
        signs: +1 when a revolute axis points up, -1 when down, shape (3,).
        axis_points: where each revolute axis crosses the xy plane at q = 0 [m], shape (3, 2).
        slide: travel of the frame along z per unit prismatic motion (+1 or -1).
        frame_zero: the controlled frame at q = 0, shape (4, 4).
    """

    revolute_joints: tuple[int, int, int]
    prismatic_joint: int
    signs: np.ndarray
    axis_points: np.ndarray
    slide: float
    frame_zero: np.ndarray

    structure = "scara"
    required_rows = REQUIRED_ROWS

    def solve(self, target: np.ndarray, hint: np.ndarray) -> list[tuple[np.ndarray, str]]:
        """Every solution ``(q, branch)`` (limits not applied) for a target pose in base."""
        # Yaw ψ maximising trace(R_targetᵀ Rz(ψ) R_zero): exact for a reachable rotation.
        m = self.frame_zero[:3, :3] @ target[:3, :3].T
        yaw = math.atan2(m[0, 1] - m[1, 0], m[0, 0] + m[1, 1])
        c, s = math.cos(yaw), math.sin(yaw)
        first, middle, last = self.axis_points
        offset = self.frame_zero[:2, 3] - last  # last axis to the frame, at q = 0
        wrist = target[:2, 3] - np.array([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1]])
        solutions = []
        first_hint = float(hint[self.revolute_joints[0]] * self.signs[0])
        for t1, t2, side in planar_two_link(middle - first, last - middle, wrist - first, first_hint):
            angles = np.array([t1, t2, yaw - t1 - t2]) * self.signs
            q = np.zeros(4)
            q[list(self.revolute_joints)] = angles
            q[self.prismatic_joint] = (target[2, 3] - self.frame_zero[2, 3]) / self.slide
            solutions.append((q, "elbow=right" if side > 0 else "elbow=left"))
        return solutions


def detect_scara(geometry: ChainGeometry) -> ScaraSolver | None:
    """The SCARA closed form when the chain has that structure, else None."""
    if geometry.dof != 4 or int(geometry.revolute.sum()) != 3:
        return None
    if not all(parallel(axis, _UP) for axis in geometry.axes):
        return None
    revolute = tuple(int(i) for i in np.flatnonzero(geometry.revolute))
    prismatic = int(np.flatnonzero(~geometry.revolute)[0])
    points = geometry.points[list(revolute), :2]
    if min(np.linalg.norm(points[1] - points[0]), np.linalg.norm(points[2] - points[1])) < 1e-9:
        return None  # two coincident axes: not a two-link arm
    return ScaraSolver(
        revolute_joints=revolute,
        prismatic_joint=prismatic,
        signs=np.sign(geometry.axes[list(revolute), 2]),
        axis_points=points,
        slide=float(np.sign(geometry.axes[prismatic, 2])),
        frame_zero=geometry.frame_zero,
    )
