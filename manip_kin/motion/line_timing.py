"""Whether a timed line keeps the joints within their velocity and acceleration limits.

The reach check (:func:`~manip_kin.motion.line_reach.check_line_reachable`) gives the joint path
``q(s)`` over the line's progress ``s``; the time scaling gives ``s(t)``. Then
``q̇ = q'(s)·ṡ`` and ``q̈ = q''(s)·ṡ² + q'(s)·s̈``, with ``q'`` and ``q''`` from finite
differences of the path, evaluated on 400 instants of the line. That is an estimate (the
continuation's path is not the controller's where the arm is redundant or near a singularity,
where it swings joints the tool does not feel), so the generator logs it as a warning: the
controller's command filter holds the joints to their limits whatever the line asks. A
``constant`` scaling, though, starts and stops at full speed at once, an unbounded
acceleration for certain: :func:`constant_scaling_problem` refuses it while acceleration
limits are in force. Plain numpy: no ROS here.
"""

from __future__ import annotations

import math

import numpy as np

from manip_kin.control.joint_limits import JointLimits
from manip_kin.core.model import RobotModel
from manip_kin.motion.line_reach import ReachReport
from manip_kin.motion.lines import LineTrajectory

#: Instants of the line at which the joint rates and accelerations are evaluated.
TIMING_SAMPLES = 400
_TOLERANCE = 1e-3  # relative: the path's finite differences are an estimate


def constant_scaling_problem(line: LineTrajectory, limits: JointLimits) -> str:
    """Why a ``constant`` line cannot run within ``limits`` ("" for any other, or without
    acceleration limits)."""
    if line.scaling.kind != "constant" or line.scaling.duration <= 0.0 or not limits.limits_acceleration:
        return ""
    return (
        "the constant time scaling starts and stops at full speed at once (an unbounded joint acceleration); "
        "valid: trapezoidal, jerk_limited, cubic or quintic time_scaling while joint acceleration limits are in force"
    )


def line_limits_problem(model: RobotModel, line: LineTrajectory, report: ReachReport, limits: JointLimits) -> str:
    """Where the timed ``line`` seems to need more than ``limits`` allow, estimated from the
    reach check's path ("" when it does not; see the module docstring)."""
    scaling = line.scaling
    if scaling.duration <= 0.0 or report.path.shape[0] < 3 or scaling.kind == "constant":
        return ""
    progress, path = report.progress, report.path
    first = np.gradient(path, progress, axis=0)  # q'(s)
    second = np.gradient(first, progress, axis=0)  # q''(s)
    velocity_limits = np.minimum(model.velocity_limits, limits.velocity)
    for t in np.linspace(0.0, scaling.duration, TIMING_SAMPLES):
        s, rate, acceleration = scaling.evaluate(float(t))
        q_first = np.array([np.interp(s, progress, first[:, j]) for j in range(model.dof)])
        q_second = np.array([np.interp(s, progress, second[:, j]) for j in range(model.dof)])
        speeds = np.abs(q_first * rate)
        accelerations = np.abs(q_second * rate * rate + q_first * acceleration)
        for values, bound, what, unit in (
            (speeds, velocity_limits, "speed", "/s"),
            (accelerations, limits.acceleration, "acceleration", "/s²"),
        ):
            ratios = values / bound
            j = int(np.argmax(ratios))
            if ratios[j] > 1.0 + _TOLERANCE and math.isfinite(bound[j]):
                base = "rad" if model.joints[j].is_revolute else "m"
                return (
                    f"the line may need {values[j]:.4g} {base}{unit} of {what} from joint '{model.joint_names[j]}' "
                    f"at {100.0 * s:.0f}% of the way, its limit is {bound[j]:.4g} {base}{unit}: the commands are "
                    "held to the limit there and the tool may lag or leave the line (lower max_linear_velocity/"
                    "max_linear_acceleration, or the angular ones, avoid it)"
                )
    return ""
