"""Can the arm follow a line? :func:`check_line_reachable` walks the line's samples with damped
least-squares steps within the joint limits from the start configuration, and reports how far it
got (:class:`ReachReport`), with the joint path for the timing check
(:mod:`manip_kin.motion.line_timing`) and the collision check of the path. Plain numpy: no ROS here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from manip_kin.core.damped_least_squares import damped_least_squares
from manip_kin.core.kinematics import KinematicsData, forward_kinematics, frame_in_base, geometric_jacobian_from_data
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import FULL_TASK, Task, parse_task
from manip_kin.core.rotations import matrix_to_rotvec
from manip_kin.motion.lines import LineTrajectory


@dataclass(frozen=True)
class ReachReport:
    """Result of :func:`check_line_reachable`.

    Attributes:
        reachable: True when every sample of the line was reached within tolerance.
        progress_reached: largest progress ``s`` [-] up to which every sample was reached.
        position_error: residual position error at the first failing sample [m] (0 if reachable).
        orientation_error: residual orientation error there [rad] (0 if reachable).
        q_end: joint positions at the last reached sample, shape (n,).
        reason: one line for a log ("" when reachable).
        progress: the progress of each reached sample, shape (K,).
        path: the joint positions at each reached sample, shape (K, n).
    """

    reachable: bool
    progress_reached: float
    position_error: float
    orientation_error: float
    q_end: np.ndarray
    reason: str = ""
    progress: np.ndarray = field(default_factory=lambda: np.zeros(0))
    path: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


def check_line_reachable(
    model: RobotModel,
    line: LineTrajectory,
    q_start,
    frame: str | None = None,
    max_step: float = 0.01,
    max_angle_step: float = 0.05,
    position_tolerance: float = 1e-4,
    orientation_tolerance: float = 1e-3,
    iterations: int = 30,
    damping: float = 1e-3,
    task: Task | str | None = FULL_TASK,
) -> ReachReport:
    """Follow the line with a joint-limited damped least-squares IK, from ``q_start`` on.

    Why continuation rather than an IK per sample: a resolved-rate controller tracks the
    line by moving continuously from the current configuration, so the question is not
    whether each pose has *some* IK solution, but whether the branch the arm is on reaches
    every pose without leaving the joint limits. Each sample is solved from the previous
    sample's solution (a few Newton steps each), which also makes this cheap: a 1 m line
    takes about 100 samples, a few milliseconds each.

    Args:
        model: the robot.
        line: the planned line.
        q_start: configuration at the start of the line, shape (n,).
        frame: controlled frame (default: tool if any, else ee).
        max_step: sample spacing along the position [m].
        max_angle_step: sample spacing along the orientation [rad].
        position_tolerance: reached when the position error is below this [m].
        orientation_tolerance: reached when the orientation error is below this [rad].
        iterations: Newton steps per sample at most.
        damping: λ of the damped least squares [-].
        task: the pose components that must be reached (see :mod:`manip_kin.core.pose_rows`; None = the
            model's default task); the others are free, e.g. the orientation of a position-only line.

    Returns:
        A :class:`ReachReport`.
    """
    q = model.clip_to_limits(model.check_q(q_start, "q_start"))
    frame_index = model.frame_index(model.default_frame if frame is None else frame)
    data = KinematicsData(model)
    count = max(2, int(math.ceil(max(line.length / max_step, line.angle / max_angle_step))) + 1)
    count = min(count, 2000)
    lower, upper = model.lower, model.upper
    task_of = parse_task(task, model)
    rows = list(task_of.rows)
    last_reached = 0.0
    path = []
    for s in np.linspace(0.0, 1.0, count):
        target = line.pose_at(float(s))
        position_error = orientation_error = math.inf
        for _ in range(iterations):
            forward_kinematics(model, data, q)
            current = data.tool if frame_index == model.dof + 2 else (data.ee if frame_index == model.dof + 1 else None)
            if current is None:
                current = frame_in_base(model, data, frame_index)
            error = np.concatenate(
                [matrix_to_rotvec(target[:3, :3] @ current[:3, :3].T), target[:3, 3] - current[:3, 3]]
            )
            orientation_error, position_error = task_of.error_norms(error[:3], error[3:])
            if position_error < position_tolerance and orientation_error < orientation_tolerance:
                break
            jac = geometric_jacobian_from_data(model, data, frame_index, current[:3, 3])
            q = _limited_dls_step(jac[rows], error[rows], q, lower, upper, damping)
        if not (position_error < position_tolerance and orientation_error < orientation_tolerance):
            reason = (
                f"line leaves the arm's reach at {100.0 * s:.0f}% of the way "
                f"(at {np.round(target[:3, 3], 4).tolist()} m): residual {position_error:.4g} m, "
                f"{orientation_error:.4g} rad within the joint limits (task {task_of.name}); "
                f"{_why_stuck(model, data, frame_index, q, rows)}"
            )
            return ReachReport(False, last_reached, position_error, orientation_error, q, reason)
        last_reached = float(s)
        path.append(q.copy())
    return ReachReport(True, 1.0, 0.0, 0.0, q, "", np.linspace(0.0, 1.0, count), np.array(path))


def _why_stuck(model: RobotModel, data: KinematicsData, frame_index: int, q: np.ndarray, rows: list[int]) -> str:
    """Why the continuation stopped at ``q``: joints at their limits, or a singular arm."""
    at_limit = [
        name
        for name, value, low, high in zip(model.joint_names, q, model.lower, model.upper)
        if value <= low + 1e-6 or value >= high - 1e-6
    ]
    if at_limit:
        return f"joints at a position limit there: {', '.join(at_limit)}"
    forward_kinematics(model, data, q)
    origin = frame_in_base(model, data, frame_index)[:3, 3]
    jac = geometric_jacobian_from_data(model, data, frame_index, origin)[rows]
    sigma_min = float(np.linalg.svd(jac, compute_uv=False)[-1]) if jac.shape[0] <= jac.shape[1] else 0.0
    if sigma_min < 1e-2:
        return f"the arm is at a singularity there (smallest singular value {sigma_min:.2g}): outside its workspace"
    return "no configuration within the joint limits continues the line from the arm's current branch"


def _limited_dls_step(jac, error, q, lower, upper, damping) -> np.ndarray:
    """One damped least-squares step, re-solved without joints the limits stop (two passes)."""
    active = np.ones(q.shape[0], dtype=bool)
    step = np.zeros_like(q)
    for _ in range(3):
        j = jac[:, active]
        step_active = damped_least_squares(j, error, damping)
        step[:] = 0.0
        step[active] = step_active
        blocked = ((q <= lower + 1e-12) & (step < 0)) | ((q >= upper - 1e-12) & (step > 0))
        if not np.any(blocked & active):
            break
        active &= ~blocked
        if not np.any(active):
            break
    return np.clip(q + step, lower, upper)
