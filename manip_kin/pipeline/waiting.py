"""Waiting on a pipeline's nodes: for a status, for a goal taken, converged or ended, for a line
target taken or done (matched by the stamp in ``/diagnostics``); and the goals and line targets
sent again while their node does not report them (:meth:`WaitingClient._resend_unreported`).

A mixin of :class:`~manip_kin.pipeline.client.PipelineClient`, which provides ``_statuses``,
``_first_converged``, ``_newest_sent``, ``status_name``, ``spin_until`` and ``publisher``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from manip_kin.pipeline.errors import PipelineError
from manip_kin.pipeline.outcome import GoalOutcome, goal_outcome, taken
from manip_kin.pipeline.status import Status

#: Seconds without its node reporting a goal or line target of ours after which it is sent again.
GOAL_RESEND_AFTER_S = 1.0
#: Times a goal or line target is sent again at most.
GOAL_RESENDS = 3


@dataclass
class SentTarget:
    """A goal or line target a client sent: its stamp key, the message, when it last went out
    (time.monotonic() [s]) and how many times it was sent again."""

    stamp: str
    msg: object
    sent_at: float
    resends: int = 0


class WaitingClient:
    """The ``wait_*`` methods of a client node."""

    def wait_status(self, name: str, timeout: float = 10.0, after_ns: int = 0) -> Status:
        """Wait for a status of node ``name`` (in this namespace) received after ``after_ns``."""
        key = self.status_name(name)
        status = self.spin_until(
            lambda: (s := self._statuses.get(key)) is not None and s.received_ns > after_ns and s, timeout
        )
        if status is None:
            raise PipelineError(f"no /diagnostics from {key} within {timeout:g} s")
        return status

    def wait_converged(
        self, goal_stamp: str, timeout: float = 30.0, controller: str = "cartesian_controller"
    ) -> tuple[bool, Status | None]:
        """Wait until the controller reports how the goal stamped ``goal_stamp`` ended
        (:func:`manip_kin.pipeline.outcome.goal_outcome`: converged, unreachable, blocked,
        stopped, rejected), or ``timeout``.

        Returns:
            ``(converged, status)``: the first status that said converged on that goal, else
            the one that ended it, else the last one about it; it has ``position_error`` [m]
            and ``orientation_error`` [rad]. :meth:`outcome` reads how it ended.
        """
        last: list[Status | None] = [None]
        key = self.status_name(controller)

        def done():
            status = self._statuses.get(key)
            if status is None or not taken(status.values, goal_stamp):
                self._resend_unreported("goal_pose", goal_stamp, status.values.get("goal_stamp", "") if status else "")
                return False
            last[0] = status
            outcome = goal_outcome(status.values, status.message, goal_stamp)
            if outcome.word == "converged":
                last[0] = self._first_converged.get((key, goal_stamp), status)
            return outcome.word not in ("", "paused")

        self.spin_until(done, timeout)
        return self.outcome(last[0], goal_stamp).word == "converged", last[0]

    @staticmethod
    def outcome(status: Status | None, goal_stamp: str) -> GoalOutcome:
        """How the goal ``goal_stamp`` ended according to ``status`` (``word`` "" if not yet)."""
        return goal_outcome(status.values, status.message, goal_stamp) if status is not None else GoalOutcome("")

    def wait_taken(self, goal_stamp: str, timeout: float = 10.0, controller: str = "cartesian_controller") -> Status:
        """Wait until the controller reports ``goal_stamp`` as its goal (or as rejected); the
        goal is sent again while it does not (see :meth:`_resend_unreported`).

        Raises:
            PipelineError: not reported within ``timeout``.
        """
        key = self.status_name(controller)

        def reported():
            status = self._statuses.get(key)
            if status is not None and taken(status.values, goal_stamp):
                return status
            self._resend_unreported("goal_pose", goal_stamp, status.values.get("goal_stamp", "") if status else "")
            return None

        status = self.spin_until(reported, timeout)
        if status is None:
            raise PipelineError(f"{key} did not report taking goal {goal_stamp} within {timeout:g} s")
        return status

    def time_to_converge(
        self, goal_stamp: str, start: float, controller: str = "cartesian_controller", sent_stamp: str = ""
    ) -> float:
        """Seconds from ``start`` (a ``time.monotonic()`` reading) until the controller first
        reported ``converged`` on the goal stamped ``goal_stamp``; until now if it has not.

        With ``sent_stamp``, the stamp of the message sent at ``start`` (the goal, the line
        target), the time is read from the two stamps instead: from ``sent_stamp`` to the
        status's own stamp, so it does not grow with how late this process heard the status (a
        client starved under load heard it 0.47 s after another one did)."""
        from manip_kin.ros.wire.messages import stamp_key_to_ns

        first = self._first_converged.get((self.status_name(controller), goal_stamp))
        if first is None:
            return time.monotonic() - start
        if sent_stamp and first.stamp_ns:
            return (first.stamp_ns - stamp_key_to_ns(sent_stamp)) * 1e-9
        return first.received_ns * 1e-9 - start

    def _resend_unreported(self, topic: str, stamp: str, reported: str) -> None:
        """Publish a goal or line target of ours again when its node has not reported it.

        ``publish_delivered`` waits for the subscriber's acknowledgement, but a reliable
        *volatile* reader that matches our writer after the sample went out acknowledges it
        without having it (Fast DDS skips what a late joiner missed): the message is lost while
        "delivered". Seen once under load (a CLI goal never reported in 30 s). The controller and
        the generator report a new goal's or target's stamp at once, so one unreported for
        ``GOAL_RESEND_AFTER_S`` is sent again (same stamp), at most ``GOAL_RESENDS`` times, and
        never over a newer one the node reports.

        Args:
            topic: ``goal_pose`` or ``line_target``.
            stamp: stamp key of the target waited for: re-sent only if it is the newest this
                client sent on ``topic``.
            reported: stamp key the node reports for its current goal or target ('' for none).
        """
        from manip_kin.ros.wire.messages import stamp_key_to_ns

        sent = self._newest_sent.get(topic)
        if sent is None or sent.stamp != stamp or sent.resends >= GOAL_RESENDS:
            return
        if time.monotonic() - sent.sent_at < GOAL_RESEND_AFTER_S:
            return
        try:
            superseded = bool(reported) and stamp_key_to_ns(reported) > stamp_key_to_ns(stamp)
        except ValueError:  # not a stamp key: a node that is not ours
            superseded = False
        if superseded:
            return  # the node has moved on to a newer one: ours is not wanted any more
        self.publisher(type(sent.msg), topic, latched=True).publish(sent.msg)
        sent.sent_at = time.monotonic()
        sent.resends += 1

    def wait_line_done(
        self, target_stamp: str, timeout: float = 60.0, generator: str = "trajectory_generator", finished: bool = True
    ) -> Status:
        """Wait until the generator finished (``holding``) or rejected the target ``target_stamp``
        (with ``finished`` False: until it started or rejected it).

        Returns:
            The generator's status: ``message`` is ``holding`` (``final_goal_stamp`` set) or
            ``rejected`` (``last_rejection`` says why; ``rejected_stamp`` is the target's);
            ``streaming`` too when not ``finished``.

        Raises:
            PipelineError: neither within ``timeout``.
        """

        key = self.status_name(generator)

        def done():
            status = self._statuses.get(key)
            if status is None:
                self._resend_unreported("line_target", target_stamp, "")
                return None
            if status.values.get("rejected_stamp") == target_stamp:
                return status
            reported = status.values.get("target_stamp", "")
            if reported == target_stamp:
                return status if status.message == "holding" or not finished else None
            self._resend_unreported("line_target", target_stamp, reported)
            return None

        status = self.spin_until(done, timeout)
        if status is None:
            last = self._statuses.get(key)
            what = "finished" if finished else "taken"
            raise PipelineError(
                f"target not {what} within {timeout:g} s (generator state: {last.message if last else 'no status'})"
            )
        return status

    def wait_target_taken(self, target_stamp: str, timeout: float = 10.0, generator: str = "trajectory_generator"):
        """:meth:`wait_line_done` until the generator started or rejected ``target_stamp``."""
        return self.wait_line_done(target_stamp, timeout, generator, finished=False)
