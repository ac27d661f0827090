"""Offline kinematic simulation of the resolved-rate control law.

Integrates ``q ← q + q̇·dt`` step by step with :class:`manip_kin.control.resolved_rate.CartesianController`
(an ideal velocity-controlled arm: the commanded rates are the joint velocities), clamping
``q`` into the position limits the way a real drive would
(:func:`manip_kin.control.integration.integrate_joint_rates`, as the ``robot_state`` node), and records the controlled
frame's pose, twist and errors. ``manip_kin simulate`` runs it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from manip_kin.control.integration import integrate_joint_rates
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig, ControlOutput
from manip_kin.core.kinematics import compiled_kinematics
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_jacobian import jacobian_of
from manip_kin.core.rotations import check_rotation
from manip_kin.errors import InvalidArgumentError

GoalPoseFunction = Callable[[float], np.ndarray]
GoalTwistFunction = Callable[[float], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class SimulationResult:
    """Outcome and record of :func:`simulate`.

    Errors are over the controller's task components (all six for a full task).

    Attributes:
        converged: True when both errors were below the tolerance (for a moving goal: at the
            end, having stayed below since ``time_to_converge``).
        time_to_converge: simulated time [s] at which the errors went (and stayed) below the
            tolerance, or None.
        final_position_error: position error norm at the end [m].
        final_orientation_error: orientation error norm at the end [rad].
        q_final: joint positions at the end, shape (n,).
        steps: number of control steps integrated.
        reason: why the run ended, in words (converged, duration elapsed, stalled at a limit,
            goal out of reach).
        task: name of the controlled task (see :mod:`manip_kin.core.pose_rows`).
        max_limit_violation: largest amount [rad | m] by which ``q + q̇·dt`` left the
            position limits before the clamp (0 when the controller respected them).
        max_velocity_ratio: largest ``|q̇ⱼ| / velocity_limitⱼ`` commanded.
        time: recorded times [s], shape (N,).
        q: recorded joint positions, shape (N, n).
        qdot: recorded commanded joint rates, shape (N, n) (zero at a final converged sample).
        frame_pose: recorded poses of the controlled frame in base, shape (N, 4, 4).
        twist: recorded frame twists ``[ω; v]`` w.r.t. base, in base, shape (N, 6) [rad/s, m/s].
        orientation_error: recorded orientation errors, shape (N, 3) [rad].
        position_error: recorded position errors, shape (N, 3) [m].
        manipulability: recorded ``sqrt(det(J Jᵀ))`` of the task Jacobian, shape (N,).
        damping: recorded damping λ, shape (N,).
        velocity_scale: recorded velocity scale factors, shape (N,).
        limited: recorded joints held at a position limit, shape (N, n), bool.
    """

    converged: bool
    time_to_converge: float | None
    final_position_error: float
    final_orientation_error: float
    q_final: np.ndarray
    steps: int
    reason: str
    task: str
    max_limit_violation: float
    max_velocity_ratio: float
    time: np.ndarray = field(repr=False)
    q: np.ndarray = field(repr=False)
    qdot: np.ndarray = field(repr=False)
    frame_pose: np.ndarray = field(repr=False)
    twist: np.ndarray = field(repr=False)
    orientation_error: np.ndarray = field(repr=False)
    position_error: np.ndarray = field(repr=False)
    manipulability: np.ndarray = field(repr=False)
    damping: np.ndarray = field(repr=False)
    velocity_scale: np.ndarray = field(repr=False)
    limited: np.ndarray = field(repr=False)

    @property
    def tool_pose(self) -> np.ndarray:
        """Alias of :attr:`frame_pose` (the controlled frame is the tool by default)."""
        return self.frame_pose


class _Recorder:
    """Preallocated arrays filled every ``every`` steps and at the end."""

    def __init__(self, model: RobotModel, frame_index: int, capacity: int):
        n = model.dof
        self._chain = compiled_kinematics(model, frame_index, True)
        self._n = n
        self.count = 0
        self.time = np.empty(capacity)
        self.q = np.empty((capacity, n))
        self.qdot = np.empty((capacity, n))
        self.frame_pose = np.empty((capacity, 4, 4))
        self.twist = np.empty((capacity, 6))
        self.orientation_error = np.empty((capacity, 3))
        self.position_error = np.empty((capacity, 3))
        self.manipulability = np.empty(capacity)
        self.damping = np.empty(capacity)
        self.velocity_scale = np.empty(capacity)
        self.limited = np.zeros((capacity, n), dtype=bool)

    def add(self, time: float, q: np.ndarray, output: ControlOutput, qdot: np.ndarray) -> None:
        i = self.count
        values = np.array(self._chain(q.tolist()))
        self.time[i] = time
        self.q[i] = q
        self.qdot[i] = qdot
        self.frame_pose[i] = values[:16].reshape(4, 4)
        self.twist[i] = jacobian_of(values, self._n) @ qdot
        self.orientation_error[i] = output.orientation_error
        self.position_error[i] = output.position_error
        self.manipulability[i] = output.manipulability
        self.damping[i] = output.damping
        self.velocity_scale[i] = output.velocity_scale
        self.limited[i, list(output.limited_joints)] = True
        self.count += 1

    def arrays(self) -> dict[str, np.ndarray]:
        k = self.count
        names = ("time", "q", "qdot", "frame_pose", "twist", "orientation_error", "position_error")
        names += ("manipulability", "damping", "velocity_scale", "limited")
        return {name: getattr(self, name)[:k].copy() for name in names}


def _check_pose(pose, what: str) -> np.ndarray:
    array = np.asarray(pose, dtype=float)
    if array.shape != (4, 4):
        raise InvalidArgumentError(f"{what} has shape {array.shape}; valid: a 4x4 homogeneous transform")
    if not np.all(np.isfinite(array)):
        raise InvalidArgumentError(f"{what} contains NaN or infinity; valid: finite values")
    check_rotation(array[:3, :3], f"{what} rotation")
    return array


def _positive(value: float, name: str, unit: str) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InvalidArgumentError(f"{name} = {value!r}; valid: a finite number > 0 [{unit}]")
    return float(value)


def simulate(
    model: RobotModel,
    q0: np.ndarray,
    goal_pose: np.ndarray,
    config: ControllerConfig = ControllerConfig(),
    dt: float = 0.001,
    duration: float = 20.0,
    tolerance: float = 1e-6,
    goal_twist_fn: GoalTwistFunction | None = None,
    goal_pose_fn: GoalPoseFunction | None = None,
    record_every: int = 1,
) -> SimulationResult:
    """Run the control law from ``q0`` towards a goal and report how and when it converged.

    Args:
        model: the robot.
        q0: start joint positions, shape (n,), within the position limits.
        goal_pose: goal pose of the controlled frame in base, shape (4, 4); the goal at
            every time when ``goal_pose_fn`` is None.
        config: the controller parameters (gains, frame, task, damping, limits).
        dt: control period and integration step [s].
        duration: simulated time limit [s].
        tolerance: convergence threshold on both the position error [m] and the orientation
            error [rad] (task components only).
        goal_twist_fn: optional ``t -> (angular [rad/s], linear [m/s])`` feed-forward of the goal.
        goal_pose_fn: optional ``t -> (4, 4)`` moving goal; then the run always lasts
            ``duration`` and converges when the error ends (and stays) below tolerance.
        record_every: record one sample every this many steps (the last state is always
            recorded).

    Returns:
        A :class:`SimulationResult`.
    """
    dt = _positive(dt, "dt", "s")
    duration = _positive(duration, "duration", "s")
    tolerance = _positive(tolerance, "tolerance", "m | rad")
    if not (isinstance(record_every, (int, np.integer)) and record_every >= 1):
        raise InvalidArgumentError(f"record_every = {record_every!r}; valid: an integer >= 1")
    q = model.check_q(q0, "q0").copy()
    if not model.within_limits(q, 1e-9):
        outside = [
            f"{joint.name}={value:.6g} not in [{joint.lower:.6g}, {joint.upper:.6g}]"
            for joint, value in zip(model.joints, q)
            if not joint.lower - 1e-9 <= value <= joint.upper + 1e-9
        ]
        raise InvalidArgumentError(f"q0 is outside the joint limits: {', '.join(outside)}")
    goal = _check_pose(goal_pose, "goal_pose")
    if goal_pose_fn is not None:
        goal = _check_pose(goal_pose_fn(0.0), "goal_pose_fn(0)")
    controller = CartesianController(model, config)
    task = controller.task
    steps_max = int(math.ceil(duration / dt - 1e-9))
    recorder = _Recorder(model, controller.frame_index, steps_max // record_every + 2)
    lower, upper = model.lower.tolist(), model.upper.tolist()
    inverse_velocity_limits = 1.0 / model.velocity_limits
    moving = goal_pose_fn is not None
    error_history = np.empty(steps_max + 1)  # task error norm per step, for the stall diagnosis
    max_violation = 0.0
    max_velocity_ratio = 0.0
    last_above: float | None = None  # last time the error was above tolerance
    converged_at: float | None = None
    step = 0
    output = None
    while True:
        time = step * dt
        if moving and step > 0:
            goal = np.asarray(goal_pose_fn(time), dtype=float)
        twist = goal_twist_fn(time) if goal_twist_fn is not None else None
        output = controller.step(q, goal, twist, dt)
        orientation, position = task.error_norms(output.orientation_error, output.position_error)
        error_history[step] = math.hypot(orientation, position)
        below = orientation < tolerance and position < tolerance
        if not below:
            last_above = time
        if below and not moving:
            converged_at = time
            recorder.add(time, q, output, np.zeros_like(q))
            break
        if step >= steps_max:
            recorder.add(time, q, output, output.qdot)
            break
        if step % record_every == 0:
            recorder.add(time, q, output, output.qdot)
        qdot = output.qdot
        max_velocity_ratio = max(max_velocity_ratio, float(np.max(np.abs(qdot) * inverse_velocity_limits)))
        # The drive stops at the limits whatever it is commanded (the controller already
        # respects the velocity limits, or was told not to: no scaling here).
        q_next, _, _, violation = integrate_joint_rates(q.tolist(), qdot.tolist(), dt, lower, upper)
        max_violation = max(max_violation, violation)
        q = np.array(q_next)
        step += 1
    final_orientation, final_position = task.error_norms(output.orientation_error, output.position_error)
    if moving and final_orientation < tolerance and final_position < tolerance:
        converged_at = last_above + dt if last_above is not None else 0.0
    converged = converged_at is not None
    gains = [config.gain_angular] * len(task.orientation_rows) + [config.gain_linear] * len(task.position_rows)
    reason = _reason(
        converged,
        converged_at,
        error_history[: step + 1],
        dt,
        duration,
        output,
        model,
        q,
        min(gains),
        final_position,
        final_orientation,
    )
    return SimulationResult(
        converged=converged,
        time_to_converge=converged_at,
        final_position_error=final_position,
        final_orientation_error=final_orientation,
        q_final=q.copy(),
        steps=step,
        reason=reason,
        task=task.name,
        max_limit_violation=max_violation,
        max_velocity_ratio=max_velocity_ratio,
        **recorder.arrays(),
    )


def _reason(
    converged: bool,
    converged_at: float | None,
    history: np.ndarray,
    dt: float,
    duration: float,
    output: ControlOutput,
    model: RobotModel,
    q_final: np.ndarray,
    slowest_gain: float,
    position: float,
    orientation: float,
) -> str:
    if converged:
        return f"converged: errors below tolerance after {converged_at:.3f} s"
    errors = f"position error {position:.3g} m, orientation error {orientation:.3g} rad"
    # Decay rate of the error over the last second (or the last quarter of a short run),
    # compared with the rate the gains ask for.
    window = max(1, min(int(round(1.0 / dt)), len(history) // 4))
    earlier, last = float(history[-1 - window]), float(history[-1])
    rate = math.log(earlier / last) / (window * dt) if earlier > 0.0 and last > 0.0 else 0.0
    if rate > 0.1 * slowest_gain:
        return f"duration {duration:g} s elapsed while the error was still decreasing at {rate:.3g}/s ({errors})"
    creeping = f" (it decays at {rate:.2g}/s, the gains ask for {slowest_gain:g}/s)" if rate > 1e-3 else ""
    at_limit = set(output.limited_joints) | {
        j for j, joint in enumerate(model.joints) if q_final[j] <= joint.lower or q_final[j] >= joint.upper
    }
    if at_limit:
        names = ", ".join(model.joints[j].name for j in sorted(at_limit))
        return f"stalled: {names} at a position limit, the error no longer decreases{creeping} ({errors})"
    if output.singular:
        return (
            "stalled at a singular configuration: the goal is out of reach; this is the closest pose "
            f"the arm reaches ({errors})"
        )
    return f"stalled: the error no longer decreases{creeping}, the goal is likely out of reach ({errors})"
