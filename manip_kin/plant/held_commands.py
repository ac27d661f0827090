"""Which velocity command a simulated arm held over an interval, when its process ran late.

robot_state simulates hardware behind a velocity interface: each cycle takes the newest
command and moves the arm with it over the period that ends at the cycle (the command a
cycle takes drives the period just simulated). Real hardware applies the commands it receives
in its own cycles whatever the computer simulating it does. When robot_state's loop is late
(a stall of its process: tens of milliseconds on a loaded machine), the commands sent during
the stall are queued; applying only the newest over the whole stall would move the arm
differently from hardware that took each one at its own cycle (in one trace of the 0.4 m/s
irb120 line, a 20 ms stall of robot_state came just before a 0.52 mm deviation). :func:`held_segments` replays the missed cycles
on the nominal schedule instead: the cycle that would have run at ``last + k·period`` takes
the commands sent by then, and each command counts as zero ``timeout`` after the cycle that
took it, as at run time.

Plain data, no ROS: robot_state converts the middleware's source timestamps to its loop clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HeldCommand:
    """A command and the loop time [ns] of the cycle that took it (its timeout runs from there)."""

    values: np.ndarray
    taken_ns: int


@dataclass(frozen=True)
class Segment:
    """Part of an interval: the command held (None: none, at rest) for ``seconds``."""

    values: np.ndarray | None
    seconds: float


def held_segments(
    last_ns: int,
    now_ns: int,
    period_ns: int,
    held: HeldCommand | None,
    arrived: Sequence[tuple[int, np.ndarray]],
    timeout_ns: int,
) -> tuple[list[Segment], HeldCommand | None]:
    """The commands the arm held over ``[last_ns, now_ns]``, and the one it holds at ``now_ns``.

    Args:
        last_ns, now_ns: the previous cycle's and this cycle's loop times [ns].
        period_ns: the loop's period [ns], > 0.
        held: the command held at ``last_ns`` (None: none).
        arrived: the commands taken now, in arrival order, each with the loop time it was sent
            at [ns]. A send time is clamped into the interval (outside it, the clocks
            disagree: a command taken now was sent by now) and to no earlier than the one
            before (one writer sends in order).
        timeout_ns: a command counts as zero this long after the cycle that took it [ns], > 0.

    Returns:
        The segments in order, neighbours with the same command merged. Their seconds sum to
        the interval, except that a rest at its end lasts at most ``timeout_ns`` (a long stall
        of an arm at rest needs no integration of its whole length). And the command held at
        ``now_ns``.
    """
    segments: list[Segment] = []
    if now_ns <= last_ns:  # no time to move over (the first cycle): the newest is taken
        return segments, HeldCommand(arrived[-1][1], now_ns) if arrived else held
    # The missed cycles: last + k·period for k = 1..missed; the cycle now takes the last
    # period, one to two periods long (a loop less than a period late missed none).
    missed = max((now_ns - last_ns) // period_ns - 1, 0)
    sends, sent = [], last_ns
    for sent_ns, _ in arrived:
        sent = min(max(sent_ns, sent, last_ns), now_ns)
        sends.append(sent)
    cursor, index = last_ns, 0
    while index < len(arrived):
        # The cycle that takes it (the first after it was sent), and the one before: the
        # command drives the period between them.
        cycle = max(-(-(sends[index] - last_ns) // period_ns), 1)
        if cycle <= missed:
            taking = last_ns + cycle * period_ns
            before = taking - period_ns
        else:
            taking, before = now_ns, last_ns + missed * period_ns
        _hold(segments, held, cursor, max(before, cursor), timeout_ns)
        # That cycle takes every command sent by then; the newest drives the period.
        while index < len(arrived) and sends[index] <= taking:
            index += 1
        held = HeldCommand(arrived[index - 1][1], taking)
        _hold(segments, held, max(before, cursor), taking, timeout_ns)
        cursor = taking
    _hold(segments, held, cursor, now_ns, timeout_ns)
    if segments and segments[-1].values is None:
        segments[-1] = Segment(None, min(segments[-1].seconds, timeout_ns * 1e-9))
    return segments, held


def _hold(segments: list[Segment], held: HeldCommand | None, start: int, end: int, timeout_ns: int) -> None:
    """Append ``[start, end]`` under ``held``: the command until it times out, then none."""
    if end <= start:
        return
    moving = 0 if held is None else min(max(held.taken_ns + timeout_ns - start, 0), end - start)
    for values, span in ((held.values if held is not None else None, moving), (None, end - start - moving)):
        if span <= 0:
            continue
        if segments and segments[-1].values is values:
            segments[-1] = Segment(values, segments[-1].seconds + span * 1e-9)
        else:
            segments.append(Segment(values, span * 1e-9))
