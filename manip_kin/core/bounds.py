"""What a model can physically do, as bounds on the inputs a node accepts (no ROS here).

A node must reject a goal a hundred orders of magnitude outside the workspace before the
numbers reach a time scaling or a solver; these bounds say where "absurd" starts for one
robot, computed once from the model:

* the **reach radius** bounds the distance of every frame (tool included) from the base
  origin over every configuration inside the limits: the chain is
  ``F_1 Z(q_1) … F_n Z(q_n) · ee_offset · tool`` and rotations keep lengths, so
  ``|p| <= Σ |t(F_i)| + Σ_prismatic max(|lower|, |upper|) + |t(ee_offset)| + |t(tool)|``;
* the **speed bounds** bound the tool's speed at the joint velocity limits: a revolute
  joint moves any point within the reach radius at most ``ω_i · r``, a prismatic one at
  ``v_i``; angular speed at most ``Σ ω_i``.

Inputs are rejected only when they are far beyond these (factor
:data:`ABSURD_FACTOR`): a goal just outside the reach is a legitimate request the
controller stretches towards; one at twice the reach radius is a mistake.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.core.model import RobotModel

#: Inputs beyond this multiple of what the model can do are rejected as absurd.
ABSURD_FACTOR = 2.0
#: A joint-rate command beyond this multiple of a velocity limit is rejected (below it, the
#: arm scales it into the limits as a whole).
COMMAND_FACTOR = 100.0
#: Reported joint positions may lie this fraction of the joint's range outside its limits
#: (encoder noise, a driver's own limits) before they are rejected; at least 0.01 rad | m.
JOINT_RANGE_MARGIN = 0.1
#: Cap for quantities the model leaves unbounded (continuous joints, endless prismatic
#: travel): large enough for any arm, small enough that squares and sums stay finite.
UNBOUNDED = 1e6


@dataclass(frozen=True)
class InputBounds:
    """Bounds on what a node accepts for one model.

    Attributes:
        reach_radius: largest distance of any frame from the base origin [m].
        max_target_distance: a target position farther than this from the base is rejected [m].
        max_linear_speed: fastest the tool can move at the velocity limits [m/s].
        max_angular_speed: fastest the tool can turn [rad/s].
        max_twist_linear: a goal twist faster than this is rejected [m/s].
        max_twist_angular: ... or turning faster than this [rad/s].
        position_lower: smallest accepted reported joint position, shape (n,) [rad | m].
        position_upper: largest accepted reported joint position, shape (n,) [rad | m].
        max_command: largest accepted |joint-rate command| per joint, shape (n,) [rad/s | m/s].
    """

    reach_radius: float
    max_target_distance: float
    max_linear_speed: float
    max_angular_speed: float
    max_twist_linear: float
    max_twist_angular: float
    position_lower: np.ndarray
    position_upper: np.ndarray
    max_command: np.ndarray

    @classmethod
    def of(cls, model: RobotModel) -> InputBounds:
        """The bounds of ``model`` (a node computes them once, at start)."""
        return _compute(model)


def reach_radius(model: RobotModel) -> float:
    """Upper bound of the distance of any frame from the base origin [m] (see module doc)."""
    return InputBounds.of(model).reach_radius


def _translation_length(transform) -> float:
    return float(np.linalg.norm(np.asarray(transform, dtype=float)[:3, 3]))


def _compute(model: RobotModel) -> InputBounds:
    chain = model.chain
    radius = sum(_translation_length(f) for f in chain.fixed) + _translation_length(chain.moving_to_ee)
    if model.tool is not None:
        radius += _translation_length(model.tool)
    for joint in model.joints:
        if not joint.is_revolute:
            radius += min(max(abs(joint.lower), abs(joint.upper)), UNBOUNDED)
    radius = min(radius, UNBOUNDED)
    revolute = model.chain.revolute_mask > 0.5
    velocity = np.minimum(model.velocity_limits, UNBOUNDED)
    angular = float(velocity[revolute].sum())
    linear = float(angular * radius + velocity[~revolute].sum())
    lower = np.where(np.isfinite(model.lower), model.lower, -UNBOUNDED)
    upper = np.where(np.isfinite(model.upper), model.upper, UNBOUNDED)
    margin = np.maximum(JOINT_RANGE_MARGIN * (upper - lower), 0.01)
    return InputBounds(
        reach_radius=radius,
        max_target_distance=ABSURD_FACTOR * max(radius, 0.01),
        max_linear_speed=linear,
        max_angular_speed=angular,
        max_twist_linear=ABSURD_FACTOR * max(linear, 0.01),
        max_twist_angular=ABSURD_FACTOR * max(angular, 0.01),
        position_lower=lower - margin,
        position_upper=upper + margin,
        max_command=COMMAND_FACTOR * velocity,
    )


def norm3(x: float, y: float, z: float) -> float:
    """Euclidean length of a 3-vector without overflow for finite inputs (``math.hypot``)."""
    return math.hypot(x, y, z)
