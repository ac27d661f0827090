""" "Blocked by pair X": the goal's progress stalled while a collision constraint holds the arm.

For the controller's supervisor: feed it the outputs of the last moments (e.g. 0.5 s of
cycles) and it says whether the arm is stuck against a pair, which one and how near. A goal
that is being reached, or an arm held only by a joint limit, is not blocked.
:func:`blocked_by` judges pose steps (progress of the pose error), :func:`joint_blocked_by`
joint steps (progress of the joint error); both name the pair the same way.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

from manip_kin.control.qp.law import QpJointOutput, QpOutput, QpReport


@dataclass(frozen=True)
class Blocked:
    """The pair that blocks the goal.

    Attributes:
        pair: the pair label, ``first-second`` (see :attr:`~manip_kin.collision.pair_distance.PairDistance.label`).
        distance: the nearest distance in the newest output [m].
        position_progress: how much the position error shrank over the history [m] (nan for a
            joint reference).
        orientation_progress: how much the orientation error shrank over the history [rad] (nan
            for a joint reference).
        joint_progress: how much ``‖q_ref − q‖`` shrank over the history [rad | m] (nan for a pose goal).
    """

    pair: str
    distance: float
    position_progress: float = math.nan
    orientation_progress: float = math.nan
    joint_progress: float = math.nan

    @property
    def reason(self) -> str:
        """In words, e.g. ``blocked by panda_hand-obstacle:cell/1 (0.020 m apart)``."""
        return f"blocked by {self.pair} ({self.distance:.3f} m apart)"


def blocked_by(
    history: Sequence[QpOutput],
    min_position_progress: float = 1e-3,
    min_orientation_progress: float = 1e-2,
    position_tolerance: float = 1e-3,
    orientation_tolerance: float = 1e-2,
    active_fraction: float = 0.9,
) -> Blocked | None:
    """The blocking pair, or None when the goal still progresses or no collision constraint holds.

    The goal is blocked when a component of its error (position or orientation) is still
    above its tolerance and shrank by less than its minimum progress over ``history``, while
    a collision constraint was binding in most of the outputs. (The other component may still
    converge: a hand held off by an obstacle can finish turning, but it will not arrive.)

    Args:
        history: consecutive outputs, oldest first (at least two), covering a short time
            (e.g. the last 0.3 s of cycles).
        min_position_progress: less shrinking of the position error than this is a stall [m].
        min_orientation_progress: the same for the orientation error [rad].
        position_tolerance: a position error below this is reached, not stalled [m].
        orientation_tolerance: an orientation error below this is reached [rad].
        active_fraction: the share of outputs (0..1) in which a collision constraint must bind.

    Returns:
        :class:`Blocked` with the pair binding most often over ``history``.
    """
    if len(history) < 2:
        return None
    first, last = history[0], history[-1]
    position_progress = first.position_error_norm - last.position_error_norm
    orientation_progress = first.orientation_error_norm - last.orientation_error_norm
    position_stalled = last.position_error_norm > position_tolerance and position_progress < min_position_progress
    orientation_stalled = (
        last.orientation_error_norm > orientation_tolerance and orientation_progress < min_orientation_progress
    )
    if not (position_stalled or orientation_stalled):
        return None
    pair = _holding_pair(history, active_fraction)
    return None if pair is None else Blocked(pair, last.nearest_distance, position_progress, orientation_progress)


def joint_blocked_by(
    history: Sequence[QpJointOutput],
    min_progress: float = 1e-3,
    tolerance: float = 1e-3,
    active_fraction: float = 0.9,
) -> Blocked | None:
    """The blocking pair of a joint reference (or None), as :func:`blocked_by` for pose goals.

    Blocked when some joint is still farther than ``tolerance`` from the reference (the
    supervisor's "reached"), the distance to the reference in joint space ``‖q_ref − q‖`` shrank
    by less than ``min_progress`` over ``history`` (an arm sliding along an obstacle still
    progresses), and a collision constraint was binding in most of the outputs.

    Args:
        history: consecutive joint-step outputs, oldest first (at least two).
        min_progress: less shrinking of ``‖q_ref − q‖`` than this is a stall [rad | m].
        tolerance: every joint within this of the reference is reached, not stalled [rad | m].
        active_fraction: the share of outputs (0..1) in which a collision constraint must bind.
    """
    if len(history) < 2:
        return None
    first, last = history[0], history[-1]
    progress = first.joint_error_norm - last.joint_error_norm
    reached = not len(last.joint_error) or float(abs(last.joint_error).max()) <= tolerance
    if reached or progress >= min_progress:
        return None
    pair = _holding_pair(history, active_fraction)
    return None if pair is None else Blocked(pair, last.nearest_distance, joint_progress=progress)


def _holding_pair(history: Sequence[QpReport], active_fraction: float) -> str | None:
    """The pair binding most often, when a collision constraint binds in ``active_fraction`` of ``history``."""
    counts: Counter[str] = Counter()
    held = 0
    for output in history:
        pairs = output.active_collision_pairs
        if pairs:
            held += 1
            counts.update(pairs)
    if held < active_fraction * len(history) or not counts:
        return None
    return counts.most_common(1)[0][0]
