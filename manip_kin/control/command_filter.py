"""The last stage of every joint-rate command: velocity, acceleration and jerk limits.

Whatever the control law asks for (a pose goal's step, a joint reference, a halt), the
command that goes out keeps ``|Δq̇|/dt <= A`` and ``|Δ²q̇|/dt² <= J`` per joint at every
cycle, with ``A`` and ``J`` from :class:`~manip_kin.control.joint_limits.JointLimits`:

* where stepping straight to the law's command keeps both (a line, a converging goal: the
  usual case), it goes out as it is, and the filter adds no lag (tracking a ramp with a target
  acceleration of zero, ruckig lags it: the irb120 line at 0.4 m/s left its segment by 1.36 mm
  instead of 0.07 mm, offline at 1 kHz);
* where every joint's target is within one period's acceleration but a jerk bound is exceeded
  (a target that wobbles a little from cycle to cycle), each joint takes its own time-optimal
  step towards its target (:meth:`CommandFilter._track`): no lag, where ruckig's synchronised
  profiles towards the wobbling target lagged it by different amounts on different joints (the
  irb120 line, offline with the goal up to 0.5 ms off its instant: 0.09 mm off its segment,
  against 0.91 mm with ruckig alone);
* otherwise (a goal step, a reversal, a halt, the corners of a trapezoid) the command is the
  next sample of a jerk-limited trajectory from the previous command towards it, computed by
  ruckig's online velocity interface (``update()`` once a period from the state it returned
  last); ruckig's time synchronisation keeps the joints' transients in step, so the joint-space
  direction of a change is kept.

After a late update, a target that follows a moving reference (``feed_forward``: a streamed
line, a joint trajectory with velocities) is raised by what makes up the displacement the late
update cost (:mod:`~manip_kin.control.late_updates`): the arm drove the held command
meanwhile, and the jerk limit closes the lag late. Offline, with 2 % of the cycles late by 2-10 periods, the irb120
line then left its segment by 0.06-0.10 mm instead of 0.15-0.31 mm in five of six runs, and by
0.30 instead of 0.36 mm in the sixth, with a burst of late cycles (docs/performance_limits.md).
Stalls (late updates of more than 30 ms) are left to the law's feedback.
A pose goal's target is its feedback alone, which sees the loss and corrects it: nothing is made
up there.

Before ruckig, the target is

1. scaled by one factor into the velocity limits (direction kept), and
2. set to zero for a joint that must start braking not to pass a position limit (after one
   more period towards it, its time-optimal stop,
   :func:`~manip_kin.control.joint_limits.stopping_distance`, would no longer fit), so it stops
   before the limit within its deceleration and jerk limits. Ruckig's community edition has
   no position limits; the law keeps ``q + q̇·dt`` inside them, and this keeps the filtered
   command from carrying a joint past one.

With no acceleration limit on any joint only those two steps apply (and the command follows
its target at once). Plain numpy and ruckig: no ROS here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from ruckig import ControlInterface, InputParameter, OutputParameter, Result, Ruckig, RuckigError, Synchronization

from manip_kin.control.joint_limits import JointLimits, stopping_distance
from manip_kin.control.late_updates import DriveTime, LateUpdateMakeUp
from manip_kin.control.streamed_goal import minmod
from manip_kin.errors import InvalidArgumentError

#: A joint this close to its target velocity [rad/s | m/s] with at most this acceleration
#: [rad/s² | m/s²] has arrived (far below any limit times a period).
_LANDED_VELOCITY = 1e-12
_LANDED_ACCELERATION = 1e-9

#: Ruckig takes finite acceleration bounds only: a joint without one gets this [rad/s² | m/s²].
UNBOUNDED_ACCELERATION = 1e9


def time_optimal_step(error: float, jerk: float, dt: float) -> float:
    """The acceleration relative to a target's own rate [rad/s² | m/s²] that closes a velocity
    ``error`` [rad/s | m/s] soonest, sampled every ``dt`` [s] with its change at most
    ``c = jerk·dt`` a period: the ``x`` whose step ``x·dt`` leaves exactly what easing off to zero
    in steps of ``c`` closes, ``(x - c) + (x - 2c) + … ``, times ``dt``. Within one step's reach
    it is ``error / dt``: the step lands on the target."""
    if not math.isfinite(jerk):
        return error / dt
    size = abs(error) / dt
    step = jerk * dt
    # n whole ease-off steps: the largest with n(n+1)/2 · c <= |error| / dt.
    n = math.floor((math.sqrt(1.0 + 8.0 * size / step) - 1.0) / 2.0)
    return math.copysign((size + step * n * (n + 1) / 2.0) / (n + 1), error)


class FilterResult(StrEnum):
    """What :meth:`CommandFilter.update` did this cycle."""

    FOLLOWING = "following"  # the command equals its target
    LIMITED = "limited"  # the command is on its way to the target within the limits
    AT_REST = "at rest"  # the target and the command are exactly zero


@dataclass(frozen=True)
class FilterState:
    """The filter's last command [rad/s | m/s] and its acceleration [rad/s² | m/s²], shapes (n,),
    and how many periods a command has recently driven the arm for, >= 1
    (:class:`~manip_kin.control.late_updates.DriveTime`): what a stop's time and travel stretch by."""

    velocity: np.ndarray
    acceleration: np.ndarray
    stretch: float = 1.0


class CommandFilter:
    """Jerk-limited joint-rate commands (see the module docstring).

    Args:
        limits: the limits in force.
        lower: lower position limits, shape (n,) [rad | m].
        upper: upper position limits, shape (n,) [rad | m].
        dt: control period [s], > 0.
        limit_velocity: scale the target into the velocity limits (see :meth:`configure`).
    """

    def __init__(self, limits: JointLimits, lower, upper, dt: float, limit_velocity: bool = True):
        if not 0.0 < dt < math.inf:
            raise InvalidArgumentError(f"dt = {dt!r}; valid: a finite period > 0 [s]")
        self.dt = float(dt)
        self.dof = len(limits.per_joint)
        self._lower = [float(v) for v in lower]
        self._upper = [float(v) for v in upper]
        self._velocity = [0.0] * self.dof
        self._acceleration = [0.0] * self.dof
        self._fd_acceleration = [0.0] * self.dof  # (v_k - v_k-1) / dt: what the limits bound
        self._previous_target: list[float] | None = None
        # The target's rate of change [rad/s² | m/s²] this update and the one before.
        self._target_rates = self._target_rate_before = [0.0] * self.dof
        self._ruckig = Ruckig(self.dof, self.dt)
        self._input = InputParameter(self.dof)
        self._input.control_interface = ControlInterface.Velocity
        self._output = OutputParameter(self.dof)
        self.result = FilterResult.AT_REST
        self.braking_joints: tuple[int, ...] = ()
        self._braking: dict[int, float] = {}  # joint -> the side (+1 upper, -1 lower) it brakes for
        self._synchronised = True
        #: Cycles computed without time synchronisation because ruckig found none.
        self.unsynchronised_cycles = 0
        self.drive_time = DriveTime(self.dt)
        self.configure(limits, limit_velocity)

    def configure(self, limits: JointLimits, limit_velocity: bool = True) -> None:
        """New limits from the next cycle on; the command's state is kept (live tuning). A lower
        acceleration bound than the present acceleration is reached at the jerk limit.
        ``limit_velocity`` False: no velocity scaling (the law's ``respect_velocity_limits``)."""
        if len(limits.per_joint) != self.dof:
            raise InvalidArgumentError(f"limits for {len(limits.per_joint)} joints; valid: {self.dof}")
        self.limits = limits
        self._velocity_limits = limits.velocity.tolist() if limit_velocity else [math.inf] * self.dof
        self._accelerations = limits.acceleration.tolist()
        self._jerks = limits.jerk.tolist()
        self.filtering = limits.limits_acceleration
        self._make_up = LateUpdateMakeUp(self.dt, self._accelerations, self._jerks, self._velocity_limits)
        self._input.max_velocity = [v if math.isfinite(v) else UNBOUNDED_ACCELERATION for v in self._velocity_limits]
        self._input.max_acceleration = [min(a, UNBOUNDED_ACCELERATION) for a in self._accelerations]
        self._input.max_jerk = self._jerks

    @property
    def state(self) -> FilterState:
        """The last command, its acceleration and the stretch of a late loop."""
        return FilterState(np.array(self._velocity), np.array(self._acceleration), self.drive_time.periods)

    @property
    def at_rest(self) -> bool:
        """True when the last command was exactly zero and not accelerating."""
        return not any(self._velocity) and not any(self._acceleration)

    def stopping_time(self) -> float:
        """An upper bound on the time [s] to bring the present command to rest."""
        return self.limits.stopping_time(self._velocity, self._acceleration)

    def reset(self) -> None:
        """Forget the command: the next cycle starts from rest (the arm is known to be still)."""
        self._velocity = [0.0] * self.dof
        self._acceleration = [0.0] * self.dof
        self._fd_acceleration = [0.0] * self.dof
        self._previous_target = None
        self._make_up.reset()
        self._target_rates = self._target_rate_before = [0.0] * self.dof
        self._braking = {}
        self.result = FilterResult.AT_REST

    def update(self, target, positions=None, elapsed: float | None = None, feed_forward: bool = False) -> list[float]:
        """The next command towards ``target`` [rad/s | m/s], shape (n,), as a list.

        Args:
            target: the joint rates the law asks for, shape (n,).
            positions: the joint positions the command starts from, shape (n,), for the
                braking speeds towards the position limits; None skips that step.
            elapsed: the time since the last update [s] (None: one period), over which the
                target's own rate is taken. The limits hold per update whatever it is: each
                command may drive the arm for one period only.
            feed_forward: the target follows a reference that moves on its own (a streamed
                line or joint trajectory with its velocity): the displacement a late update
                cost is then made up (:mod:`~manip_kin.control.late_updates`). False for a law
                whose target is its feedback alone (a pose goal): that law sees the loss and
                corrects it itself.
        """
        target = [float(v) for v in target]
        self.drive_time.update(elapsed)
        if self.filtering:
            target = self._make_up.raised(target, self._velocity, elapsed, feed_forward, bool(self.braking_joints))
        scale = 1.0
        for v, limit in zip(target, self._velocity_limits):
            if abs(v) * scale > limit:
                scale = limit / abs(v)
        if scale < 1.0:
            target = [v * scale for v in target]
        braking = []
        if positions is not None and self.filtering:
            latched = self._braking
            for j, q in enumerate(positions):
                side = latched.get(j)
                if side is not None and (target[j] * side <= 0.0 or not (self._velocity[j] or self._acceleration[j])):
                    del latched[j]  # the target turned away, or the joint has stopped: decide again
                    side = None
                if side is None and self._must_brake(j, q, target[j]):
                    side = latched[j] = 1.0 if (self._velocity[j] or target[j]) > 0.0 else -1.0
                if side is not None:
                    # Once braking, brake until at rest: deciding afresh every period chattered
                    # (brake, speed up, brake...) and crept past the limit.
                    target[j] = 0.0
                    braking.append(j)
        self.braking_joints = tuple(braking)
        previous = self._velocity
        if self._previous_target is None:
            self._previous_target = previous
        # Over the time that passed: a late cycle's target has moved on by more, not faster (a
        # loop starved for 10 ms took it for a rate ten times the real one, and overshot).
        span = self.dt if elapsed is None else max(float(elapsed), self.dt)
        self._target_rates = [(t - p) / span for t, p in zip(target, self._previous_target)]
        if not self.filtering or self._within_limits(target):
            # The law's own command when it already keeps the limits (a line, a converging
            # goal): ruckig would only add its lag. Its acceleration is the finite difference.
            self._acceleration = [(v - old) / self.dt for v, old in zip(target, previous)]
            self._velocity = target
        else:
            # A target within one period's acceleration (one that wobbles from cycle to cycle: a
            # goal paired with a state a little off its instant): each joint tracks it on its
            # own, which adds no lag. Ruckig's synchronised profiles towards such a target
            # lagged it, by different amounts on different joints, and took the tool off a line
            # (docs/performance_limits.md).
            wobble = not braking and any(target) and self._within_one_period(target)
            if not (wobble and self._track(target, previous)):
                self._step(target)
        self._fd_acceleration = [(v - old) / self.dt for v, old in zip(self._velocity, previous)]
        self._target_rate_before = self._target_rates
        self._previous_target = target
        if not any(target) and not any(self._velocity):
            self.result = FilterResult.AT_REST
        elif self._velocity == target:
            self.result = FilterResult.FOLLOWING
        else:
            self.result = FilterResult.LIMITED
        return self._velocity

    def _landing(self, target: list[float], accelerations: list[float]) -> tuple[list[float], list[float]]:
        """The sample of a profile that ends within the period: on the target, with the target's
        acceleration; but held to the sampled stream's limits, which such a landing can exceed
        by a little (seen: 15 % of the jerk limit), the state then following the held sample."""
        dt = self.dt
        velocity, acceleration = list(target), list(accelerations)
        rows = zip(target, self._velocity, self._fd_acceleration, self._accelerations, self._jerks)
        for j, (v, old, a_old, bound, jerk) in enumerate(rows):
            a = (v - old) / dt
            held = min(max(a, a_old - jerk * dt, -bound), a_old + jerk * dt, bound)
            if held != a:
                velocity[j], acceleration[j] = old + held * dt, held
        return velocity, acceleration

    def _within_limits(self, target: list[float]) -> bool:
        """True when stepping straight to ``target`` keeps every joint's finite-difference
        acceleration and jerk within its bounds (from the last command and its acceleration),
        and lands with an acceleration the target's own can follow: a step that lands on a
        target moving slower than it arrives would only defer the jerk to the next cycle."""
        dt = self.dt
        rows = zip(target, self._velocity, self._fd_acceleration, self._target_rates, self._accelerations, self._jerks)
        for v, old, a_old, rate, bound, jerk in rows:
            a = (v - old) / dt
            room = jerk * dt
            if abs(a) > bound or abs(a - a_old) > room or abs(a - rate) > room:
                return False
        return True

    def _within_one_period(self, target: list[float]) -> bool:
        """True when every joint can reach ``target`` in one period within its acceleration bound."""
        dt = self.dt
        return all(abs(v - old) <= bound * dt for v, old, bound in zip(target, self._velocity, self._accelerations))

    def _track(self, target: list[float], previous: list[float]) -> bool:
        """Each joint's time-optimal step towards ``target`` moving at its own rate ``r``
        (:func:`time_optimal_step`), held to this period's jerk and acceleration bounds. ``r`` is
        the minmod of the target's last two finite differences: a ramp's slope, but zero for a
        target that wobbles about a value (the rate of one difference amplified the wobble).
        False (no step) when the step, or easing its acceleration off after it
        (``v + a·|a|/2J``), would pass a velocity limit."""
        dt = self.dt
        rates = minmod(np.array(self._target_rates), np.array(self._target_rate_before)).tolist()
        velocity, acceleration = [], []
        rows = zip(
            target, rates, previous, self._fd_acceleration, self._accelerations, self._jerks, self._velocity_limits
        )
        for v_target, rate, v, a_old, bound, jerk, limit in rows:
            if abs(rate) > bound:  # a jump, not a rate: arrive on it at rest
                rate = 0.0
            a = rate + time_optimal_step(v_target - v - rate * dt, jerk, dt)
            a = min(max(a, a_old - jerk * dt, -bound), a_old + jerk * dt, bound)
            v_new = v + a * dt
            if abs(v_new + a * abs(a) / (2.0 * jerk)) > limit:
                return False
            velocity.append(v_new)
            acceleration.append(a)
        self._velocity, self._acceleration = velocity, acceleration
        return True

    def _must_brake(self, j: int, q: float, target: float) -> bool:
        """True when joint ``j`` at ``q`` must start its stop now not to pass a position limit:
        after one more period towards ``target`` (as fast as the jerk limit allows, but not
        past the target's speed), its time-optimal stop
        (:func:`~manip_kin.control.joint_limits.stopping_distance`) would no longer fit."""
        v, a = self._velocity[j], self._acceleration[j]
        direction = v if v else target
        if direction > 0.0:
            room, speed = self._upper[j] - q, target
        elif direction < 0.0:
            room, v, a, speed = q - self._lower[j], -v, -a, -target
        else:
            return False
        bound, jerk, dt = self._accelerations[j], self._jerks[j], self.dt
        # Far from the limit (the usual case): a bound on the stop's distance, its top speed
        # times its longest duration, clears it without the exact profile (most of the cost).
        ramp = 1.0 / jerk if math.isfinite(jerk) else 0.0
        top = max(v, speed, 0.0) + abs(a) * dt + (a * a + bound * bound) * ramp
        if top * (top / bound + 2.0 * bound * ramp + 3.0 * dt) < room:
            return False
        a_rise = min(a + jerk * dt, bound) if math.isfinite(jerk) else bound
        v_rise = v + 0.5 * (a + a_rise) * dt
        ceiling = max(speed, v)
        if v_rise > ceiling:  # it lands on the target's speed: no faster, and easing off
            v_rise = ceiling
            a_rise = min(a_rise, math.sqrt(2.0 * jerk * max(ceiling - v, 0.0))) if math.isfinite(jerk) else 0.0
        # This period's travel, and the sampled stop's excess over the continuous one: one
        # period at the stop's highest speed (a still rising acceleration carries it higher).
        v_rise = max(v_rise, 0.0)
        peak_speed = v_rise + (0.5 * a_rise * a_rise / jerk if a_rise > 0.0 and math.isfinite(jerk) else 0.0)
        return (v_rise + peak_speed) * dt + stopping_distance(v_rise, a_rise, bound, jerk) >= room

    def _step(self, target: list[float]) -> None:
        inp = self._input
        # The target's own rate: ruckig lands on a moving target (the law's command during a
        # line) instead of lagging it with a target acceleration of zero.
        # A target that jumped (a new goal) has no rate to follow: arrive at rest on it.
        rows = zip(self._target_rates, self._accelerations)
        inp.target_acceleration = [r if abs(r) <= bound else 0.0 for r, bound in rows]
        # A braking joint stops as fast as it can: not slowed to the others' time.
        braking = self.braking_joints
        if braking or self._synchronised is not True:
            inp.per_dof_synchronization = (
                [Synchronization.No if j in braking else Synchronization.Time for j in range(self.dof)]
                if braking
                else None
            )
            self._synchronised = not braking
        inp.current_velocity = self._velocity
        inp.current_acceleration = self._acceleration
        inp.target_velocity = target
        try:
            result = self._ruckig.update(inp, self._output)
        except RuckigError:
            # Its time synchronisation has no solution for some states (seen: two joints
            # accelerating towards nearly reached targets); each joint alone always has one.
            self.unsynchronised_cycles += 1
            inp.per_dof_synchronization = [Synchronization.No] * self.dof
            self._synchronised = False
            result = self._ruckig.update(inp, self._output)
        if result == Result.Finished:
            # The target is reached within this period: land on it exactly (an exact zero at rest).
            velocity, acceleration = self._landing(target, list(inp.target_acceleration))
        elif result == Result.Working:
            velocity = list(self._output.new_velocity)
            acceleration = list(self._output.new_acceleration)
            # A joint whose profile has ended up to rounding (1e-20 rad/s left) lands on its
            # target: at rest means an exact zero.
            for j, v in enumerate(velocity):
                if abs(v - target[j]) <= _LANDED_VELOCITY and abs(acceleration[j]) <= _LANDED_ACCELERATION:
                    velocity[j], acceleration[j] = target[j], 0.0
        else:  # an input ruckig refuses: keep the last command's speed, decelerating is the next try
            raise InvalidArgumentError(f"ruckig refused the command filter's input: {result}")
        self._velocity = velocity
        self._acceleration = acceleration
