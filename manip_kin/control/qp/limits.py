"""Limits: the constraints of the QP, each an object one can add and test alone.

Two kinds:

* box limits bound each joint rate, ``lower <= q̇ <= upper`` (:meth:`box`);
* row limits add inequalities ``A q̇ <= b`` (:meth:`rows`).

When box limits contradict each other for a joint, the velocity limit wins over the
position limit, and both over the acceleration limit (see :func:`merge_boxes`): a joint
never exceeds its speed, and a joint past its position limit may be stopped harder than
its acceleration limit allows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.collision.distances import CollisionChecker
from manip_kin.collision.pair_distance import DamperRows
from manip_kin.control.command_filter import FilterState
from manip_kin.control.joint_limits import JointLimits
from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError


@dataclass(frozen=True)
class Box:
    """Bounds on the joint rates, shapes (n,) [rad/s | m/s]; ±inf where unbounded."""

    lower: np.ndarray
    upper: np.ndarray


def merge_boxes(primary: Box, secondary: Box) -> Box:
    """``secondary`` within ``primary``: their intersection, or, for a joint where they do not
    overlap, the bound of ``primary`` nearest to ``secondary`` (``primary`` wins)."""
    lower = np.minimum(np.maximum(primary.lower, secondary.lower), primary.upper)
    upper = np.maximum(np.minimum(primary.upper, secondary.upper), primary.lower)
    return Box(lower, upper)


def _positive(name: str, value: float, unit: str) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InvalidArgumentError(f"{name} = {value!r}; valid: a finite number > 0 [{unit}]")
    return float(value)


def _per_joint(name: str, values, n: int, unit: str) -> np.ndarray:
    array = np.broadcast_to(np.array(values, dtype=float), (n,)).copy()
    if not np.all(array > 0) or np.any(np.isnan(array)):
        raise InvalidArgumentError(f"{name} = {array.tolist()}; valid: {n} values > 0 [{unit}] (or one for all)")
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class PositionLimit:
    """Joint position limits reached smoothly.

    ``q̇_i <= K (upper_i − margin − q_i)`` and ``q̇_i >= K (lower_i + margin − q_i)``: the
    distance to the shrunk limit decays as ``exp(−K t)``, so the joint slows down as it
    approaches and never crosses it (and a joint inside the margin is pulled back out).

    Attributes:
        lower, upper: limits, shape (n,) [rad | m]; ±inf for none.
        margin: kept from each limit [rad | m], >= 0.
        gain: K [1/s], > 0.
    """

    lower: np.ndarray
    upper: np.ndarray
    margin: float = 0.02
    gain: float = 5.0

    @classmethod
    def of(cls, model: RobotModel, margin: float = 0.02, gain: float = 5.0) -> PositionLimit:
        """The model's joint limits."""
        if not (math.isfinite(margin) and margin >= 0):
            raise InvalidArgumentError(f"position limit margin = {margin!r}; valid: >= 0 [rad | m]")
        return cls(model.lower, model.upper, float(margin), _positive("position limit gain", gain, "1/s"))

    def __post_init__(self):
        upper = np.asarray(self.upper, dtype=float) - self.margin
        lower = np.asarray(self.lower, dtype=float) + self.margin
        # A range narrower than twice the margin: aim for its middle.
        narrow = lower > upper
        middle = 0.5 * (np.asarray(self.lower, dtype=float) + np.asarray(self.upper, dtype=float))
        # The kept limits as rows [lower, upper], shape (2, n): both bounds in one product.
        kept = np.array([np.where(narrow, middle, lower), np.where(narrow, middle, upper)])
        kept.setflags(write=False)
        object.__setattr__(self, "_kept", kept)

    def box(self, q: np.ndarray, dt: float, previous: np.ndarray) -> Box:
        # inf - q stays inf: a joint without a limit gets no bound.
        lower, upper = self.gain * (self._kept - q)
        return Box(lower, upper)


@dataclass(frozen=True)
class VelocityLimit:
    """``|q̇_i| <= v_i``.

    Attributes:
        limits: v, shape (n,) [rad/s | m/s] (inf: none).
    """

    limits: np.ndarray

    def __post_init__(self):
        limits = np.array(self.limits, dtype=float)
        lower = -limits
        for array in (limits, lower):
            array.setflags(write=False)
        object.__setattr__(self, "_box", Box(lower, limits))  # the same every cycle

    @classmethod
    def of(cls, model: RobotModel) -> VelocityLimit:
        """The model's velocity limits."""
        return cls(model.velocity_limits)

    def box(self, q: np.ndarray, dt: float, previous: np.ndarray) -> Box:
        return self._box


@dataclass(frozen=True)
class AccelerationLimit:
    """``|q̇_i − q̇_prev,i| <= a_i dt``: a box around the previous command.

    Attributes:
        max_acceleration: a, shape (n,) [rad/s² | m/s²].
    """

    max_acceleration: np.ndarray

    @classmethod
    def of(cls, model: RobotModel, max_acceleration) -> AccelerationLimit:
        """``max_acceleration`` per joint (or one value for all)."""
        return cls(_per_joint("max_acceleration", max_acceleration, model.dof, "rad/s² | m/s²"))

    def box(self, q: np.ndarray, dt: float, previous: np.ndarray) -> Box:
        step = self.max_acceleration * dt
        return Box(previous - step, previous + step)


@dataclass(frozen=True)
class CollisionLimit:
    """Velocity dampers on the pairs within the influence distance (see :mod:`manip_kin.collision.distances`).

    ``n·(J_a − J_b) q̇ <= ξ (d − d_s) / (d_i − d_s)`` for each pair nearer than ``d_i``.

    With ``braking`` (the limits of a command filter the rates pass through) and the command in
    force, each pair's ``d`` is first lessened by what it closes while that filter stops the
    command, ``max(0, n·(J_a − J_b) Δq)`` with ``Δq`` each joint's stopping travel
    (:meth:`~manip_kin.control.joint_limits.JointLimits.stopping_travel`), and the pairs within
    ``d_i`` plus the most any shape can move meanwhile are looked at. So the damper binds where
    the filter must start braking, not where the QP could stop at once.

    Attributes:
        checker: the robot's collision checker (holding the scene's obstacles).
        safety_distance: d_s [m], >= 0: the closest allowed approach
            (``collision_safety_distance``).
        influence_distance: d_i [m], > d_s: pairs farther apart are free.
        gain: ξ [m/s], > 0: the closing speed allowed at d_i.
        braking: the command filter's limits, or None (the rates are applied as they are).
    """

    checker: CollisionChecker
    safety_distance: float = 0.02
    influence_distance: float = 0.10
    gain: float = 0.5
    braking: JointLimits | None = None

    def __post_init__(self):
        if not (math.isfinite(self.safety_distance) and self.safety_distance >= 0):
            raise InvalidArgumentError(f"collision_safety_distance = {self.safety_distance!r}; valid: >= 0 [m]")
        if not (math.isfinite(self.influence_distance) and self.influence_distance > self.safety_distance):
            raise InvalidArgumentError(
                f"influence distance = {self.influence_distance!r}; valid: > collision_safety_distance "
                f"({self.safety_distance:g} m) [m]"
            )
        _positive("collision gain", self.gain, "m/s")

    @property
    def hold_time(self) -> float:
        """``(d_i − d_s) / ξ`` [s]: the longest a command may be held (a stalled loop, a plant
        that moves on the last command until its timeout) without a pair coming within ``d_s``.

        The damper allows a closing speed of at most ``(d − d_s) / hold_time`` at distance
        ``d``, so held for ``T`` it closes ``(d − d_s) · T / hold_time``: less than the margin
        while ``T < hold_time`` (to first order in the motion).
        """
        return (self.influence_distance - self.safety_distance) / self.gain

    def rows(self, q: np.ndarray, command: FilterState | None = None) -> DamperRows:
        """This cycle's damper rows at ``q``, the filter's ``command`` in force (see the class docstring)."""
        d_i, d_s = self.influence_distance, self.safety_distance
        if self.braking is None or command is None or not (command.velocity.any() or command.acceleration.any()):
            return self.checker.evaluate(q, d_i, d_s, self.gain)
        # A loop that runs late drives each of the stop's commands for longer: the filter's limits
        # hold per update, so the stop's travel stretches by as much.
        travel = command.stretch * self.braking.stopping_travel(command.velocity, command.acceleration)
        return self.checker.evaluate(q, d_i, d_s, self.gain, travel)
