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


def seconds_between(earlier: str, later: str) -> float | None:
    """Seconds from the stamp key ``earlier`` to ``later`` (``sec.nanosec`` texts of the ROS
    clock, as the nodes report them); None when either is missing or not a stamp key."""
    from manip_kin.ros.wire.messages import stamp_key_to_ns

    try:
        return (stamp_key_to_ns(later) - stamp_key_to_ns(earlier)) * 1e-9
    except ValueError:
        return None


@dataclass(frozen=True)
class MotionTiming:
    """When a motion ended and when the controller settled on its goal, from their reports.

    Attributes:
        motion_s: from the motion's start to its last sample [s] (the generator's
            ``started_stamp`` to ``final_goal_stamp``); None for a single goal, or unknown.
        settled_s: from the start to the first cycle within the controller's tolerances [s]
            (its ``converged_stamp``); None if it has not settled (or is not known).
        tolerance: the tolerances it settled within, in words (``0.0001 m / 0.001 rad``).
    """

    motion_s: float | None
    settled_s: float | None
    tolerance: str

    def text(self, motion: str = "motion") -> str:
        """``line ended after 2.50 s; settled within 0.0001 m / 0.001 rad after 3.10 s`` (the
        parts known; ``motion`` names the motion)."""
        parts = [] if self.motion_s is None else [f"{motion} ended after {self.motion_s:.2f} s"]
        if self.settled_s is not None:
            parts.append(f"settled within {self.tolerance} after {self.settled_s:.2f} s")
        return "; ".join(parts)

    def fields(self, converged: bool) -> dict:
        """The ``--json`` keys: ``motion_time``, ``settle_time`` (None unless converged), ``settle_tolerance``."""
        return {
            "motion_time": self.motion_s,
            "settle_time": self.settled_s if converged else None,
            "settle_tolerance": self.tolerance,
        }

    def converged_verdict(self, motion: str, elapsed: float) -> str:
        """The line of a converged goal: its motion's end and settling where the controller
        reported them, else the ``elapsed`` seconds [s] until it said converged."""
        if self.settled_s is not None:
            return f"converged ({self.text(motion)})"
        return f"converged in {elapsed:.2f} s"


def motion_timing(start_stamp: str, controller: dict, generator: dict | None = None) -> MotionTiming:
    """The timing of a goal sent at ``start_stamp`` (``generator`` None) or of a generator's
    motion (its status ``values``: measured from its ``started_stamp``), read from the
    controller status ``values`` that reported the goal converged."""
    start = generator.get("started_stamp", "") if generator is not None else start_stamp
    motion = seconds_between(start, generator.get("final_goal_stamp", "")) if generator is not None else None
    settled = seconds_between(start, controller.get("converged_stamp", ""))
    if controller.get("goal_kind") == "joint":
        tolerance = f"{controller.get('joint_tolerance', '?')} rad or m per joint"
    elif controller.get("task") == "position":
        tolerance = f"{controller.get('position_tolerance', '?')} m"
    else:
        tolerance = (
            f"{controller.get('position_tolerance', '?')} m / {controller.get('orientation_tolerance', '?')} rad"
        )
    return MotionTiming(motion, settled, tolerance)
