"""Making up the displacement a late update cost a command that follows a moving reference.

The arm behind a velocity interface drives each command until the next one. When the control
loop runs late (a starved process), the arm drives the held command over the missed periods
while the reference moves on; afterwards the command filter can close the lag only at the
jerk limit. A straight line then leaves its segment: offline, with 2 % of the cycles late by
2-10 periods, the irb120 line at 0.4 m/s left it by 0.15-0.36 mm, against 0.09-0.13 mm with no
filter (docs/performance_limits.md).

:class:`LateUpdateMakeUp` keeps, from a late update on, what each joint owes: over the updates,
the targets the law would have sent (ramping from its last target to the new one over the
skipped periods) less the commands that drove the arm. It raises the target by
``owed / T``, ``T`` the joint's make-up time; the command filter takes the raised target
through its limits like any other. The debt is dropped once paid (:data:`MAKE_UP_DONE`),
:data:`MAKE_UP_LONGEST` after the last late update, after a stall longer than
:data:`MAKE_UP_LONGEST_GAP`, when the target no longer follows a moving reference, at a zero
target (a halt), when a joint brakes, or when the raised target would pass a velocity limit.

Only a target that follows a moving reference is made up (``feed_forward``: a line's twist, a
joint trajectory's velocities). A pose goal's target is its feedback alone, which sees the loss
and corrects it; making it up as well would overshoot. Plain floats, no ROS.
"""

from __future__ import annotations

#: The make-up time is each joint's acceleration ramp time ``A/J`` [s], but no fewer periods
#: than this (a joint without a jerk limit). Shorter make-up times went unstable offline.
MAKE_UP_MIN_PERIODS = 10
#: A make-up ends this long [s] after the last late update, whatever is left.
MAKE_UP_LONGEST = 0.25
#: ... or once every joint owes less than this [rad | m].
MAKE_UP_DONE = 1e-7
#: A stall longer than this [s] is not made up, and drops any debt: what the arm did meanwhile
#: (held the command, or stopped at the hardware's command timeout) is not known well enough,
#: and the law's feedback corrects it. Offline, stalls of 100-300 ms made up came out worse as
#: often as better (docs/performance_limits.md).
MAKE_UP_LONGEST_GAP = 0.03


class LateUpdateMakeUp:
    """What late updates cost each joint, and the target that makes it up (module docstring).

    Args:
        dt: the control period [s].
        accelerations: each joint's acceleration bound ``A`` [rad/s² | m/s²], shape (n,).
        jerks: each joint's jerk bound ``J`` [rad/s³ | m/s³] (inf: none), shape (n,).
        velocity_limits: each joint's velocity limit [rad/s | m/s] (inf: none), shape (n,).
    """

    def __init__(self, dt: float, accelerations, jerks, velocity_limits):
        self.dt = dt
        shortest = MAKE_UP_MIN_PERIODS * dt
        self._jerks = list(jerks)
        self._times = [max(a / j, shortest) for a, j in zip(accelerations, self._jerks)]
        self._velocity_limits = list(velocity_limits)
        self._law_target: list[float] | None = None
        #: What each joint owes [rad | m]; None: nothing.
        self.owed: list[float] | None = None
        self._since_late = 0.0

    def reset(self) -> None:
        """Forget the last target and any debt."""
        self._law_target = self.owed = None

    def raised(
        self, target: list[float], command: list[float], elapsed: float | None, feed_forward: bool, braking: bool
    ) -> list[float]:
        """``target`` raised by what makes up the debt, or ``target`` itself.

        Args:
            target: the law's joint rates this update [rad/s | m/s].
            command: the last command, which drove the arm since the last update.
            elapsed: the time since the last update [s] (None: one period).
            feed_forward: the target follows a moving reference.
            braking: a joint brakes for a position limit (it can take no more).
        """
        previous_target, self._law_target = self._law_target, target
        owed = self.owed
        if not (feed_forward and previous_target is not None and any(target)):
            self.owed = None
            return target
        dt = self.dt
        periods = 1 if elapsed is None else max(1, round(elapsed / dt))
        late = periods - 1
        if (owed is None and not late) or late * dt > MAKE_UP_LONGEST_GAP:
            self.owed = None
            return target
        owed = owed or [0.0] * len(target)
        self._since_late = 0.0 if late else self._since_late + dt
        rows = zip(owed, target, previous_target, command)
        owed = [o + dt * (periods * (p - v) + 0.5 * late * (t - p)) for o, t, p, v in rows]
        paid = not late and max(map(abs, owed)) < MAKE_UP_DONE
        if paid or braking or self._since_late > MAKE_UP_LONGEST:
            self.owed = None
            return target
        self.owed = owed
        # A larger debt takes longer: no less than the shortest jerk-limited move of that length,
        # (32·|owed|/J)^(1/3); a fixed time overshot after gaps of 30 ms (offline: up to 2.4 mm).
        rows = zip(target, owed, self._times, self._jerks)
        raised = [t + o / max(time, (32.0 * abs(o) / jerk) ** (1.0 / 3.0)) for t, o, time, jerk in rows]
        if any(abs(v) > limit for v, limit in zip(raised, self._velocity_limits)):
            self.owed = None
            return target
        return raised


#: How far the drive-time estimate moves towards an update's sample: quickly towards a longer
#: one, slowly back, so that a load that comes and goes keeps it near its worst [per update].
DRIVE_TIME_RISE = 0.1
DRIVE_TIME_FALL = 0.01


class DriveTime:
    """How long each command has recently driven the arm, in periods (>= 1).

    The command filter's limits hold per update, so a loop that runs late ``k`` periods a cycle
    on average stretches a stop's profile, its time and its travel, by ``k``. Each update's
    sample is its elapsed time in periods, held to at most :data:`MAKE_UP_LONGEST_GAP`: a longer
    stall is a held command, bounded by what the arm does meanwhile (its command timeout), not a
    slower loop.

    Args:
        dt: the control period [s].
    """

    def __init__(self, dt: float):
        self.dt = dt
        self._longest = max(MAKE_UP_LONGEST_GAP, dt) / dt
        #: The estimate [periods], >= 1.
        self.periods = 1.0

    def update(self, elapsed: float | None) -> None:
        """One update, ``elapsed`` [s] after the last (None: one period)."""
        sample = 1.0 if elapsed is None else min(max(elapsed / self.dt, 1.0), self._longest)
        weight = DRIVE_TIME_RISE if sample > self.periods else DRIVE_TIME_FALL
        self.periods += weight * (sample - self.periods)
