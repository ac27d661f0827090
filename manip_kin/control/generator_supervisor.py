"""The state machine of ``trajectory_generator``, without ROS (see
:mod:`manip_kin.control.state_machines` for how a node and its supervisor share the work)."""

from __future__ import annotations

from enum import StrEnum
from typing import Protocol

from manip_kin.control.status import StatusThrottle


class GeneratorState(StrEnum):
    """States of ``trajectory_generator`` (the DiagnosticStatus message)."""

    IDLE = "idle"
    STREAMING = "streaming"
    HOLDING = "holding"
    REJECTED = "rejected"


class Motion(Protocol):
    """A planned motion the generator streams: a line or a joint trajectory."""

    @property
    def duration(self) -> float:
        """Total time [s]."""
        ...

    def progress_at(self, t: float) -> float:
        """Progress in [0, 1] at time ``t`` [s] from the start."""
        ...


class GeneratorSupervisor:
    """The running motion, its timing, the rejections and the status timing of the generator.

    Per cycle the node reports rejected and accepted targets (:meth:`reject`,
    :meth:`start`); while streaming, :meth:`time_into_motion` says where to sample and
    whether the motion just ended (then :meth:`finish`); :meth:`report_due` says whether
    to publish ``/diagnostics``.

    Args:
        diagnostics_period_ns: period of the regular status [ns].
    """

    def __init__(self, diagnostics_period_ns: int):
        self.throttle = StatusThrottle(diagnostics_period_ns)
        self.state = GeneratorState.IDLE
        self.detail = "no target yet"
        self.motion: Motion | None = None
        self.motion_kind = ""
        self.target_stamp = ""
        self.final_goal_stamp = ""
        self.progress = 0.0
        self.rejected_targets = 0
        self.rejected_stamp = ""
        self.last_rejection = ""
        self.rejection_kind = ""
        self._start_ns = 0

    def reject(self, reason: str, stamp: str, kind: str = "invalid") -> str:
        """A target was rejected; returns what happens to the running motion (for the log line).

        ``kind`` is ``invalid`` (the message or the pipeline's state is unusable) or
        ``unreachable`` (a valid target the arm cannot follow). A rejection neither stops a
        running motion nor replaces its ``target_stamp``.
        """
        self.rejected_targets += 1
        self.last_rejection = reason
        self.rejection_kind = kind
        self.rejected_stamp = stamp
        if self.state is GeneratorState.STREAMING:
            return f"the running {self.motion_kind} goes on"
        self.state, self.detail = GeneratorState.REJECTED, reason
        return "nothing to do"

    def has_taken(self, stamp: str) -> bool:
        """True for the stamp of the motion started last (streaming, holding or stopped): a
        client that missed the report of it sends the same target again (same stamp), and
        planning it again would start a second, shorter motion from wherever the arm is then.
        ``""`` (an unstamped target) is always new."""
        return bool(stamp) and stamp == self.target_stamp

    def start(self, motion: Motion, kind: str, now_ns: int, stamp: str, detail: str) -> bool:
        """A motion was planned and starts now; True when it pre-empted a running one."""
        preempted = self.state is GeneratorState.STREAMING
        self.motion = motion
        self.motion_kind = kind
        self._start_ns = now_ns
        self.target_stamp = stamp
        self.final_goal_stamp = ""
        self.progress = 0.0
        self.state, self.detail = GeneratorState.STREAMING, detail
        return preempted

    @property
    def started_ns(self) -> int | None:
        """When the current motion started [ns, the loop's clock]; None before the first."""
        return self._start_ns if self.motion is not None else None

    def time_into_motion(self, now_ns: int) -> tuple[float, bool] | None:
        """While streaming: ``(t [s] clipped to the duration, finished)``; None otherwise."""
        if self.state is not GeneratorState.STREAMING or self.motion is None:
            return None
        elapsed = (now_ns - self._start_ns) * 1e-9
        duration = self.motion.duration
        finished = elapsed >= duration
        t = duration if finished else elapsed
        self.progress = 1.0 if finished else float(self.motion.progress_at(t))
        return t, finished

    def finish(self, final_goal_stamp: str) -> None:
        """The last sample (final pose or reference, at rest) went out: hold."""
        self.final_goal_stamp = final_goal_stamp
        self.progress = 1.0
        self.state, self.detail = GeneratorState.HOLDING, f"{self.motion_kind} finished, final goal sent"

    def stop(self, detail: str) -> bool:
        """Stop streaming after a fault (the last goal sent is held); True when a motion was running."""
        if self.state is not GeneratorState.STREAMING:
            return False
        self.state, self.detail = GeneratorState.HOLDING, detail
        return True

    def report_due(self, now_ns: int) -> bool:
        """True when a status should be published now (regular period, or a state change)."""
        return self.throttle.due(now_ns, self.state)

    @property
    def level(self) -> str:
        """Diagnostic level of the state."""
        return "warn" if self.state is GeneratorState.REJECTED else "ok"
