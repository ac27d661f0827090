"""Straight-line pose trajectories with time scalings (whether the arm can follow one:
:mod:`manip_kin.motion.line_reach`).

A line goes from a start pose to a goal pose (4x4, base frame): the position moves along
the segment, the orientation turns about one fixed axis at a rate proportional to the
position's progress (the same path as quaternion slerp, computed as
``R(s) = R0 · exp(s · log(R0ᵀ R1))``). The progress ``s ∈ [0, 1]`` follows a time
scaling ``s(t)``:

* ``trapezoidal``: accelerate at the acceleration limit, cruise at the velocity limit,
  decelerate (a triangle when the line is too short to reach the cruise speed);
* ``cubic`` and ``quintic``: polynomials with zero end velocities (quintic: zero end
  accelerations too);
* ``jerk_limited``: the trapezoid with its corners rounded: the acceleration builds and
  falls at the jerk limit instead of stepping, so the joint rates a controller follows along
  it change without the jerk steps a trapezoid's corners ask for (which a jerk-limited
  command filter can only follow late, off the line);
* ``constant``: constant speed from the first instant to the last, velocity jumps at both
  ends (the irb120 scenario (b): 0.4 m/s along the line).

Every scaling is sized by the same limits: the shortest duration for which the linear
speed stays at or below ``max_linear_velocity`` [m/s], the angular speed at or below
``max_angular_velocity`` [rad/s] and, except for ``constant``, the accelerations at or
below ``max_linear_acceleration`` [m/s²] and ``max_angular_acceleration`` [rad/s²], and
for ``jerk_limited`` the jerks at or below ``max_linear_jerk`` [m/s³] and
``max_angular_jerk`` [rad/s³].

Plain numpy: no ROS here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from manip_kin.core.rotations import check_rotation, matrix_to_rotvec, rotvec_to_matrix
from manip_kin.errors import InvalidArgumentError, check_finite

TIME_SCALINGS = ("trapezoidal", "cubic", "quintic", "constant", "jerk_limited")


@dataclass(frozen=True)
class MotionLimits:
    """Cartesian limits that size a time scaling.

    Attributes:
        max_linear_velocity: [m/s], > 0.
        max_linear_acceleration: [m/s²], > 0 (not used by ``constant``).
        max_angular_velocity: [rad/s], > 0.
        max_angular_acceleration: [rad/s²], > 0 (not used by ``constant``).
        max_linear_jerk: [m/s³], > 0 (``jerk_limited`` only).
        max_angular_jerk: [rad/s³], > 0 (``jerk_limited`` only).
    """

    max_linear_velocity: float = 0.25
    max_linear_acceleration: float = 0.5
    max_angular_velocity: float = 0.5
    max_angular_acceleration: float = 1.0
    # The default accelerations build up in 0.1 s.
    max_linear_jerk: float = 5.0
    max_angular_jerk: float = 10.0

    def __post_init__(self):
        for name in (
            "max_linear_velocity",
            "max_linear_acceleration",
            "max_angular_velocity",
            "max_angular_acceleration",
            "max_linear_jerk",
            "max_angular_jerk",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InvalidArgumentError(f"{name} = {value}; valid: a positive finite number")


@dataclass(frozen=True)
class TimeScaling:
    """Progress ``s(t)`` from 0 to 1 over ``duration`` seconds.

    Attributes:
        kind: one of :data:`TIME_SCALINGS`.
        duration: total time [s], >= 0.
        ramp_time: acceleration (= deceleration) time of ``trapezoidal`` and ``jerk_limited``
            [s]; 0 otherwise.
        jerk_time: of ``jerk_limited``, the time [s] the acceleration takes to build up (and
            to fall) at the jerk limit within each ramp, <= ``ramp_time / 2``; 0 otherwise.
    """

    kind: str
    duration: float
    ramp_time: float = 0.0
    jerk_time: float = 0.0

    def evaluate(self, t: float) -> tuple[float, float, float]:
        """Progress ``s`` [-], its rate ``ṡ`` [1/s] and ``s̈`` [1/s²] at time ``t`` [s].

        Before 0 the line has not started (s = 0, at rest); after ``duration`` it is
        finished (s = 1, at rest).
        """
        duration = self.duration
        if duration <= 0.0 or t >= duration:
            return 1.0, 0.0, 0.0
        if t <= 0.0:
            return 0.0, 0.0, 0.0
        kind = self.kind
        if kind == "constant":
            return t / duration, 1.0 / duration, 0.0
        if kind == "cubic":
            tau = t / duration
            return (3.0 - 2.0 * tau) * tau * tau, 6.0 * tau * (1.0 - tau) / duration, (6.0 - 12.0 * tau) / duration**2
        if kind == "quintic":
            tau = t / duration
            tau2 = tau * tau
            s = tau2 * tau * (10.0 - 15.0 * tau + 6.0 * tau2)
            sdot = 30.0 * tau2 * (1.0 - tau) ** 2 / duration
            sddot = 60.0 * tau * (1.0 - 3.0 * tau + 2.0 * tau2) / duration**2
            return s, sdot, sddot
        # trapezoidal and jerk_limited: ramp up to the peak rate v = 1 / (duration - ramp),
        # cruise, and ramp down as the first ramp mirrored in time.
        ramp = self.ramp_time
        peak = 1.0 / (duration - ramp)
        if t < ramp:
            return self._ramp(t, peak)
        if t <= duration - ramp:
            return 0.5 * peak * ramp + peak * (t - ramp), peak, 0.0
        s, sdot, sddot = self._ramp(duration - t, peak)
        return 1.0 - s, sdot, -sddot

    def _ramp(self, t: float, peak: float) -> tuple[float, float, float]:
        """``(s, ṡ, s̈)`` at ``0 <= t <= ramp_time`` of the ramp from rest up to ``peak`` [1/s].

        The acceleration ``a = peak / (ramp - jerk_time)`` is reached at the jerk
        ``a / jerk_time`` and held (at once when ``jerk_time`` is 0: the trapezoid); the rate is
        symmetric about the ramp's middle, so the ramp covers ``peak · ramp / 2``.
        """
        ramp, rise = self.ramp_time, self.jerk_time
        accel = peak / (ramp - rise)
        if rise <= 0.0:
            return 0.5 * accel * t * t, accel * t, accel
        jerk = accel / rise
        if t < rise:
            return jerk * t**3 / 6.0, 0.5 * jerk * t * t, jerk * t
        if t <= ramp - rise:
            held = t - rise
            return (
                accel * rise * rise / 6.0 + 0.5 * accel * rise * held + 0.5 * accel * held * held,
                0.5 * accel * rise + accel * held,
                accel,
            )
        left = ramp - t  # the rise mirrored: ṡ(ramp - u) = peak - ṡ(u)
        return 0.5 * peak * ramp - peak * left + jerk * left**3 / 6.0, peak - 0.5 * jerk * left * left, jerk * left

    @property
    def peak_rate(self) -> float:
        """Largest ``ṡ`` [1/s] over the motion."""
        if self.duration <= 0.0:
            return 0.0
        return {
            "constant": 1.0,
            "cubic": 1.5,
            "quintic": 1.875,
            "trapezoidal": self.duration / max(self.duration - self.ramp_time, 1e-300),
            "jerk_limited": self.duration / max(self.duration - self.ramp_time, 1e-300),
        }[self.kind] / self.duration


# Peak ṡ·T and peak |s̈|·T² of the unit polynomials: cubic 6τ(1-τ) peaks at 1.5, its
# acceleration 6 - 12τ at 6; quintic 30τ²(1-τ)² peaks at 1.875, its acceleration at 10/√3.
_PEAK_RATE = {"cubic": 1.5, "quintic": 1.875}
_PEAK_ACCEL = {"cubic": 6.0, "quintic": 10.0 / math.sqrt(3.0)}


def make_time_scaling(kind: str, length: float, angle: float, limits: MotionLimits) -> TimeScaling:
    """The fastest scaling of ``kind`` that keeps a line within ``limits``.

    Args:
        kind: one of :data:`TIME_SCALINGS`.
        length: distance travelled by the position [m], >= 0.
        angle: rotation angle of the orientation [rad], >= 0.
        limits: velocity and acceleration limits.

    Returns:
        The scaling; duration 0 for a line of zero length and zero angle.
    """
    if kind not in TIME_SCALINGS:
        raise InvalidArgumentError(f"unknown time scaling {kind!r}; valid: {', '.join(TIME_SCALINGS)}")
    if not (0.0 <= length < math.inf and 0.0 <= angle < math.inf):
        raise InvalidArgumentError(f"line of {length} m, {angle} rad; valid: finite, non-negative length and angle")
    # Largest allowed ṡ and s̈: each Cartesian limit divided by the distance it applies to.
    rate_limit = min(_ratio(limits.max_linear_velocity, length), _ratio(limits.max_angular_velocity, angle))
    accel_limit = min(_ratio(limits.max_linear_acceleration, length), _ratio(limits.max_angular_acceleration, angle))
    if math.isinf(rate_limit):
        return TimeScaling(kind, 0.0)
    # A line so long (or limits so small) that the ratios underflow would divide by zero below.
    if not (rate_limit > 1e-150 and accel_limit > 1e-150):
        raise InvalidArgumentError(
            f"line of {length:.6g} m, {angle:.6g} rad cannot be timed within the limits; "
            "valid: a line whose duration is a finite number of seconds"
        )
    if kind == "constant":
        return TimeScaling(kind, 1.0 / rate_limit)
    if kind in _PEAK_RATE:
        duration = max(_PEAK_RATE[kind] / rate_limit, math.sqrt(_PEAK_ACCEL[kind] / accel_limit))
        return TimeScaling(kind, duration)
    if kind == "jerk_limited":
        jerk_limit = min(_ratio(limits.max_linear_jerk, length), _ratio(limits.max_angular_jerk, angle))
        return _jerk_limited(rate_limit, accel_limit, jerk_limit)
    # Trapezoid: cruise at rate_limit when the ramps leave room, else a triangle.
    ramp = rate_limit / accel_limit
    if rate_limit * ramp >= 1.0:
        ramp = math.sqrt(1.0 / accel_limit)
        return TimeScaling(kind, 2.0 * ramp, ramp)
    return TimeScaling(kind, 1.0 / rate_limit + ramp, ramp)


def _jerk_limited(rate_limit: float, accel_limit: float, jerk_limit: float) -> TimeScaling:
    """The fastest rest-to-rest ``jerk_limited`` scaling with ``ṡ``, ``s̈`` and ``s⃛`` within the
    limits [1/s, 1/s², 1/s³] (the double-S profile of a unit distance)."""
    if not jerk_limit > 1e-150:
        raise InvalidArgumentError("a jerk limit this small cannot time the line; valid: a finite duration")

    def ramp_of(peak: float) -> tuple[float, float]:
        """(ramp, jerk_time) of the shortest ramp from rest to ``peak``."""
        if peak * jerk_limit >= accel_limit * accel_limit:  # the acceleration limit is reached
            rise = accel_limit / jerk_limit
            return peak / accel_limit + rise, rise
        rise = math.sqrt(peak / jerk_limit)
        return 2.0 * rise, rise

    ramp, rise = ramp_of(rate_limit)
    if rate_limit * ramp <= 1.0:  # the two ramps cover peak · ramp: room to cruise
        return TimeScaling("jerk_limited", 1.0 / rate_limit + ramp, ramp, rise)
    # No cruise: the peak whose two ramps cover the whole line, peak · ramp(peak) = 1.
    rise = accel_limit / jerk_limit
    peak = 0.5 * accel_limit * (math.sqrt(rise * rise + 4.0 / accel_limit) - rise)
    if peak * jerk_limit < accel_limit * accel_limit:
        peak = (0.25 * jerk_limit) ** (1.0 / 3.0)
    ramp, rise = ramp_of(peak)
    return TimeScaling("jerk_limited", 2.0 * ramp, ramp, rise)


def _ratio(limit: float, distance: float) -> float:
    return math.inf if distance <= 1e-12 else limit / distance


@dataclass(frozen=True)
class LineTrajectory:
    """A straight-line pose trajectory from ``start`` to ``goal`` in the base frame.

    Attributes:
        start: start pose, shape (4, 4).
        goal: goal pose, shape (4, 4).
        scaling: the time scaling ``s(t)``.
        displacement: ``p_goal - p_start`` [m], shape (3,).
        rotation_axis_angle: rotation vector of ``R_startᵀ R_goal`` [rad], in the start frame, shape (3,).
        angular_direction: the same vector expressed in base [rad], shape (3,).
    """

    start: np.ndarray
    goal: np.ndarray
    scaling: TimeScaling
    displacement: np.ndarray = field(init=False, repr=False)
    rotation_axis_angle: np.ndarray = field(init=False, repr=False)
    angular_direction: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        start = np.array(self.start, dtype=float)
        goal = np.array(self.goal, dtype=float)
        for pose, what in ((start, "start pose"), (goal, "goal pose")):
            if pose.shape != (4, 4):
                raise InvalidArgumentError(f"{what} has shape {pose.shape}; valid: (4, 4)")
            check_finite(pose, what)
            check_rotation(pose[:3, :3], f"{what} rotation")
        rotvec = matrix_to_rotvec(start[:3, :3].T @ goal[:3, :3])
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "goal", goal)
        object.__setattr__(self, "displacement", goal[:3, 3] - start[:3, 3])
        object.__setattr__(self, "rotation_axis_angle", rotvec)
        object.__setattr__(self, "angular_direction", start[:3, :3] @ rotvec)

    @classmethod
    def plan(cls, start, goal, kind: str = "trapezoidal", limits: MotionLimits = MotionLimits()) -> LineTrajectory:
        """A line from ``start`` to ``goal`` timed by the fastest ``kind`` scaling within ``limits``."""
        start = check_finite(start, "start pose")
        goal = check_finite(goal, "goal pose")
        for pose, what in ((start, "start pose"), (goal, "goal pose")):
            if pose.shape != (4, 4):
                raise InvalidArgumentError(f"{what} has shape {pose.shape}; valid: (4, 4)")
            check_rotation(pose[:3, :3], f"{what} rotation")
        with np.errstate(over="ignore"):  # a distance past 1e308 m is inf, which the scaling rejects
            length = float(np.linalg.norm(goal[:3, 3] - start[:3, 3]))
        angle = float(np.linalg.norm(matrix_to_rotvec(start[:3, :3].T @ goal[:3, :3])))
        return cls(start, goal, make_time_scaling(kind, length, angle, limits))

    @property
    def length(self) -> float:
        """Distance the position travels [m]."""
        return float(np.linalg.norm(self.displacement))

    @property
    def angle(self) -> float:
        """Angle the orientation turns [rad]."""
        return float(np.linalg.norm(self.rotation_axis_angle))

    @property
    def duration(self) -> float:
        """Total time [s]."""
        return self.scaling.duration

    def progress_at(self, t: float) -> float:
        """Progress ``s ∈ [0, 1]`` at time ``t`` [s] from the start."""
        return self.scaling.evaluate(t)[0]

    def pose_at(self, progress: float) -> np.ndarray:
        """The pose at progress ``s ∈ [0, 1]``, shape (4, 4)."""
        pose = np.eye(4)
        pose[:3, :3] = self.start[:3, :3] @ rotvec_to_matrix(self.rotation_axis_angle * progress)
        pose[:3, 3] = self.start[:3, 3] + self.displacement * progress
        return pose

    def sample(self, t: float) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """Pose and twist at time ``t`` [s] from the start.

        Returns:
            ``(pose, (angular, linear))``: pose in base, shape (4, 4); angular velocity
            [rad/s] and linear velocity [m/s] w.r.t. base in base, each shape (3,).
            Before the start and after the end the twist is zero.
        """
        s, sdot, _ = self.scaling.evaluate(t)
        return self.pose_at(s), (self.angular_direction * sdot, self.displacement * sdot)

    def sample_path(self, count: int) -> np.ndarray:
        """``count`` >= 2 poses evenly spaced in progress from start to goal, shape (count, 4, 4)."""
        return np.stack([self.pose_at(s) for s in np.linspace(0.0, 1.0, max(int(count), 2))])

    def peak_speeds(self) -> tuple[float, float]:
        """Largest ``(linear [m/s], angular [rad/s])`` speed over the motion."""
        rate = self.scaling.peak_rate
        return self.length * rate, self.angle * rate


def distance_to_segment(points, start, end) -> np.ndarray:
    """Distance [m] of each point to the segment from ``start`` to ``end``.

    Args:
        points: shape (N, 3) or (3,).
        start: segment start, shape (3,).
        end: segment end, shape (3,).

    Returns:
        Distances, shape (N,) (or a 0-d array for one point).
    """
    points = np.asarray(points, dtype=float)
    start = np.asarray(start, dtype=float)
    direction = np.asarray(end, dtype=float) - start
    length_sq = float(direction @ direction)
    if length_sq < 1e-24:
        return np.linalg.norm(points - start, axis=-1)
    fraction = np.clip(((points - start) @ direction) / length_sq, 0.0, 1.0)
    closest = start + fraction[..., None] * direction
    return np.linalg.norm(points - closest, axis=-1)
