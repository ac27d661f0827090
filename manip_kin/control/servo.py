"""Servoing commands without a goal pose: a twist of the controlled frame, a joint jog.

As MoveIt Servo's TWIST and JOINT_JOG commands, but run through the same law and command
filter as every other goal:

* :class:`TwistReference` turns a stream of twists into a moving pose reference: it starts at
  the controlled frame's pose and advances by the twist each period, and the law tracks it
  with the twist as feed-forward (exactly as a line: the feed-forward moves the frame, the
  feedback removes what the arm lagged). The reference never runs more than
  :data:`MAX_LEAD_M` / :data:`MAX_LEAD_RAD` ahead of the frame: where the arm cannot follow
  (a limit, a singularity) it waits for the arm instead of winding up.
* :class:`JogReference` does the same in joint space for the jogged joints; the others hold
  where they were.
* :func:`singularity_scale`: approaching a singularity (the smallest singular value of the
  task Jacobian falling towards ``stop``) scales the motion down; a motion that leaves it
  (the singular value rising) is not slowed, so the arm never halts where it cannot leave.
  The direction is the commanded twist's through the Jacobian transpose (``Jᵀ v``: the joint
  motion that does most for it), so a motion scaled to nothing still knows where it would go;
  the reference of :class:`TwistReference` advances by the scaled twist, so it does not run
  ahead of an arm held back.
  The smallest singular value rather than the condition number: with angular rows (1) and
  linear rows (m) in one Jacobian the condition number of a healthy arm is already 50 to 100
  (the irb120 at rest: 60), while σ_min falls to 0 at any singularity, as the law's damping
  rule uses it.

Plain numpy: no ROS here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.core.kinematics import pose_and_jacobian_in_base
from manip_kin.core.model import RobotModel
from manip_kin.core.rotations import matrix_to_rotvec, rotvec_to_matrix
from manip_kin.errors import InvalidArgumentError, UnknownFrameError

#: How far the twist reference may lead the controlled frame [m] and [rad].
MAX_LEAD_M = 0.01
MAX_LEAD_RAD = 0.05
#: How far along the motion σ_min is probed to tell approaching from leaving [rad | m of q].
PROBE_STEP = 1e-3


def resolve_frame(model: RobotModel, frame_id: str) -> int:
    """The frame index of a message's ``frame_id``: the base frame, a chain link, ``ee``,
    ``tool`` or the name the model gives a frame.

    Raises:
        UnknownFrameError: with the frames that are valid.
    """
    try:
        return model.frame_index(frame_id)
    except UnknownFrameError:
        for index in range(len(model.frame_names)):
            if model.frame_name(index) == frame_id:
                return index
        raise


@dataclass(frozen=True)
class SingularityScaling:
    """Where motion towards a singularity slows (``start``) and stops (``stop``): smallest
    singular values of the task Jacobian (m/s per rad/s for the linear rows, 1 for the
    angular ones, as the law's ``singular_threshold``), start > stop > 0."""

    start: float = 0.05
    stop: float = 0.01

    def __post_init__(self):
        if not (0.0 < self.stop < self.start < math.inf):
            raise InvalidArgumentError(
                f"singularity thresholds start {self.start!r}, stop {self.stop!r}; valid: start > stop > 0, finite"
            )


def smallest_singular_value(jacobian_rows: np.ndarray) -> float:
    """σ_min of a task Jacobian (0 at a singularity)."""
    return float(np.linalg.svd(jacobian_rows, compute_uv=False)[-1])


def singularity_scale(
    model: RobotModel,
    q: np.ndarray,
    direction: np.ndarray,
    frame_index: int,
    rows,
    scaling: SingularityScaling,
    sigma_now: float | None = None,
) -> tuple[float, float]:
    """``(scale, σ_min)``: the factor [0, 1] for a motion along the joint-space ``direction``
    from ``q`` (only its sign along the way matters; ``sigma_now``: σ_min at ``q`` if known).

    1 above ``scaling.start`` and whenever the motion raises σ_min (leaving the singularity);
    towards it, falling linearly to 0 at ``scaling.stop``.
    """
    rows = list(rows)
    if sigma_now is None:
        sigma_now = smallest_singular_value(pose_and_jacobian_in_base(model, q, frame_index)[1][rows])
    length = float(np.linalg.norm(direction))
    if sigma_now >= scaling.start or length == 0.0:
        return 1.0, sigma_now
    probe = q + direction * (PROBE_STEP / length)
    ahead = smallest_singular_value(pose_and_jacobian_in_base(model, probe, frame_index)[1][rows])
    if ahead >= sigma_now:
        return 1.0, sigma_now
    return max(0.0, min(1.0, (sigma_now - scaling.stop) / (scaling.start - scaling.stop))), sigma_now


class TwistReference:
    """A pose reference driven by twists (see the module docstring)."""

    def __init__(self):
        self.pose: np.ndarray | None = None

    def reset(self) -> None:
        """Start again from the frame's pose at the next :meth:`advance`."""
        self.pose = None

    def advance(self, frame_pose: np.ndarray, angular: np.ndarray, linear: np.ndarray, dt: float) -> np.ndarray:
        """The reference after ``dt`` [s] more of the twist (``angular`` [rad/s], ``linear``
        [m/s], both in base), from where it was, held within the lead of ``frame_pose``."""
        reference = frame_pose.copy() if self.pose is None else self.pose.copy()
        reference[:3, 3] += np.asarray(linear) * dt
        reference[:3, :3] = rotvec_to_matrix(np.asarray(angular) * dt) @ reference[:3, :3]
        lead = reference[:3, 3] - frame_pose[:3, 3]
        distance = float(np.linalg.norm(lead))
        if distance > MAX_LEAD_M:
            reference[:3, 3] = frame_pose[:3, 3] + lead * (MAX_LEAD_M / distance)
        turn = matrix_to_rotvec(reference[:3, :3] @ frame_pose[:3, :3].T)
        angle = float(np.linalg.norm(turn))
        if angle > MAX_LEAD_RAD:
            reference[:3, :3] = rotvec_to_matrix(turn * (MAX_LEAD_RAD / angle)) @ frame_pose[:3, :3]
        self.pose = reference
        return reference


class JogReference:
    """Joint positions driven by jog velocities; the joints not jogged hold their place."""

    def __init__(self, model: RobotModel):
        self._lower, self._upper = model.lower, model.upper
        self.positions: np.ndarray | None = None

    def reset(self) -> None:
        """Start again from the arm's positions at the next :meth:`advance`."""
        self.positions = None

    def advance(self, q: np.ndarray, velocities: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(q_ref, q̇_ref)`` after ``dt`` [s] more of ``velocities`` (model order, zero for the
        joints not jogged), within the position limits and within the lead of ``q``."""
        start = q.copy() if self.positions is None else self.positions
        reference = np.clip(start + velocities * dt, self._lower, self._upper)
        reference = np.clip(reference, q - MAX_LEAD_RAD, q + MAX_LEAD_RAD)
        self.positions = reference
        rates = np.where((reference <= self._lower) | (reference >= self._upper), 0.0, velocities)
        return reference, rates
