"""plant.held_commands: a late cycle replays the commands it missed on the loop's schedule."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.plant.held_commands import HeldCommand, Segment, held_segments

MS = 1_000_000


def _displacement(segments: list[Segment]) -> np.ndarray:
    return sum((s.values * s.seconds for s in segments if s.values is not None), np.zeros(2))


def _cycle_by_cycle(last_ns, now_ns, period_ns, held, arrived, timeout_ns):
    """The schedule run one cycle at a time, as a loop that was never late would have run it:
    the cycles at last + k·period (while a whole period is left before now) and now; each takes
    what was sent by then (send times clamped into the interval and kept in order) and moves
    the arm over the period before it with the newest command, until that command times out."""
    cycles = []
    cycle = last_ns + period_ns
    while cycle <= now_ns - period_ns:
        cycles.append(cycle)
        cycle += period_ns
    cycles.append(now_ns)
    sent, clamped = last_ns, []
    for time_ns, values in arrived:
        sent = min(max(time_ns, sent, last_ns), now_ns)
        clamped.append((sent, values))
    moved, previous, index = np.zeros(2), last_ns, 0
    for cycle in cycles:
        while index < len(clamped) and clamped[index][0] <= cycle:
            held = HeldCommand(clamped[index][1], cycle)
            index += 1
        if held is not None:
            moving = min(max(held.taken_ns + timeout_ns - previous, 0), cycle - previous)
            moved = moved + held.values * moving * 1e-9
        previous = cycle
    return moved, held


def test_an_on_time_cycle_applies_the_newest_command_over_its_period():
    a, b = np.array([1.0, 0.0]), np.array([0.0, 2.0])
    segments, held = held_segments(0, 1_300_000, MS, None, [(200_000, a), (900_000, b)], 100 * MS)
    assert len(segments) == 1 and segments[0].values is b
    assert abs(segments[0].seconds - 1.3e-3) < 1e-15
    assert held.values is b and held.taken_ns == 1_300_000


def test_a_stall_replays_each_command_over_the_period_its_own_cycle_drove():
    """Ten periods late, with a command sent in each: every command drives one period, as ten
    cycles on time would have had it (the newest over all ten was the old rule)."""
    commands = [np.array([float(k), 1.0]) for k in range(10)]
    arrived = [(k * MS + 500_000, commands[k]) for k in range(10)]
    segments, held = held_segments(0, 10 * MS, MS, None, arrived, 100 * MS)
    assert [s.values for s in segments] == commands
    assert all(abs(s.seconds - 1e-3) < 1e-15 for s in segments)
    np.testing.assert_allclose(_displacement(segments), [45e-3, 10e-3])
    assert held.values is commands[9] and held.taken_ns == 10 * MS


def test_a_command_times_out_after_the_cycle_that_took_it_and_the_rest_is_bounded():
    a = np.array([1.0, -1.0])
    segments, held = held_segments(0, 2_000 * MS, MS, HeldCommand(a, 0), [], 100 * MS)
    assert [s.values is a for s in segments] == [True, False]
    assert abs(segments[0].seconds - 0.1) < 1e-12  # moves until 0 + timeout
    assert abs(segments[1].seconds - 0.1) < 1e-12  # and rests, at most a timeout's length
    assert held.values is a  # still the newest, only timed out


def test_send_times_out_of_the_interval_are_clamped_into_it():
    a = np.array([1.0, 1.0])
    # sent "before the last cycle" (a clock behind) and "after now" (a clock ahead)
    early, _ = held_segments(10 * MS, 15 * MS, MS, None, [(-5 * MS, a)], 100 * MS)
    late, _ = held_segments(10 * MS, 15 * MS, MS, None, [(99 * MS, a)], 100 * MS)
    np.testing.assert_allclose(_displacement(early), [5e-3, 5e-3])  # taken by the first missed cycle
    np.testing.assert_allclose(_displacement(late), [1e-3, 1e-3])  # taken now: drives the last period


@settings(max_examples=300, deadline=None)
@given(
    period_ms=st.integers(1, 20),
    stall_periods=st.floats(0.0, 30.0),
    sends=st.lists(st.tuples(st.floats(-0.2, 1.2), st.floats(-3, 3), st.floats(-3, 3)), max_size=12),
    held_age_periods=st.one_of(st.none(), st.floats(0.0, 40.0)),
    timeout_periods=st.floats(0.5, 25.0),
)
def test_the_segments_move_the_arm_as_the_schedule_run_cycle_by_cycle(
    period_ms, stall_periods, sends, held_age_periods, timeout_periods
):
    period = period_ms * MS
    last, now = 1_000 * MS, 1_000 * MS + int(stall_periods * period)
    timeout = max(int(timeout_periods * period), 1)
    held = (
        None if held_age_periods is None else HeldCommand(np.array([0.5, -0.25]), last - int(held_age_periods * period))
    )
    arrived = [(last + int(f * (now - last)), np.array([x, y])) for f, x, y in sends]
    segments, final = held_segments(last, now, period, held, arrived, timeout)
    moved, expected_final = _cycle_by_cycle(last, now, period, held, arrived, timeout)
    np.testing.assert_allclose(_displacement(segments), moved, atol=1e-12)
    assert (final is None) == (expected_final is None)
    if final is not None:
        assert final.values is expected_final.values and final.taken_ns == expected_final.taken_ns
    # the segments cover the interval, but for a rest at its end, cut to at most a timeout
    covered = sum(s.seconds for s in segments) * 1e9
    if segments and segments[-1].values is None and covered < now - last - 1:
        assert abs(segments[-1].seconds * 1e9 - timeout) < 1
    else:
        assert abs(covered - (now - last)) < 1
    for first, second in zip(segments, segments[1:]):
        assert first.values is not second.values  # neighbours merged
