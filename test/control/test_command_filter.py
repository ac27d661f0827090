"""The command filter: every output obeys the acceleration and jerk limits cycle to cycle."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.control.command_filter import CommandFilter, FilterResult, time_optimal_step
from manip_kin.control.joint_limits import JointLimit, JointLimits, default_joint_limits, stopping_distance
from manip_kin.control.late_updates import MAKE_UP_DONE
from manip_kin.core.robots import load_robot

DT = 0.001
SLACK = 1e-9  # relative: ruckig's samples sit on the bounds up to rounding


def finite_differences(commands: np.ndarray, dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """(accelerations, jerks) of a command stream, from rest before the first command."""
    stream = np.vstack([np.zeros((2, commands.shape[1])), commands])
    acceleration = np.diff(stream, axis=0) / dt
    return acceleration[1:], np.diff(acceleration, axis=0) / dt


def assert_within(commands, limits: JointLimits, dt: float = DT) -> None:
    acceleration, jerk = finite_differences(np.asarray(commands), dt)
    assert np.all(np.abs(acceleration) <= limits.acceleration * (1 + SLACK) + 1e-12), np.abs(acceleration).max(axis=0)
    assert np.all(np.abs(jerk) <= limits.jerk * (1 + SLACK) + 1e-9), np.abs(jerk).max(axis=0)


def irb120():
    return load_robot("irb120")


def test_a_velocity_step_becomes_a_jerk_limited_ramp():
    model = irb120()
    limits = JointLimits.of(model)
    command_filter = CommandFilter(limits, model.lower, model.upper, DT)
    target = 0.9 * limits.velocity
    commands = [list(command_filter.update(target)) for _ in range(1000)]
    assert_within(commands, limits)
    # Independently of ruckig: from rest, the fastest jerk-limited rise to v takes v/A + A/J.
    # The sampled stream keeps the limits on its finite differences, and a stream that holds
    # the jerk into its last periods (not a profile's samples) lands up to 3 periods sooner.
    rise = max(v / a + a / j for v, a, j in zip(target, limits.acceleration, limits.jerk))
    first_at_target = next(k for k, c in enumerate(commands) if np.allclose(c, target, rtol=0, atol=1e-12))
    assert rise - 3 * DT <= (first_at_target + 1) * DT <= 1.3 * rise + 2 * DT
    assert command_filter.result is FilterResult.FOLLOWING
    # The first command is half a cycle of jerk: J dt² / 2 on the joint whose rise is longest.
    assert 0 < abs(commands[0][0]) < target[0]


def test_the_stop_ends_in_an_exact_zero_within_the_stopping_time_bound():
    model = irb120()
    limits = JointLimits.of(model)
    command_filter = CommandFilter(limits, model.lower, model.upper, DT)
    for _ in range(500):
        command_filter.update(-0.8 * limits.velocity)
    bound = command_filter.stopping_time()
    commands = []
    while not command_filter.at_rest and len(commands) < 10_000:
        commands.append(list(command_filter.update(np.zeros(model.dof))))
    assert commands[-1] == [0.0] * model.dof
    assert len(commands) * DT <= bound + DT
    assert len(commands) * DT >= max(0.8 * v / a for v, a in zip(limits.velocity, limits.acceleration))
    assert command_filter.result is FilterResult.AT_REST


def test_deceleration_limit_below_acceleration_limit_bounds_both():
    model = irb120()
    per_joint = default_joint_limits(model)
    per_joint["joint1"] = JointLimit(True, 4.0, True, 20.0, True, 5.0, True, 1000.0)
    limits = JointLimits.of(model, per_joint)
    assert limits.acceleration[0] == 5.0
    with pytest.raises(ValueError, match=r"joint_limits\.joint1\.max_jerk = -1.*valid"):
        JointLimits.of(model, {"joint1": JointLimit(True, 4.0, True, 20.0, True, 5.0, True, -1.0)})
    with pytest.raises(ValueError, match="not a joint of irb120"):
        JointLimits.of(model, {"elbow": per_joint["joint1"]})


@pytest.mark.parametrize("speed", [0.0, 0.05, 0.5, 2.0])
@pytest.mark.parametrize("acceleration", [-8.0, 0.0, 6.0])
def test_stopping_distance_matches_a_simulated_time_optimal_stop(speed, acceleration):
    bound, jerk, dt = 10.0, 500.0, 1e-6
    v, a, travelled = speed, acceleration, 0.0
    while v > 0.0 or a > 0.0:  # jerk -J, until easing off at +J lands on v = 0 with a = 0
        j = jerk if a < 0.0 and v - a * a / (2 * jerk) <= 0.0 else -jerk
        a = min(max(a + j * dt, -bound), bound)
        v += a * dt
        travelled += max(v, 0.0) * dt
        if v <= 0.0:
            break
    assert stopping_distance(speed, acceleration, bound, jerk) == pytest.approx(travelled, rel=2e-3, abs=1e-7)


@settings(max_examples=40)
@given(
    st.lists(
        st.tuples(st.integers(1, 300), st.lists(st.floats(-1.5, 1.5), min_size=6, max_size=6)),
        min_size=1,
        max_size=6,
    ),
    st.floats(0.5, 50.0),
    st.floats(0.01, 0.5),
)
def test_any_target_sequence_keeps_the_limits(segments, acceleration_factor, jerk_time):
    """Goal sequences, reversals and limits: the finite differences stay within the limits, the
    commands within the velocity limits, and a held target is reached."""
    model = irb120()
    per_joint = {
        name: JointLimit(True, v, True, acceleration_factor * v, False, 1.0, True, acceleration_factor * v / jerk_time)
        for name, v in zip(model.joint_names, model.velocity_limits)
    }
    limits = JointLimits.of(model, per_joint)
    command_filter = CommandFilter(limits, model.lower, model.upper, DT)
    commands = []
    for cycles, fractions in segments:
        target = np.array(fractions) * limits.velocity
        commands += [list(command_filter.update(target)) for _ in range(cycles)]
    state = command_filter.state
    change_time = limits.stopping_time(state.velocity - target, state.acceleration)  # a change of speed is a stop
    settle = int(math.ceil(change_time / DT)) + 2
    commands += [list(command_filter.update(target)) for _ in range(2 * settle)]
    assert_within(commands, limits)
    assert np.all(np.abs(commands) <= limits.velocity * (1 + SLACK))
    scale = min(1.0, float(np.min(limits.velocity / np.maximum(np.abs(target), 1e-300))))
    np.testing.assert_allclose(commands[-1], scale * target, rtol=0, atol=1e-9)


@settings(max_examples=30)
@given(st.floats(-2.8, 2.8), st.floats(0.2, 1.0))
def test_a_joint_driven_at_its_limit_stops_on_it(start, speed_fraction):
    """The braking speed keeps the filtered command from carrying a joint past its limit."""
    model = irb120()
    limits = JointLimits.of(model)
    command_filter = CommandFilter(limits, model.lower, model.upper, DT)
    q = np.zeros(model.dof)
    q[0] = start
    commands = []
    cycles = int((model.upper[0] - start) / (speed_fraction * limits.velocity[0]) / DT) + 1000
    for _ in range(cycles):
        target = np.zeros(model.dof)
        target[0] = speed_fraction * limits.velocity[0]
        command = command_filter.update(target, q)
        commands.append(list(command))
        q = q + np.array(command) * DT
        assert q[0] <= model.upper[0] + 1e-9
    assert_within(commands, limits)
    assert q[0] > model.upper[0] - 0.01  # it got there


@given(st.floats(1.5, 5.0), st.floats(-1.0, 1.0), st.integers(0, 1000))
@settings(max_examples=20)
def test_a_target_that_wobbles_along_a_ramp_is_followed_without_lag(noise_over_jerk, slope, seed):
    """A law's command paired with states a little off their instants: a ramp (a line's
    acceleration phase, joint accelerations of about 1 rad/s²) plus noise whose cycle-to-cycle
    changes exceed the jerk bound 1.5 to 5 times. The command keeps the limits and stays within
    a few noise amplitudes of the target: it does not fall behind the ramp."""
    model = irb120()
    limits = JointLimits.of(model)
    command_filter = CommandFilter(limits, model.lower, model.upper, DT)
    # Alternating noise ε changes the finite-difference acceleration by 4ε/dt a cycle: over J dt
    # when ε > J dt²/4.
    amplitude = noise_over_jerk * float(np.max(limits.jerk)) * DT * DT / 4
    rng = np.random.default_rng(seed)
    ramp_acceleration = slope * np.linspace(0.5, 1.5, model.dof)  # [rad/s²]
    start = np.zeros(model.dof)  # the ramp starts from rest, as a line does
    commands, targets = [], []
    for k in range(600):
        target = start + ramp_acceleration * k * DT + amplitude * rng.choice([-1.0, 1.0], model.dof)
        targets.append(target)
        commands.append(list(command_filter.update(target)))
    assert_within(commands, limits)
    # From 50 cycles on: within 3 amplitudes of the noise-free ramp. Ruckig's profiles towards the noisy target lagged it by more.
    ramp = start + ramp_acceleration * np.arange(600)[:, None] * DT
    assert np.max(np.abs(np.array(commands)[50:] - ramp[50:])) <= 3 * amplitude


@settings(max_examples=200)
@given(st.floats(-5.0, 5.0).filter(lambda e: abs(e) > 1e-9), st.floats(10.0, 1e5), st.sampled_from([1e-3, 2e-3, 5e-4]))
def test_the_time_optimal_step_closes_an_error_without_overshoot_in_the_fewest_periods(error, jerk, dt):
    """From rest relative to the target, each period's acceleration x changing by at most
    c = J·dt: the error closes exactly, never changes sign, and ends at rest; in the fewest
    periods such a sampled stream needs (n rising steps 1c..nc and n falling close at most
    n²·c·dt, so n >= sqrt(|e| / (c·dt)), and the stream takes 2n periods or one more)."""
    step = jerk * dt
    remaining, x, periods = error, 0.0, 0
    while (remaining or x) and periods < 100_000:
        wanted = time_optimal_step(remaining, jerk, dt)
        new_x = min(max(wanted, x - step), x + step)
        assert abs(new_x - x) <= step * (1 + 1e-12)
        x, remaining, periods = new_x, remaining - new_x * dt, periods + 1
        assert remaining * error >= -1e-12 * abs(error)  # no overshoot
        if abs(remaining) <= 1e-12 * abs(error) and abs(x) <= step:
            remaining, x, periods = 0.0, 0.0, periods + (x != 0.0)  # lands; then the acceleration ends
    assert remaining == 0.0 and x == 0.0
    fewest = 2 * math.ceil(math.sqrt(abs(error) / (step * dt)) - 1e-9)
    assert fewest - 1 <= periods <= fewest + 2, (periods, fewest)


def _ramp_driven(late_fraction: float, late_periods: int, seed: int, feed_forward: bool):
    """A target ramping in real time (late updates from 0.05 s to 0.5 s, then 0.4 s on time; none
    with ``late_periods`` 1), each command held by the arm until the next update: (commands, the
    displacement they drove [rad])."""
    model = irb120()
    command_filter = CommandFilter(JointLimits.of(model), model.lower, model.upper, DT)
    slope = np.linspace(0.5, 1.5, model.dof)  # [rad/s²]
    rng = np.random.default_rng(seed)
    k, last, commands, driven = 0, None, [], np.zeros(model.dof)
    while k < 900:
        target = 0.01 + slope * k * DT
        command = command_filter.update(target, None, None if last is None else (k - last) * DT, feed_forward)
        commands.append(command)
        # Late from 50 ms on (once on the ramp), the first time at 50 ms.
        late = k == 50 or (50 < k < 500 and rng.random() < late_fraction)
        periods = late_periods if late else 1
        driven += np.array(command) * periods * DT
        last, k = k, k + periods
    return commands, driven


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 1000), st.floats(0.0, 0.3), st.integers(3, 12))
def test_what_late_cycles_cost_a_moving_reference_is_made_up_within_the_limits(seed, late_fraction, late_periods):
    """A starved loop on a moving reference (``feed_forward``): the arm drives each command until
    the next update, so a late one costs displacement, and the jerk limit closes the lag late.
    The filter makes that up within the limits per update: once on time again, the commands
    have driven what an on-time loop's drove, to within a tenth of the debt and five times
    MAKE_UP_DONE; without the make-up the debt stays."""
    limits = JointLimits.of(irb120())
    _, on_time = _ramp_driven(0.0, 1, seed, True)
    commands, made_up = _ramp_driven(late_fraction, late_periods, seed, True)
    _, held = _ramp_driven(late_fraction, late_periods, seed, False)
    assert_within(commands, limits)
    debt = np.abs(held - on_time).max()
    assert debt > 2e-6, debt  # [rad]: the loss without the make-up
    left = np.abs(made_up - on_time).max()
    assert left <= 0.1 * debt and left <= 5 * MAKE_UP_DONE, (left, debt)


@settings(max_examples=20)
@given(st.integers(0, 1000), st.floats(0.1, 0.5), st.integers(2, 12))
def test_a_late_cycle_does_not_take_a_ramp_for_a_faster_one(seed, late_fraction, late_periods):
    """A loop that runs late now and then (a starved controller): the target ramps in real time,
    and each update is told the time since the last one. The command keeps the limits per update
    and never runs ahead of the ramp. Taken per period, the late cycles' larger steps looked
    like a faster ramp and the command ran up to 25 ms of the ramp ahead of it (overshoot)."""
    model = irb120()
    limits = JointLimits.of(model)
    command_filter = CommandFilter(limits, model.lower, model.upper, DT)
    slope = np.linspace(0.5, 1.5, model.dof)  # [rad/s²]
    rng = np.random.default_rng(seed)
    time, last, commands, lead = 0.0, None, [], []
    while time < 0.5:
        target = 0.01 + slope * time
        command = command_filter.update(target, None, None if last is None else time - last)
        commands.append(command)
        if len(commands) > 20:  # after the first rise onto the ramp
            lead.append(float(np.max((np.array(command) - target) / slope)))
        last = time
        time += DT * (late_periods if rng.random() < late_fraction else 1)
    assert_within(commands, limits)
    assert max(lead) <= 1e-9, max(lead)  # [s of the ramp]


@settings(max_examples=50)
@given(st.lists(st.floats(0.0, 2.0), min_size=1, max_size=300), st.sampled_from([1e-3, 4e-3]))
def test_the_stretch_is_the_drive_time_of_a_late_loop_in_periods(elapsed, dt):
    """The stretch the dampers multiply a stop's travel by: how many periods the commands have
    recently driven the arm for. It stays within 1 and the longest sample counted (a stall's is
    held to 30 ms: a held command, not a slower loop), is 1 on time, and a loop steadily k
    periods late reaches k."""
    model = irb120()
    command_filter = CommandFilter(JointLimits.of(model), model.lower, model.upper, dt)
    zeros = [0.0] * model.dof
    for seconds in elapsed:
        command_filter.update(zeros, None, seconds)
        counted = [min(max(s / dt, 1.0), 0.03 / dt) for s in elapsed]
        assert 1.0 - 1e-12 <= command_filter.state.stretch <= max(counted) + 1e-12
    on_time = CommandFilter(JointLimits.of(model), model.lower, model.upper, dt)
    for _ in range(100):
        on_time.update(zeros, None, dt if _ else None)
    assert on_time.state.stretch == 1.0
    steady = min(max(elapsed[0] / dt, 1.0), 0.03 / dt)
    for _ in range(2000):  # from as far as 30 periods, falling 1 % of the way an update
        command_filter.update(zeros, None, steady * dt)
    assert command_filter.state.stretch == pytest.approx(steady, rel=1e-3)
