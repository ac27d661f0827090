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

from manip_kin.core.rotations import invert_transform
from manip_kin.ik.closed_form.geometry import (
    POINT_TOLERANCE,
    ChainGeometry,
    closest_point_of_lines,
    distance_to_line,
    parallel,
    perpendicular,
    planar_two_link,
)

REQUIRED_ROWS = (0, 1, 2, 3, 4, 5)
_SINGULAR = 1e-12


Matrix = tuple[tuple[float, float, float], ...]


def _rows(matrix) -> Matrix:
    """A 3x3 array as nested float tuples: the per-call code runs on plain floats (no numpy overhead)."""
    return tuple(tuple(float(v) for v in row) for row in np.asarray(matrix)[:3, :3])


def _mul(a, b) -> tuple:
    """3x3 product, unrolled (a third of the time of the loop form)."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = a[0][:3], a[1][:3], a[2][:3]
    (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = b[0][:3], b[1][:3], b[2][:3]
    return (
        (a00 * b00 + a01 * b10 + a02 * b20, a00 * b01 + a01 * b11 + a02 * b21, a00 * b02 + a01 * b12 + a02 * b22),
        (a10 * b00 + a11 * b10 + a12 * b20, a10 * b01 + a11 * b11 + a12 * b21, a10 * b02 + a11 * b12 + a12 * b22),
        (a20 * b00 + a21 * b10 + a22 * b20, a20 * b01 + a21 * b11 + a22 * b21, a20 * b02 + a21 * b12 + a22 * b22),
    )


def _turn_back(angle: float, m) -> tuple:
    """``Rz(angle)ᵀ · m``."""
    c, s = math.cos(angle), math.sin(angle)
    (m00, m01, m02), (m10, m11, m12) = m[0], m[1]
    return (
        (c * m00 + s * m10, c * m01 + s * m11, c * m02 + s * m12),
        (c * m10 - s * m00, c * m11 - s * m01, c * m12 - s * m02),
        m[2],
    )


@dataclass(frozen=True)
class OpwSolver:
    """Precomputed closed form of an OPW-type arm (see the module docstring); per-call work in floats.

    Attributes:
        joint1_rotation, joint1_shift: base to joint 1's frame at q1 = 0 (3x3 rows, 3 values).
        wrist_in_frame: the wrist centre in the controlled frame [m], 3 values.
        lateral: ``b``, the wrist centre's constant component along axis 2 [m].
        axis2_xy, across_xy: horizontal parts of axis 2 and ``z × axis2`` in joint 1's frame.
        shoulder: axis 2 in the arm plane (coordinates along ``across`` and z) [m].
        upper_arm, forearm: axis 2 to axis 3 and axis 3 to the wrist centre in the plane at q = 0 [m].
        elbow_sign: +1 when axis 3 points like axis 2, -1 when opposite.
        front_sign: sign of the wrist centre's ``across`` coordinate at q = 0.
        arm_transposed: rotations of ``F_1..F_4`` transposed (3x3 rows each).
        target_to_wrist: ``tailᵀ`` rotation: the controlled frame to joint 6's frame.
        wrist_parts: ``F_5 Rz(q5) F_6 = cos q5 · P + sin q5 · Q + R``: (P, Q, R).
        along, alpha, beta, phase, aligned, orthogonal: constants of the wrist sub-problem
            (module docstring): axis 5·axis 6, the cos/sin coefficients of axis 6's z component
            over q5, their phase, the q5 aligning axes 4 and 6, and whether 4 ⊥ 5 ⊥ 6 exactly.
        axis5_z: z component of axis 5 in joint 4's frame.
    """

    joint1_rotation: Matrix
    joint1_shift: tuple[float, float, float]
    wrist_in_frame: tuple[float, float, float]
    lateral: float
    axis2_xy: tuple[float, float]
    across_xy: tuple[float, float]
    shoulder: tuple[float, float]
    upper_arm: tuple[float, float]
    forearm: tuple[float, float]
    elbow_sign: float
    front_sign: float
    arm_transposed: tuple[Matrix, Matrix, Matrix, Matrix]
    target_to_wrist: Matrix
    wrist_parts: tuple[Matrix, Matrix, Matrix]
    along: float
    alpha: float
    beta: float
    phase: float
    aligned: float
    orthogonal: bool
    axis5_z: float

    structure = "opw"
    required_rows = REQUIRED_ROWS

    def solve(self, target: np.ndarray, hint) -> list[tuple[list[float], str]]:
        """Every solution ``(q, branch)`` (limits not applied) for a target pose in base."""
        rows = target.tolist()
        w = self.wrist_in_frame
        centre_base = [rows[i][0] * w[0] + rows[i][1] * w[1] + rows[i][2] * w[2] + rows[i][3] for i in range(3)]
        r, t = self.joint1_rotation, self.joint1_shift
        centre = [
            r[i][0] * centre_base[0] + r[i][1] * centre_base[1] + r[i][2] * centre_base[2] + t[i] for i in range(3)
        ]
        radius_sq = centre[0] ** 2 + centre[1] ** 2
        reach_sq = radius_sq - self.lateral**2
        if reach_sq < -1e-12:
            return []  # the wrist centre is closer to joint 1's axis than the lateral offset b
        reach = math.sqrt(max(0.0, reach_sq))
        # X = A4ᵀ Rz(-q3) A3ᵀ Rz(-q2) A2ᵀ Rz(-q1) A1ᵀ R_target tailᵀ = Rz(q4) F5 Rz(q5) F6 Rz(q6)
        a1, a2, a3, a4 = self.arm_transposed
        start = _mul(a1, _mul(rows, self.target_to_wrist))
        solutions = []
        for across in (self.front_sign * reach, -self.front_sign * reach):
            horizontal = [self.lateral * self.axis2_xy[i] + across * self.across_xy[i] for i in (0, 1)]
            if math.sqrt(radius_sq) < _SINGULAR:
                q1 = float(hint[0])  # the wrist centre is on joint 1's axis: q1 is free
            else:
                q1 = math.atan2(centre[1], centre[0]) - math.atan2(horizontal[1], horizontal[0])
            shoulder_name = "front" if across * self.front_sign >= 0.0 else "back"
            in_plane = (across - self.shoulder[0], centre[2] - self.shoulder[1])
            after1 = _mul(a2, _turn_back(q1, start))
            for t2, t3, side in planar_two_link(self.upper_arm, self.forearm, in_plane, float(hint[1])):
                # side +1: elbow clockwise of the shoulder-wrist line in (across, z): "down" when
                # the wrist is ahead (positive across), "up" when it is behind.
                elbow_name = "up" if side * (1.0 if across >= 0.0 else -1.0) < 0 else "down"
                q3 = self.elbow_sign * t3
                wrist_rotation = _mul(a4, _turn_back(q3, _mul(a3, _turn_back(t2, after1))))
                for q456, wrist_name in self._wrist(wrist_rotation, hint):
                    branch = f"shoulder={shoulder_name} elbow={elbow_name} wrist={wrist_name}"
                    solutions.append(([q1, t2, q3, *q456], branch))
        return solutions

    def _wrist(self, x, hint) -> list[tuple[tuple[float, float, float], str]]:
        """Joints 4..6 from the wrist rotation ``x`` in joint 4's frame: two ``((q4, q5, q6), '+'|'-')``."""
        pointing = (x[0][2], x[1][2], x[2][2])  # where axis 6 must point
        amplitude = math.hypot(self.alpha, self.beta)
        cosine = (pointing[2] - self.along * self.axis5_z) / amplitude
        if abs(cosine) > 1.0 + 1e-9:
            return []
        cosine = min(1.0, max(-1.0, cosine))
        if self.orthogonal:
            # sin from the pointing's horizontal part keeps full precision near the singularity,
            # where sqrt(1 - cos²) loses half the digits.
            sine = math.hypot(pointing[0], pointing[1])
        else:
            sine = math.sqrt(max(0.0, 1.0 - cosine * cosine))
        p, q, r = self.wrist_parts
        results = []
        for sign in (1.0, -1.0):
            q5 = self.phase + sign * math.atan2(sine, cosine)
            c5, s5 = math.cos(q5), math.sin(q5)
            g = [[c5 * p[i][j] + s5 * q[i][j] + r[i][j] for j in range(3)] for i in range(3)]  # F5 Rz(q5) F6
            turned = (g[0][2], g[1][2])  # axis 6 before joint 4 turns it
            if math.hypot(*turned) < _SINGULAR or math.hypot(pointing[0], pointing[1]) < _SINGULAR:
                q4 = float(hint[3])  # axes 4 and 6 aligned: only q4 + q6 (or q4 - q6) matters
            else:
                q4 = math.atan2(pointing[1], pointing[0]) - math.atan2(turned[1], turned[0])
            c4, s4 = math.cos(q4), math.sin(q4)
            # Rz(q6) = (Rz(q4) g)ᵀ x: its first column, from columns 0 and 1 of Rz(q4) g.
            column0 = (c4 * g[0][0] - s4 * g[1][0], s4 * g[0][0] + c4 * g[1][0], g[2][0])
            column1 = (c4 * g[0][1] - s4 * g[1][1], s4 * g[0][1] + c4 * g[1][1], g[2][1])
            cos6 = column0[0] * x[0][0] + column0[1] * x[1][0] + column0[2] * x[2][0]
            sin6 = column1[0] * x[0][0] + column1[1] * x[1][0] + column1[2] * x[2][0]
            results.append(((q4, q5, math.atan2(sin6, cos6)), "+" if math.sin(q5 - self.aligned) >= 0.0 else "-"))
        return results


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
    f5, f6 = fixed[4][:3, :3], fixed[5][:3, :3]
    axis5 = f5[:, 2]
    axis6 = f5 @ f6[:, 2]
    along = float(axis5 @ axis6)
    alpha = float(axis6[2] - along * axis5[2])
    beta = float(np.cross(axis5, axis6)[2])
    amplitude = math.hypot(alpha, beta)
    phase = math.atan2(beta, alpha)
    aligned = phase + math.acos(min(1.0, max(-1.0, (1.0 - along * axis5[2]) / amplitude)))
    cos_part, sin_part, constant = np.diag([1.0, 1.0, 0.0]), np.zeros((3, 3)), np.diag([0.0, 0.0, 1.0])
    sin_part[0, 1], sin_part[1, 0] = -1.0, 1.0  # Rz(q) = cos q · diag(1,1,0) + sin q · [e_z]× + e_z e_zᵀ
    wrist_centre = (invert_transform(geometry.frame_zero) @ np.append(centre, 1.0))[:3]
    return OpwSolver(
        joint1_rotation=_rows(rotation),
        joint1_shift=tuple(float(v) for v in shift),
        wrist_in_frame=tuple(float(v) for v in wrist_centre),
        lateral=float((rotation @ centre + shift) @ axis2),
        axis2_xy=(float(axis2[0]), float(axis2[1])),
        across_xy=(float(across[0]), float(across[1])),
        shoulder=(float(shoulder[0]), float(shoulder[1])),
        upper_arm=tuple(float(v) for v in elbow - shoulder),
        forearm=tuple(float(v) for v in wrist - elbow),
        elbow_sign=1.0 if float(axes[1] @ axes[2]) > 0 else -1.0,
        front_sign=1.0 if wrist[0] >= 0.0 else -1.0,
        arm_transposed=tuple(_rows(fixed[i][:3, :3].T) for i in range(4)),
        target_to_wrist=_rows(geometry.tail[:3, :3].T),
        wrist_parts=(_rows(f5 @ cos_part @ f6), _rows(f5 @ sin_part @ f6), _rows(f5 @ constant @ f6)),
        along=along,
        alpha=alpha,
        beta=beta,
        phase=phase,
        aligned=aligned,
        orthogonal=abs(along) < _SINGULAR and abs(axis5[2]) < _SINGULAR and abs(amplitude - 1.0) < _SINGULAR,
        axis5_z=float(axis5[2]),
    )
