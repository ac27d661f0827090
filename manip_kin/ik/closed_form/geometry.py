"""The chain geometry the closed-form solvers read, and the small planar sub-problem they share.

A model's chain is ``F_1 Z(q_1) F_2 Z(q_2) … F_n Z(q_n) · tail`` (see
:class:`manip_kin.core.model.ChainArrays`): joint ``i`` rotates about, or slides along, the z axis
of the frame ``F_1 … F_i``. At q = 0 those frames give every joint's axis direction and a
point on it, in base; the solvers detect their structure from these, never from names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.core.kinematics import pose_in_base
from manip_kin.core.model import RobotModel
from manip_kin.core.rotations import invert_transform

# Two directions count as parallel / perpendicular, and two lines as meeting, within these.
# URDFs round angles (rpy="0 0 1.5708" is 4e-6 rad off); a small residue is removed by the
# numeric refinement that follows a closed-form solution which does not verify.
DIRECTION_TOLERANCE = 1e-5
POINT_TOLERANCE = 1e-6  # [m]
# |cos| of a two-link elbow may exceed 1 by this much (a stretched arm) before it is out of reach.
REACH_SLACK = 1e-9


@dataclass(frozen=True)
class ChainGeometry:
    """Joint axes and the controlled frame of a model at q = 0, in base.

    Attributes:
        model: the robot.
        frame_index: the controlled frame (n, ee or tool: rigidly attached to the last link).
        revolute: per joint, True for revolute, shape (n,).
        moving_zero: frame ``F_1 … F_i`` per joint (z = joint axis), shape (n, 4, 4).
        axes: unit axis direction per joint, shape (n, 3).
        points: a point on each axis (the frame origin) [m], shape (n, 3).
        tail: from joint n's moving frame to the controlled frame, shape (4, 4).
        frame_zero: the controlled frame's pose at q = 0, shape (4, 4).
    """

    model: RobotModel
    frame_index: int
    revolute: np.ndarray
    moving_zero: np.ndarray
    axes: np.ndarray
    points: np.ndarray
    tail: np.ndarray
    frame_zero: np.ndarray

    @property
    def dof(self) -> int:
        return self.model.dof


def chain_geometry(model: RobotModel, frame_index: int) -> ChainGeometry | None:
    """The geometry of ``model`` for a frame on its last link; None for a frame before it."""
    n = model.dof
    if frame_index < n:
        return None
    moving = np.empty((n, 4, 4))
    current = np.eye(4)
    for i in range(n):
        current = current @ model.chain.fixed[i]
        moving[i] = current
    frame_zero = pose_in_base(model, np.zeros(n), frame_index)
    return ChainGeometry(
        model=model,
        frame_index=frame_index,
        revolute=model.chain.revolute_mask > 0.5,
        moving_zero=moving,
        axes=moving[:, :3, 2].copy(),
        points=moving[:, :3, 3].copy(),
        tail=invert_transform(moving[-1]) @ frame_zero,
        frame_zero=frame_zero,
    )


def parallel(a: np.ndarray, b: np.ndarray) -> bool:
    """Unit directions ``a`` and ``b`` are parallel or antiparallel."""
    return float(np.linalg.norm(np.cross(a, b))) < DIRECTION_TOLERANCE


def perpendicular(a: np.ndarray, b: np.ndarray) -> bool:
    """Unit directions ``a`` and ``b`` are perpendicular."""
    return abs(float(np.dot(a, b))) < DIRECTION_TOLERANCE


def closest_point_of_lines(p1, d1, p2, d2) -> tuple[np.ndarray, float] | None:
    """Midpoint of the shortest segment between two non-parallel lines, and its length [m]."""
    normal = np.cross(d1, d2)
    norm_sq = float(normal @ normal)
    if norm_sq < DIRECTION_TOLERANCE**2:
        return None
    offset = p2 - p1
    t1 = float(np.cross(offset, d2) @ normal) / norm_sq
    t2 = float(np.cross(offset, d1) @ normal) / norm_sq
    a, b = p1 + t1 * d1, p2 + t2 * d2
    return 0.5 * (a + b), float(np.linalg.norm(a - b))


def distance_to_line(point, line_point, direction) -> float:
    """Distance from ``point`` to the line through ``line_point`` along unit ``direction`` [m]."""
    return float(np.linalg.norm(np.cross(point - line_point, direction)))


def rotate_2d(angle: float, vector) -> tuple[float, float]:
    """``vector`` (x, y) rotated counter-clockwise by ``angle`` [rad]."""
    c, s = math.cos(angle), math.sin(angle)
    return (c * vector[0] - s * vector[1], s * vector[0] + c * vector[1])


def planar_two_link(first, second, target, first_hint: float = 0.0) -> list[tuple[float, float, int]]:
    """Both solutions of a planar two-link arm: ``Rot(t1) (first + Rot(t2) second) = target``.

    Args:
        first: the first link's vector (shoulder to elbow) at zero angles, shape (2,).
        second: the second link's vector (elbow to wrist) at zero angles, shape (2,).
        target: the wrist point relative to the shoulder, shape (2,).
        first_hint: ``t1`` when the target is on the shoulder (folded equal links: t1 is free).

    Returns:
        ``(t1, t2, side)`` per solution [rad]; ``side`` is +1 when the second link turns
        counter-clockwise from the first (the elbow lies clockwise of the shoulder-wrist line),
        -1 otherwise. Empty when the target is out of reach; both solutions coincide (and are
        both returned) when the arm is stretched or folded.
    """
    l1, l2 = math.hypot(*first), math.hypot(*second)
    distance_sq = float(target[0] ** 2 + target[1] ** 2)
    cos_relative = (distance_sq - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    if abs(cos_relative) > 1.0 + REACH_SLACK:
        return []
    cos_relative = min(1.0, max(-1.0, cos_relative))
    # sin² = (1 - cos)(1 + cos) from the distances themselves: 1 - cos² cancels to nothing near
    # stretched or folded, where the target's last nanometres would be lost (elbow off by ~1e-8 rad).
    sin_sq = ((l1 + l2) ** 2 - distance_sq) * (distance_sq - (l1 - l2) ** 2) / (2.0 * l1 * l2) ** 2
    sin_relative = math.sqrt(max(0.0, min(1.0, sin_sq)))
    relative_at_zero = math.atan2(second[1], second[0]) - math.atan2(first[1], first[0])
    solutions = []
    for side in (1, -1):
        t2 = math.atan2(side * sin_relative, cos_relative) - relative_at_zero
        elbow_to_wrist = rotate_2d(t2, second)
        reach = (first[0] + elbow_to_wrist[0], first[1] + elbow_to_wrist[1])
        if math.hypot(*target) < 1e-12:
            t1 = first_hint
        else:
            t1 = math.atan2(target[1], target[0]) - math.atan2(reach[1], reach[0])
        solutions.append((t1, t2, side))
    return solutions


def wrap_to_pi(angle: float) -> float:
    """``angle`` moved by whole turns into (-π, π]."""
    wrapped = math.remainder(angle, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped
