"""How a goal ended, in the words of ``shared`` interfaces: read from the controller's status.

``converged``, ``unreachable`` (with why), ``blocked`` (with the colliding pair), ``rejected``
(with the controller's reason), ``stopped``, ``paused``; ``""`` while the goal is still on
its way (or the status is about another goal).
"""

from __future__ import annotations

from dataclasses import dataclass

#: Controller states that end a goal, besides ``converged``.
ENDING_STATES = ("unreachable", "blocked", "stopped")

#: Exit codes by outcome: 0 done, 1 a valid goal not achieved, 2 a goal refused as invalid.
EXIT_CODES = {"converged": 0, "rejected": 2}


@dataclass(frozen=True)
class GoalOutcome:
    """How a goal ended (``word`` ``""``: not yet) and the controller's words for it."""

    word: str
    reason: str = ""

    @property
    def exit_code(self) -> int:
        """0 converged, 2 rejected, 1 otherwise (not achieved, or not yet)."""
        return EXIT_CODES.get(self.word, 1)


def goal_outcome(values: dict, state: str, goal_stamp: str) -> GoalOutcome:
    """The outcome of the goal stamped ``goal_stamp`` from a controller status (its ``values``
    and its state, the status message)."""
    if values.get("rejected_stamp") == goal_stamp:
        return GoalOutcome("rejected", values.get("last_rejection", ""))
    if values.get("goal_stamp") != goal_stamp:
        return GoalOutcome("")
    if state == "converged":
        return GoalOutcome("converged")
    if state in ENDING_STATES or state == "paused":
        return GoalOutcome(state, values.get("detail", ""))
    return GoalOutcome("")


def taken(values: dict, goal_stamp: str) -> bool:
    """True once the controller reports ``goal_stamp`` as its goal, or as rejected."""
    return goal_stamp in (values.get("goal_stamp"), values.get("rejected_stamp"))
