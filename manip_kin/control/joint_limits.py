"""Per-joint velocity, acceleration, deceleration and jerk limits, in ros2_control's layout.

The fields are those of ros2_control's ``joint_limits`` (and of a MoveIt config's
``joint_limits.yaml``): ``has_velocity_limits``/``max_velocity`` [rad/s | m/s],
``has_acceleration_limits``/``max_acceleration`` [rad/s² | m/s²],
``has_deceleration_limits``/``max_deceleration`` [rad/s² | m/s²] (a magnitude) and
``has_jerk_limits``/``max_jerk`` [rad/s³ | m/s³]. Nodes declare them as parameters
``joint_limits.<joint>.<field>`` (see :func:`manip_kin.ros.nodes.joint_limit_params.joint_limit_parameters`).

Defaults (:func:`default_joint_limits`): the velocity limit is the model's (URDF or robot
file); acceleration and jerk come from :data:`PUBLISHED_LIMITS` where the maker publishes
them (the Franka Panda), else from :data:`DEFAULT_RAMP_TIMES`: full speed in 0.2 s and full
acceleration in 20 ms, which is our choice for the bundled robots (their sources give none).

Plain numpy: no ROS here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError

#: The parameter fields of one joint, in ros2_control's order.
LIMIT_FIELDS = (
    "has_velocity_limits",
    "max_velocity",
    "has_acceleration_limits",
    "max_acceleration",
    "has_deceleration_limits",
    "max_deceleration",
    "has_jerk_limits",
    "max_jerk",
)

#: Defaults where a maker gives none: seconds to reach the velocity limit at the acceleration
#: limit, and to reach the acceleration limit at the jerk limit (our choice, see the module doc).
DEFAULT_RAMP_TIMES = {"velocity_to_acceleration": 0.2, "acceleration_to_jerk": 0.02}

#: Limits published by the arm's maker, by joint name: (max_acceleration, max_jerk).
#: Franka Emika Panda: the "Limits for Panda" table of the Franka Control Interface
#: documentation (joint space, rad/s² and rad/s³).
PUBLISHED_LIMITS: Mapping[str, tuple[float, float]] = {
    "panda_joint1": (15.0, 7500.0),
    "panda_joint2": (7.5, 3750.0),
    "panda_joint3": (10.0, 5000.0),
    "panda_joint4": (12.5, 6250.0),
    "panda_joint5": (15.0, 7500.0),
    "panda_joint6": (20.0, 10000.0),
    "panda_joint7": (20.0, 10000.0),
}

#: The largest limit value accepted: beyond it a limit means nothing physical (and squares overflow).
MAX_LIMIT_VALUE = 1e9


@dataclass(frozen=True)
class JointLimit:
    """One joint's limits (ros2_control's ``joint_limits`` fields; magnitudes, > 0 where used)."""

    has_velocity_limits: bool
    max_velocity: float
    has_acceleration_limits: bool
    max_acceleration: float
    has_deceleration_limits: bool
    max_deceleration: float
    has_jerk_limits: bool
    max_jerk: float

    def check(self, joint: str) -> JointLimit:
        """Self, after checking every value; raises :class:`InvalidArgumentError` naming the field."""
        for name in LIMIT_FIELDS:
            value = getattr(self, name)
            if name.startswith("has_"):
                if not isinstance(value, bool):
                    raise InvalidArgumentError(f"joint_limits.{joint}.{name} = {value!r:.40}; valid: true or false")
            elif not (isinstance(value, (int, float)) and 0.0 < value <= MAX_LIMIT_VALUE):
                raise InvalidArgumentError(
                    f"joint_limits.{joint}.{name} = {value!r:.40}; valid: a number in (0, {MAX_LIMIT_VALUE:g}]"
                )
        return self


def default_joint_limit(name: str, velocity_limit: float) -> JointLimit:
    """The default limits of one joint (see the module docstring)."""
    if name in PUBLISHED_LIMITS:
        acceleration, jerk = PUBLISHED_LIMITS[name]
    else:
        acceleration = velocity_limit / DEFAULT_RAMP_TIMES["velocity_to_acceleration"]
        jerk = acceleration / DEFAULT_RAMP_TIMES["acceleration_to_jerk"]
    return JointLimit(True, float(velocity_limit), True, acceleration, False, acceleration, True, jerk)


def default_joint_limits(model: RobotModel) -> dict[str, JointLimit]:
    """Default limits of every joint of ``model``, by joint name."""
    return {name: default_joint_limit(name, v) for name, v in zip(model.joint_names, model.velocity_limits)}


@dataclass(frozen=True)
class JointLimits:
    """The limits in force for a model's joints, as arrays in model joint order.

    Attributes:
        per_joint: each joint's :class:`JointLimit`, model order.
        velocity: effective velocity limit [rad/s | m/s], inf where none, shape (n,).
        acceleration: effective acceleration bound [rad/s² | m/s²], shape (n,), inf where none:
            ``min(max_acceleration, max_deceleration)``, one bound for speeding up and slowing
            down (ruckig's online mode bounds acceleration, not speeding and slowing apart), so
            both limits hold.
        jerk: effective jerk bound [rad/s³ | m/s³], inf where none, shape (n,).
    """

    per_joint: tuple[JointLimit, ...]
    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray

    def __post_init__(self):
        # 1/J, 0 without a jerk bound: the jerk ramps' durations per unit of acceleration [s³/rad].
        # Plain floats, as the bounds beside them: a handful of products per joint cost less so.
        ramps = np.where(np.isfinite(self.jerk), 1.0 / self.jerk, 0.0)
        object.__setattr__(self, "_ramps", tuple(zip(self.acceleration.tolist(), ramps.tolist())))

    @classmethod
    def of(cls, model: RobotModel, per_joint: Mapping[str, JointLimit] | None = None) -> JointLimits:
        """The limits of ``model``'s joints: ``per_joint`` by name, the defaults for the rest.

        Raises:
            InvalidArgumentError: a value outside its range, or a name that is not a model joint.
        """
        given = dict(per_joint or {})
        unknown = sorted(set(given) - set(model.joint_names))
        if unknown:
            raise InvalidArgumentError(
                f"joint_limits for {unknown[0]!r:.60}, not a joint of {model.name}; valid: {', '.join(model.joint_names)}"
            )
        defaults = default_joint_limits(model)
        limits = tuple(given.get(name, defaults[name]).check(name) for name in model.joint_names)
        velocity = np.array([lim.max_velocity if lim.has_velocity_limits else math.inf for lim in limits])
        acceleration = np.array(
            [
                min(
                    lim.max_acceleration if lim.has_acceleration_limits else math.inf,
                    lim.max_deceleration if lim.has_deceleration_limits else math.inf,
                )
                for lim in limits
            ]
        )
        jerk = np.array([lim.max_jerk if lim.has_jerk_limits else math.inf for lim in limits])
        for array in (velocity, acceleration, jerk):
            array.flags.writeable = False
        return cls(limits, velocity, acceleration, jerk)

    @property
    def limits_acceleration(self) -> bool:
        """True when any joint has a finite acceleration (or deceleration) bound."""
        return bool(np.isfinite(self.acceleration).any())

    def stopping_time(self, velocity: Sequence[float], acceleration: Sequence[float] | None = None) -> float:
        """An upper bound on the time [s] to bring ``velocity`` to rest within the limits.

        Per joint: undo the acceleration ``a`` (``|a|/J``, meanwhile the speed grows by at most
        ``a²/(2J)``), then a jerk-limited stop from that speed ``v'``: ``v'/A + A/J``.
        """
        worst = 0.0
        accelerations = acceleration if acceleration is not None else [0.0] * len(velocity)
        for v, a, (bound, ramp) in zip(velocity, accelerations, self._ramps):
            if not math.isfinite(bound):
                continue
            speed = abs(v) + 0.5 * a * a * ramp
            worst = max(worst, abs(a) * ramp + speed / bound + bound * ramp)
        return worst

    def stopping_travel(self, velocity: Sequence[float], acceleration: Sequence[float]) -> np.ndarray:
        """An upper bound on how far each joint goes [rad | m] from a command ``velocity`` with
        ``acceleration`` until a stop within the limits brings it to rest, signed as its motion,
        shape (n,); 0 for a joint without an acceleration bound.

        Undo a rising acceleration ``a`` (``a/J``, the speed growing to ``v' = v + a²/(2J)``),
        then stop from ``v'``: ``v'·a/J + v'²/(2A) + v'·A/(2J)``. The last two are the
        time-optimal stop's distance where it reaches ``-A``, and bound it where it does not (by
        the AM-GM inequality), so it is never below :func:`stopping_distance`.
        """
        travel = []
        for v, a, (bound, ramp) in zip(_floats(velocity), _floats(acceleration), self._ramps):
            if not math.isfinite(bound):
                travel.append(0.0)
                continue
            direction = math.copysign(1.0, v) if v != 0.0 else (math.copysign(1.0, a) if a != 0.0 else 0.0)
            rising = max(a * direction, 0.0)
            peak = abs(v) + 0.5 * rising * rising * ramp
            travel.append(direction * peak * (rising * ramp + peak / (2.0 * bound) + 0.5 * bound * ramp))
        return np.array(travel)


def _floats(values: Sequence[float]) -> list[float]:
    """``values`` as plain floats (an array's ``tolist``)."""
    return values.tolist() if isinstance(values, np.ndarray) else [float(v) for v in values]


def stopping_distance(speed: float, acceleration: float, max_acceleration: float, max_jerk: float) -> float:
    """The shortest distance [rad | m] in which a joint at ``speed`` >= 0 [rad/s | m/s] with
    ``acceleration`` [rad/s² | m/s²] (positive: speeding up) comes to rest within the bounds.

    The time-optimal stop: jerk ``-J`` until the acceleration reaches ``a_p`` (``-A`` at most,
    held while needed), then ``+J`` back to zero as the speed reaches zero, with
    ``a_p = -sqrt(J v + a²/2)`` when that is above ``-A``. Infinite jerk: ``v²/(2A)``.
    """
    if speed <= 0.0 and acceleration <= 0.0:
        return 0.0
    bound, jerk, a = max_acceleration, max_jerk, acceleration
    if not math.isfinite(jerk):
        return speed * speed / (2.0 * bound)
    peak = -math.sqrt(jerk * speed + 0.5 * a * a) if speed > 0.0 else -abs(a) / math.sqrt(2.0)
    peak = max(peak, -bound)
    if peak > a:  # already braking harder than needed: ease off from a
        peak = a
    t1 = (a - peak) / jerk
    v1 = speed + a * t1 - 0.5 * jerk * t1 * t1
    t3 = -peak / jerk
    # The last phase takes peak²/(2J) of speed off; the hold, at `peak`, takes the rest.
    t2 = max(0.0, (v1 - peak * peak / (2.0 * jerk)) / -peak) if peak < 0.0 else 0.0
    d1 = speed * t1 + 0.5 * a * t1 * t1 - jerk * t1**3 / 6.0
    d2 = v1 * t2 + 0.5 * peak * t2 * t2
    v2 = max(v1 + peak * t2, 0.0)
    if v2 < peak * peak / (2.0 * jerk):  # the speed runs out before the acceleration is back at zero
        t3 = (-peak - math.sqrt(max(peak * peak - 2.0 * jerk * v2, 0.0))) / jerk
    d3 = v2 * t3 + 0.5 * peak * t3 * t3 + jerk * t3**3 / 6.0
    return max(d1 + d2 + max(d3, 0.0), 0.0)
