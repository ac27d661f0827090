"""Closed-form IK of 6R arms with an ortho-parallel base and a spherical wrist (OPW type).

Structure (detected from the geometry, not from names): six revolute joints; axis 2
perpendicular to axis 1; axis 3 parallel to axis 2; axes 4, 5, 6 meet in one point (the
wrist centre), with 4 ∦ 5 and 5 ∦ 6. Offsets are free: the shoulder may sit off joint 1's
axis (OPW's a1), sideways along axis 2 (b), and the elbow may be offset (a2). This is the
geometry of the irb120 and of most industrial arms described by OPW parameters (a1, a2, b,
c1..c4), read here from the joint axes instead.

Solution (Pieper's decoupling):

1. The wrist centre is fixed in the last link, so the target pose gives its position.
2. Joint 1: in joint 1's frame the wrist centre keeps its component ``b`` along axis 2; the
   rest of its horizontal distance (``±√(ρ² − b²)``) is the arm plane's reach: two shoulders.
3. Joints 2, 3: a planar two-link arm in the plane normal to axis 2: two elbows.
4. Joints 4, 5, 6: axis 6 must point where the target puts it; turning it about axis 4 and
   axis 5 is Paden-Kahan's sub-problem 2 (two wrists), and joint 6 takes the remaining roll.

Up to 8 solutions, branch ``shoulder=front|back elbow=up|down wrist=+|-``: ``front`` when
the wrist centre is on the side of joint 1's axis it has at q = 0; ``up`` when the elbow lies
above the shoulder-wrist line (seen with the wrist ahead); ``wrist=+`` when the sine of q5,
measured from where axes 4 and 6 align, is positive. Singular targets keep the free joint at
its ``hint`` value: joint 1 with the wrist centre on joint 1's axis (and b = 0), joint 4 with
axes 4 and 6 aligned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.closed_form.geometry import (
    POINT_TOLERANCE,
    ChainGeometry,
    closest_point_of_lines,
    distance_to_line,
    parallel,
    perpendicular,
    planar_two_link,
)
from manip_kin.rotations import invert_transform, rot_z

REQUIRED_ROWS = (0, 1, 2, 3, 4, 5)
_SINGULAR = 1e-12


def _rotation_about(axis: np.ndarray, angle: float, vector: np.ndarray) -> np.ndarray:
    """Rodrigues: ``vector`` turned by ``angle`` about unit ``axis``."""
    c, s = math.cos(angle), math.sin(angle)
    return c * vector + s * np.cross(axis, vector) + (1.0 - c) * float(axis @ vector) * axis


@dataclass(frozen=True)
class OpwSolver:
    """Precomputed closed form of an OPW-type arm (see the module docstring).

    Attributes:
        base_to_joint1: inverse of joint 1's frame at q1 = 0, shape (4, 4).
        fixed: the chain's fixed transforms ``F_i``, shape (6, 4, 4).
        tail: joint 6's moving frame to the controlled frame, shape (4, 4).
        wrist_in_frame: the wrist centre in the controlled frame, shape (3,).
        lateral: ``b``, the wrist centre's constant component along axis 2 [m].
        axis2, across: axis 2 and ``z × axis2`` in joint 1's frame, each shape (3,).
        shoulder, elbow, wrist: axis 2, axis 3 and the wrist centre at q = 0 in the arm plane
            (coordinates along ``across`` and z of joint 1's frame) [m], each shape (2,).
        elbow_sign: +1 when axis 3 points like axis 2, -1 when opposite.
        front_sign: sign of the wrist centre's ``across`` coordinate at q = 0.
        axis5, axis6: axis 5 in joint 4's frame, axis 6 in joint 4's frame at q5 = 0, shape (3,).
    """

    base_to_joint1: np.ndarray
    fixed: np.ndarray
    tail: np.ndarray
    wrist_in_frame: np.ndarray
    lateral: float
    axis2: np.ndarray
    across: np.ndarray
    shoulder: np.ndarray
    elbow: np.ndarray
    wrist: np.ndarray
    elbow_sign: float
    front_sign: float
    axis5: np.ndarray
    axis6: np.ndarray

    structure = "opw"
    required_rows = REQUIRED_ROWS

    def solve(self, target: np.ndarray, hint: np.ndarray) -> list[tuple[np.ndarray, str]]:
        """Every solution ``(q, branch)`` (limits not applied) for a target pose in base."""
        centre_base = target[:3, :3] @ self.wrist_in_frame + target[:3, 3]
        centre = self.base_to_joint1[:3, :3] @ centre_base + self.base_to_joint1[:3, 3]
        radius_sq = centre[0] ** 2 + centre[1] ** 2
        reach_sq = radius_sq - self.lateral**2
        if reach_sq < -1e-12:
            return []  # the wrist centre is closer to joint 1's axis than the lateral offset b
        reach = math.sqrt(max(0.0, reach_sq))
        solutions = []
        for across in (self.front_sign * reach, -self.front_sign * reach):
            horizontal = self.lateral * self.axis2[:2] + across * self.across[:2]
            if math.sqrt(radius_sq) < _SINGULAR:
                q1 = float(hint[0])  # the wrist centre is on joint 1's axis: q1 is free
            else:
                q1 = math.atan2(centre[1], centre[0]) - math.atan2(horizontal[1], horizontal[0])
            shoulder_name = "front" if across * self.front_sign >= 0.0 else "back"
            in_plane = np.array([across, centre[2]]) - self.shoulder
            for t2, t3, side in planar_two_link(
                self.elbow - self.shoulder, self.wrist - self.elbow, in_plane, float(hint[1])
            ):
                # side +1: elbow clockwise of the shoulder-wrist line in (across, z); "up" when the
                # wrist is ahead (positive across) and the elbow counter-clockwise of it.
                ahead = 1.0 if across >= 0.0 else -1.0
                elbow_name = "up" if side * ahead < 0 else "down"
                arm = (q1, t2, self.elbow_sign * t3)
                for q456, wrist_name in self._wrist(arm, target, hint):
                    q = np.array([*arm, *q456])
                    solutions.append((q, f"shoulder={shoulder_name} elbow={elbow_name} wrist={wrist_name}"))
        return solutions

    def _wrist(self, arm: tuple[float, float, float], target: np.ndarray, hint: np.ndarray):
        """Joints 4..6 for the arm joints 1..3: up to two ``((q4, q5, q6), '+'|'-')``."""
        fixed = self.fixed
        to_joint4 = fixed[0] @ rot4(arm[0]) @ fixed[1] @ rot4(arm[1]) @ fixed[2] @ rot4(arm[2]) @ fixed[3]
        # X = Rz(q4) F5 Rz(q5) F6 Rz(q6): the wrist rotation in joint 4's frame.
        wrist_rotation = to_joint4[:3, :3].T @ target[:3, :3] @ self.tail[:3, :3].T
        pointing = wrist_rotation[:, 2]  # where axis 6 must point
        f, k = self.axis5, self.axis6
        along = float(f @ k)
        perpendicular_part = k - along * f
        alpha = perpendicular_part[2]
        beta = float(np.cross(f, k)[2])
        gamma = pointing[2] - along * f[2]
        amplitude = math.hypot(alpha, beta)
        cosine = gamma / amplitude
        if abs(cosine) > 1.0 + 1e-9:
            return []
        cosine = min(1.0, max(-1.0, cosine))
        if abs(along) < _SINGULAR and abs(f[2]) < _SINGULAR and abs(amplitude - 1.0) < _SINGULAR:
            # Orthogonal wrist: sin from the pointing's horizontal part keeps full precision near
            # the singularity, where sqrt(1 - cos²) loses half the digits.
            sine = math.hypot(pointing[0], pointing[1])
        else:
            sine = math.sqrt(max(0.0, 1.0 - cosine * cosine))
        phase = math.atan2(beta, alpha)
        # q5 where axis 6 aligns with axis 4 (pointing along +z of joint 4's frame).
        aligned = phase + math.acos(min(1.0, max(-1.0, (1.0 - along * f[2]) / amplitude)))
        results = []
        for sign in (1.0, -1.0):
            q5 = phase + sign * math.atan2(sine, cosine)
            turned = _rotation_about(f, q5, k)
            if math.hypot(turned[0], turned[1]) < _SINGULAR or math.hypot(pointing[0], pointing[1]) < _SINGULAR:
                q4 = float(hint[3])  # axes 4 and 6 aligned: only q4 + q6 (or q4 - q6) matters
            else:
                q4 = math.atan2(pointing[1], pointing[0]) - math.atan2(turned[1], turned[0])
            before6 = rot_z(q4) @ fixed[4][:3, :3] @ rot_z(q5) @ fixed[5][:3, :3]
            remaining = before6.T @ wrist_rotation
            q6 = math.atan2(remaining[1, 0], remaining[0, 0])
            results.append(((q4, q5, q6), "+" if math.sin(q5 - aligned) >= 0.0 else "-"))
        return results


def rot4(angle: float) -> np.ndarray:
    """4x4 rotation about z by ``angle`` [rad]."""
    transform = np.eye(4)
    transform[:3, :3] = rot_z(angle)
    return transform


def detect_opw(geometry: ChainGeometry) -> OpwSolver | None:
    """The OPW closed form when the chain has that structure, else None."""
    if geometry.dof != 6 or not geometry.revolute.all():
        return None
    axes, points = geometry.axes, geometry.points
    if not (perpendicular(axes[0], axes[1]) and parallel(axes[1], axes[2])):
        return None
    meeting = closest_point_of_lines(points[3], axes[3], points[4], axes[4])
    if meeting is None or meeting[1] > POINT_TOLERANCE or parallel(axes[4], axes[5]):
        return None
    centre = meeting[0]
    if distance_to_line(centre, points[5], axes[5]) > POINT_TOLERANCE:
        return None
    to_joint1 = invert_transform(geometry.moving_zero[0])
    rotation, shift = to_joint1[:3, :3], to_joint1[:3, 3]
    axis2 = rotation @ axes[1]
    axis2 = axis2 - axis2[2] * np.array([0.0, 0.0, 1.0])
    axis2 /= np.linalg.norm(axis2)
    across = np.cross([0.0, 0.0, 1.0], axis2)

    def in_plane(point_base):
        point = rotation @ point_base + shift
        return np.array([point @ across, point[2]])

    shoulder, elbow, wrist = in_plane(points[1]), in_plane(points[2]), in_plane(centre)
    if min(np.linalg.norm(elbow - shoulder), np.linalg.norm(wrist - elbow)) < POINT_TOLERANCE:
        return None  # no upper arm or no forearm: not a two-link arm
    fixed = geometry.model.chain.fixed
    frame_to_base = geometry.frame_zero
    return OpwSolver(
        base_to_joint1=to_joint1,
        fixed=fixed.copy(),
        tail=geometry.tail,
        wrist_in_frame=(invert_transform(frame_to_base) @ np.append(centre, 1.0))[:3],
        lateral=float((rotation @ centre + shift) @ axis2),
        axis2=axis2,
        across=across,
        shoulder=shoulder,
        elbow=elbow,
        wrist=wrist,
        elbow_sign=1.0 if float(axes[1] @ axes[2]) > 0 else -1.0,
        front_sign=1.0 if wrist[0] >= 0.0 else -1.0,
        axis5=fixed[4][:3, 2].copy(),
        axis6=(fixed[4][:3, :3] @ fixed[5][:3, 2]).copy(),
    )
