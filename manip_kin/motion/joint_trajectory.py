"""Joint-space trajectories: waypoints with times, interpolated with a time scaling.

The input is what ``trajectory_msgs/JointTrajectory`` carries (as ros2_control's
JointTrajectoryController takes it): joint names, and points with ``time_from_start``
[s], positions [rad | m] and optional velocities [rad/s | m/s]. The motion starts at the
arm's current configuration at rest (t = 0) and passes through every point at its time.

Between two points ``(t_i, q_i, v_i)`` and ``(t_{i+1}, q_{i+1}, v_{i+1})``, with
``h = t_{i+1} - t_i`` and ``τ = (t - t_i) / h``::

    q(t) = q_i + s(τ) (q_{i+1} - q_i) + h (b_0(τ) v_i + b_1(τ) v_{i+1})

``s`` is the time scaling (the same ``s`` a line uses, :class:`manip_kin.motion.lines.TimeScaling`):

* ``cubic`` ``s = 3τ² − 2τ³`` with the cubic Hermite velocity terms ``b_0 = τ − 2τ² + τ³``,
  ``b_1 = −τ² + τ³``: position and velocity continuous at every point;
* ``quintic`` ``s = 10τ³ − 15τ⁴ + 6τ⁵`` with the quintic Hermite terms of zero end
  accelerations ``b_0 = τ − 6τ³ + 8τ⁴ − 3τ⁵``, ``b_1 = −4τ³ + 7τ⁴ − 3τ⁵``: acceleration
  continuous too (zero at every point);
* ``trapezoidal``: constant acceleration for the first third of each segment, constant
  velocity (1.5 times the mean) for the second, deceleration for the last; it stops at every
  point, so points with non-zero velocities are rejected.

Without velocities every point is passed at rest. The last point must be at rest (the
generator holds it). Every point must lie within the joint limits, and no joint may need
more than its velocity limit anywhere (checked on 64 samples per segment and at the
polynomials' peak), nor more than its acceleration limit, nor (on a segment from rest to
rest) its jerk limit: a trajectory that breaks a limit is rejected with the reason. A single
point at ``time_from_start`` 0 means "as soon as the limits allow" (:func:`move_duration`).

Jerk: the quintic's is ``60 |Δq| / h³`` at its ends and bounded everywhere; the cubic and the
trapezoid step their acceleration at the ends of a segment (and the trapezoid at its corners),
so only their interior jerk (``12 |Δq| / h³``, and 0) is checked: the controller's command
filter (:mod:`manip_kin.control.command_filter`) rounds those steps off within the jerk limit.

Plain numpy: no ROS here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from manip_kin.control.joint_limits import JointLimits
from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError, ProblemKind
from manip_kin.motion.lines import TimeScaling

JOINT_TIME_SCALINGS = ("cubic", "quintic", "trapezoidal")

#: Peak ``ds/dτ`` of each scaling: the fastest joint moves at this times its mean speed.
PEAK_RATE = {"cubic": 1.5, "quintic": 1.875, "trapezoidal": 1.5}
#: Peak ``|d²s/dτ²|``: cubic 6 − 12τ at the ends, quintic 60τ − 180τ² + 120τ³ at τ = (3 ∓ √3)/6,
#: trapezoid 1.5 / (1/3) while it ramps.
PEAK_ACCELERATION = {"cubic": 6.0, "quintic": 10.0 / math.sqrt(3.0), "trapezoidal": 4.5}
#: Peak ``|d³s/dτ³|`` inside a segment (see the module docstring for the ends).
PEAK_JERK = {"cubic": 12.0, "quintic": 60.0, "trapezoidal": 0.0}

#: Shortest duration :func:`move_duration` returns [s] (a move of zero length still takes a moment).
MIN_MOVE_DURATION = 0.1

_UNIT_SCALINGS = {
    "cubic": TimeScaling("cubic", 1.0),
    "quintic": TimeScaling("quintic", 1.0),
    "trapezoidal": TimeScaling("trapezoidal", 1.0, 1.0 / 3.0),
}
_VELOCITY_TOLERANCE = 1e-6  # relative slack of the velocity-limit check (a move sized exactly at the limit passes)


def _check_scaling(scaling: str) -> None:
    if scaling not in JOINT_TIME_SCALINGS:
        raise InvalidArgumentError(f"time scaling {scaling!r}; valid: {', '.join(JOINT_TIME_SCALINGS)}")


def _velocity_basis(scaling: str, tau):
    """``(b_0, b_1, b_0', b_1')`` of the Hermite velocity terms at ``τ`` (derivatives w.r.t. τ)."""
    tau2 = tau * tau
    tau3 = tau2 * tau
    if scaling == "cubic":
        return tau - 2.0 * tau2 + tau3, -tau2 + tau3, 1.0 - 4.0 * tau + 3.0 * tau2, -2.0 * tau + 3.0 * tau2
    tau4 = tau3 * tau
    return (
        tau - 6.0 * tau3 + 8.0 * tau4 - 3.0 * tau4 * tau,
        -4.0 * tau3 + 7.0 * tau4 - 3.0 * tau4 * tau,
        1.0 - 18.0 * tau2 + 32.0 * tau3 - 15.0 * tau4,
        -12.0 * tau2 + 28.0 * tau3 - 15.0 * tau4,
    )


@dataclass(frozen=True)
class JointTrajectoryPlan:
    """A joint-space trajectory through timed points (see the module docstring).

    Attributes:
        times: point times [s], strictly increasing, ``times[0] = 0`` (the start), shape (K+1,).
        positions: point positions in model joint order [rad | m], shape (K+1, n).
        velocities: point velocities [rad/s | m/s], shape (K+1, n); the first and last rows are zero.
        scaling: one of :data:`JOINT_TIME_SCALINGS`.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    scaling: str

    @property
    def duration(self) -> float:
        """Total time [s]."""
        return float(self.times[-1])

    @property
    def point_count(self) -> int:
        """Number of points, the start not counted."""
        return int(self.times.shape[0]) - 1

    @property
    def goal(self) -> np.ndarray:
        """The last point's positions, shape (n,)."""
        return self.positions[-1]

    def progress_at(self, t: float) -> float:
        """Fraction of the duration elapsed at ``t`` [s], in [0, 1]."""
        return min(max(t / self.duration, 0.0), 1.0)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Positions [rad | m] and velocities [rad/s | m/s] at ``t`` [s], shapes (n,).

        Before the start: the start at rest; after the end: the last point at rest.
        """
        times = self.times
        if t <= 0.0:
            return self.positions[0].copy(), np.zeros(self.positions.shape[1])
        if t >= times[-1]:
            return self.positions[-1].copy(), np.zeros(self.positions.shape[1])
        i = int(np.searchsorted(times, t, side="right")) - 1
        h = float(times[i + 1] - times[i])
        tau = (t - float(times[i])) / h
        s, sdot, _ = _UNIT_SCALINGS[self.scaling].evaluate(tau)
        q0, q1 = self.positions[i], self.positions[i + 1]
        delta = q1 - q0
        q = q0 + s * delta
        qdot = (sdot / h) * delta
        if self.scaling != "trapezoidal":
            v0, v1 = self.velocities[i], self.velocities[i + 1]
            b0, b1, db0, db1 = _velocity_basis(self.scaling, tau)
            q = q + h * (b0 * v0 + b1 * v1)
            qdot = qdot + db0 * v0 + db1 * v1
        return q, qdot


def _peak_speeds(plan: JointTrajectoryPlan) -> np.ndarray:
    """Largest ``|q̇|`` per segment and joint [rad/s | m/s], shape (K, n).

    64 samples per segment, plus the exact peak ``PEAK_RATE · |Δq| / h`` of a segment at rest
    at both ends (the samples may straddle it).
    """
    taus = np.linspace(0.0, 1.0, 65)
    peaks = np.zeros((plan.point_count, plan.positions.shape[1]))
    for i in range(plan.point_count):
        h = float(plan.times[i + 1] - plan.times[i])
        delta = np.abs(plan.positions[i + 1] - plan.positions[i])
        peaks[i] = PEAK_RATE[plan.scaling] * delta / h
        if plan.scaling != "trapezoidal" and (plan.velocities[i].any() or plan.velocities[i + 1].any()):
            t0 = float(plan.times[i])
            speeds = np.array([np.abs(plan.sample(t0 + tau * h)[1]) for tau in taus[1:-1]])
            ends = np.abs(np.stack([plan.velocities[i], plan.velocities[i + 1]]))
            peaks[i] = np.max(np.vstack([speeds, ends]), axis=0)
    return peaks


def _peak_accelerations(plan: JointTrajectoryPlan) -> tuple[np.ndarray, np.ndarray]:
    """Largest ``|q̈|`` and ``|q⃛|`` per segment and joint, shapes (K, n).

    Exact for a segment at rest at both ends (``PEAK_ACCELERATION · |Δq| / h²``,
    ``PEAK_JERK · |Δq| / h³``); with velocities, the acceleration from 128 finite differences
    of the sampled velocity, and the jerk not checked (0).
    """
    count = plan.positions.shape[1]
    accelerations, jerks = np.zeros((plan.point_count, count)), np.zeros((plan.point_count, count))
    for i in range(plan.point_count):
        h = float(plan.times[i + 1] - plan.times[i])
        delta = np.abs(plan.positions[i + 1] - plan.positions[i])
        if plan.scaling != "trapezoidal" and (plan.velocities[i].any() or plan.velocities[i + 1].any()):
            t0 = float(plan.times[i])
            speeds = np.array([plan.sample(t0 + tau * h)[1] for tau in np.linspace(0.0, 1.0, 129)])
            accelerations[i] = np.max(np.abs(np.diff(speeds, axis=0)), axis=0) / (h / 128)
        else:
            accelerations[i] = PEAK_ACCELERATION[plan.scaling] * delta / h**2
            jerks[i] = PEAK_JERK[plan.scaling] * delta / h**3
    return accelerations, jerks


def _check_peaks(model: RobotModel, plan: JointTrajectoryPlan, peaks: np.ndarray, limit, quantity: str, unit: str):
    ratios = peaks / np.asarray(limit)
    segment, joint = np.unravel_index(int(np.argmax(ratios)), ratios.shape)
    if ratios[segment, joint] > 1.0 + _VELOCITY_TOLERANCE:
        base = "rad" if model.joints[joint].is_revolute else "m"
        raise InvalidArgumentError(
            f"point {segment + 1} (at {plan.times[segment + 1]:g} s) is reached too fast: joint "
            f"'{model.joint_names[joint]}' needs {peaks[segment, joint]:.4g} {base}{unit} of {quantity}, "
            f"its limit is {limit[joint]:g} {base}{unit}; valid: later time_from_start",
            kind=ProblemKind.SPEED,
        )


def check_limits(model: RobotModel, plan: JointTrajectoryPlan, limits: JointLimits | None = None) -> None:
    """Raise :class:`InvalidArgumentError` when some joint needs more than its velocity limit
    (the model's, or the lower of it and ``limits``), or more than the acceleration or jerk
    limit of ``limits``."""
    velocity = model.velocity_limits if limits is None else np.minimum(model.velocity_limits, limits.velocity)
    _check_peaks(model, plan, _peak_speeds(plan), velocity, "speed", "/s")
    if limits is not None:
        accelerations, jerks = _peak_accelerations(plan)
        _check_peaks(model, plan, accelerations, limits.acceleration, "acceleration", "/s²")
        _check_peaks(model, plan, jerks, limits.jerk, "jerk", "/s³")


@dataclass(frozen=True)
class TrajectoryPoint:
    """One point of a joint trajectory, in the order of the trajectory's joint names.

    Attributes:
        time_from_start: [s].
        positions: [rad | m], one per joint name.
        velocities: [rad/s | m/s], one per joint name, or empty (at rest).
    """

    time_from_start: float
    positions: Sequence[float]
    velocities: Sequence[float] = ()


def _joint_order(model: RobotModel, joint_names: Sequence[str]) -> np.ndarray:
    """Index into the trajectory's joints of each model joint; raises on wrong or missing names."""
    names = list(joint_names)
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise InvalidArgumentError(
            f"joint names {duplicates} appear more than once; valid: each joint once", kind=ProblemKind.LENGTH
        )
    unknown = [name for name in names if name not in model.joint_names]
    if unknown:
        raise InvalidArgumentError(f"joints {unknown} are not joints of {model.name}; valid: {model.joint_names}")
    missing = [name for name in model.joint_names if name not in names]
    if missing:
        raise InvalidArgumentError(
            f"trajectory lacks joints {missing}; valid: every joint of {model.name} named: {model.joint_names}",
            kind=ProblemKind.LENGTH,
        )
    return np.array([names.index(name) for name in model.joint_names], dtype=np.intp)


def plan_joint_trajectory(
    model: RobotModel,
    q_start,
    joint_names: Sequence[str],
    points: Sequence[TrajectoryPoint],
    scaling: str = "cubic",
    limits: JointLimits | None = None,
) -> JointTrajectoryPlan:
    """Check a trajectory against the model and plan it from ``q_start`` at rest.

    Args:
        model: the robot (joint names, position and velocity limits).
        q_start: current configuration in model joint order, shape (n,).
        joint_names: the trajectory's joint names (any order; every model joint, each once).
        points: the points, times strictly increasing and > 0.
        scaling: one of :data:`JOINT_TIME_SCALINGS`.
        limits: velocity, acceleration and jerk limits to check as well (None: the model's
            velocity limits only). One point at time 0 is timed by :func:`move_duration`.

    Raises:
        InvalidArgumentError: with the reason (names, times, counts, non-finite values,
            positions outside the limits, velocities beyond the limits, a last point not at rest).
    """
    _check_scaling(scaling)
    q_start = model.check_q(q_start, "q_start")
    order = _joint_order(model, joint_names)
    if not points:
        raise InvalidArgumentError("trajectory has no points; valid: at least one point")
    count = len(order)
    times, positions, velocities = [0.0], [q_start], [np.zeros(count)]
    as_soon_as_possible = len(points) == 1 and float(points[0].time_from_start) == 0.0 and not len(points[0].velocities)
    for k, point in enumerate(points, start=1):
        time = float(point.time_from_start)
        if as_soon_as_possible:
            time = move_duration(model, q_start, np.asarray(point.positions, dtype=float)[order], scaling, limits)
        if not (math.isfinite(time) and time > times[-1]):
            previous = "0 (the start)" if k == 1 else f"point {k - 1}'s {times[-1]:g} s"
            raise InvalidArgumentError(
                f"point {k} time_from_start {time:g} s is not after {previous}; valid: strictly increasing times > 0"
            )
        values = np.asarray(point.positions, dtype=float)
        rates = np.asarray(point.velocities, dtype=float)
        if values.shape != (count,):
            raise InvalidArgumentError(
                f"point {k} has {values.size} positions; valid: {count}, one per joint name", kind=ProblemKind.LENGTH
            )
        if rates.size and rates.shape != (count,):
            raise InvalidArgumentError(
                f"point {k} has {rates.size} velocities; valid: none or {count}, one per joint name",
                kind=ProblemKind.LENGTH,
            )
        if not (np.all(np.isfinite(values)) and np.all(np.isfinite(rates))):
            raise InvalidArgumentError(
                f"point {k} contains NaN or infinity; valid: finite numbers", kind=ProblemKind.NON_FINITE
            )
        q = values[order]
        outside = np.flatnonzero((q < model.lower) | (q > model.upper))
        if outside.size:
            j = int(outside[0])
            unit = "rad" if model.joints[j].is_revolute else "m"
            raise InvalidArgumentError(
                f"point {k}: joint '{model.joint_names[j]}' = {q[j]:.6g} {unit} is outside its limits; "
                f"valid: [{model.lower[j]:.6g}, {model.upper[j]:.6g}] {unit}",
                kind=ProblemKind.RANGE,
            )
        times.append(time)
        positions.append(q)
        velocities.append(rates[order] if rates.size else np.zeros(count))
    if np.any(velocities[-1]):
        raise InvalidArgumentError("the last point has non-zero velocities; valid: the trajectory ends at rest")
    if scaling == "trapezoidal" and any(np.any(v) for v in velocities):
        raise InvalidArgumentError(
            "trapezoidal scaling stops at every point; valid: points without velocities, or cubic/quintic scaling"
        )
    plan = JointTrajectoryPlan(np.array(times), np.array(positions), np.array(velocities), scaling)
    check_limits(model, plan, limits)
    return plan


def move_duration(
    model: RobotModel, q_start, q_goal, scaling: str = "cubic", limits: JointLimits | None = None
) -> float:
    """Shortest duration [s] of a move from ``q_start`` to ``q_goal`` (both at rest) within the limits.

    The slowest joint sets it: ``T = max(PEAK_RATE·|Δq|/v, sqrt(PEAK_ACCELERATION·|Δq|/A),
    cbrt(PEAK_JERK·|Δq|/J))`` over the joints (velocity only without ``limits``), at least
    :data:`MIN_MOVE_DURATION`.
    """
    _check_scaling(scaling)
    delta = np.abs(model.check_q(q_goal, "q_goal") - model.check_q(q_start, "q_start"))
    if limits is None:
        return max(PEAK_RATE[scaling] * float(np.max(delta / model.velocity_limits)), MIN_MOVE_DURATION)
    velocity = np.minimum(model.velocity_limits, limits.velocity)
    duration = max(
        PEAK_RATE[scaling] * float(np.max(delta / velocity)),
        math.sqrt(PEAK_ACCELERATION[scaling] * float(np.max(delta / limits.acceleration))),
        math.cbrt(PEAK_JERK[scaling] * float(np.max(delta / limits.jerk))),
        MIN_MOVE_DURATION,
    )
    # The check allows a relative 1e-6 over each limit: stay inside it after rounding.
    return duration * (1.0 + 1e-9)
