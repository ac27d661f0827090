"""The state machine of ``cartesian_controller``, without ROS (trajectory_generator's:
:mod:`manip_kin.control.generator_supervisor`).

A node takes its messages, converts them, and tells its supervisor what happened (a joint
state arrived at ``now_ns``, a goal was rejected, a motion started, a control step
produced this output); the supervisor decides the state, its one-line detail and when a
status is due on ``/diagnostics``. Times are ``time.monotonic_ns()`` values passed in, so
every transition is testable with made-up clocks (see ``test/control/test_state_machines.py``).

States are :class:`enum.StrEnum` members: they compare equal to their text
(``ControllerState.IDLE == "idle"``), which is what ``/diagnostics`` carries.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Protocol

import numpy as np

from manip_kin.control.progress import PROGRESS_WINDOW_S, ProgressMonitor
from manip_kin.control.status import StatusThrottle, check_seconds
from manip_kin.core.pose_rows import FULL_TASK, Task
from manip_kin.errors import InvalidArgumentError

# --- the controller ------------------------------------------------------------------------------


class ControllerState(StrEnum):
    """States of ``cartesian_controller`` (the DiagnosticStatus message)."""

    IDLE = "idle"
    TRACKING = "tracking"
    CONVERGED = "converged"
    SINGULAR = "singular"
    JOINT_LIMITED = "joint-limited"
    STALE_INPUT = "stale input"
    UNREACHABLE = "unreachable"
    BLOCKED = "blocked"
    PAUSED = "paused"
    STOPPED = "stopped"


#: States in which the commands come to rest and stay there (the law does not run).
HALTED_STATES = (ControllerState.UNREACHABLE, ControllerState.BLOCKED, ControllerState.PAUSED, ControllerState.STOPPED)
#: Halted until a new goal comes.
_UNTIL_NEW_GOAL = (ControllerState.UNREACHABLE, ControllerState.BLOCKED, ControllerState.STOPPED)


class GoalKind(StrEnum):
    """What the controller follows: the latest command of any kind wins."""

    POSE = "pose"  # goal_pose (+ goal_twist feed-forward)
    JOINT = "joint"  # joint_reference
    TWIST = "twist"  # twist_command: the controlled frame's velocity
    JOG = "jog"  # joint_jog: some joints' velocities


#: Commands that are velocities: they expire after ``command_timeout`` without a new one.
SERVO_KINDS = (GoalKind.TWIST, GoalKind.JOG)


@dataclass(frozen=True)
class ControllerSupervisorConfig:
    """Timeouts and tolerances of :class:`ControllerSupervisor`.

    Attributes:
        joint_state_timeout: no joint state for longer than this: stale input [s], > 0.
        goal_timeout: a goal (or joint reference) older than this is dropped [s]; 0 = never.
        goal_twist_timeout: the feed-forward twist is used while younger than this [s], > 0.
        position_tolerance: converged on a pose when the task's position error is below this [m].
        orientation_tolerance: ... and the task's orientation error below this [rad].
        joint_tolerance: converged on a joint reference when every joint is within this of it [rad | m].
        task: the pose components that count for convergence.
    """

    joint_state_timeout: float = 0.1
    goal_timeout: float = 0.0
    goal_twist_timeout: float = 0.02
    position_tolerance: float = 1e-4
    orientation_tolerance: float = 1e-3
    joint_tolerance: float = 1e-3
    task: Task = FULL_TASK
    progress_window: float = PROGRESS_WINDOW_S
    command_timeout: float = 0.1

    def __post_init__(self):
        check_seconds("joint_state_timeout", self.joint_state_timeout)
        check_seconds("goal_timeout", self.goal_timeout, allow_zero=True)
        check_seconds("goal_twist_timeout", self.goal_twist_timeout)
        check_seconds("progress_window", self.progress_window)
        check_seconds("command_timeout", self.command_timeout)
        for name in ("position_tolerance", "orientation_tolerance", "joint_tolerance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise InvalidArgumentError(f"{name} = {value!r}; valid: a finite number > 0")


class PoseStepOutput(Protocol):
    """What :meth:`ControllerSupervisor.pose_step_done` reads of a control step's output."""

    orientation_error: np.ndarray
    position_error: np.ndarray
    manipulability: float
    damping: float
    limited_joints: tuple[int, ...]
    singular: bool


class JointStepOutput(Protocol):
    """What :meth:`ControllerSupervisor.joint_step_done` reads of a joint tracking step."""

    joint_error: np.ndarray
    limited_joints: tuple[int, ...]


class ControllerSupervisor:
    """Inputs' freshness, the goal kind, the state and the status timing of the controller.

    Per cycle the node calls the ``*_received`` methods for what it took, then
    :meth:`gate`; when that says so it runs a control step and reports it with
    :meth:`pose_step_done`, :meth:`joint_step_done` or :meth:`step_failed`; finally
    :meth:`report_due` says whether to publish ``/diagnostics``.

    Args:
        config: timeouts and tolerances.
        joint_names: model joint names (for the ``joint-limited`` detail).
        diagnostics_period_ns: period of the regular status [ns].
    """

    def __init__(self, config: ControllerSupervisorConfig, joint_names: Sequence[str], diagnostics_period_ns: int):
        self.config = config
        self.joint_names = list(joint_names)
        self.throttle = StatusThrottle(diagnostics_period_ns)
        self._joint_state_timeout_ns = int(config.joint_state_timeout * 1e9)
        self._goal_timeout_ns = int(config.goal_timeout * 1e9)
        self._twist_timeout_ns = int(config.goal_twist_timeout * 1e9)
        self._command_timeout_ns = int(config.command_timeout * 1e9)
        self.state = ControllerState.IDLE
        self.detail = "no goal yet"
        self.goal_kind: GoalKind | None = None
        self._q_time_ns: int | None = None
        self._goal_time_ns = 0
        self._twist_time_ns: int | None = None
        self._twist_moving = False
        self._reference_moving = False
        self.progress = ProgressMonitor(int(config.progress_window * 1e9))
        #: The errors when the goal was found unreachable: ``(position [m], orientation [rad])``.
        self.unreachable_errors: tuple[float, float] | None = None
        #: When the current goal was first within tolerance [ns, the loop's clock]; None before.
        #: A goal reached, left (pushed away) and reached again keeps its first time.
        self.converged_ns: int | None = None
        self._paused = False

    def reconfigure(self, config: ControllerSupervisorConfig, diagnostics_period_ns: int) -> None:
        """New timeouts, tolerances and status period from the next cycle on (live tuning); the
        state and the inputs' ages are kept."""
        self._joint_state_timeout_ns = int(config.joint_state_timeout * 1e9)
        self._goal_timeout_ns = int(config.goal_timeout * 1e9)
        self._twist_timeout_ns = int(config.goal_twist_timeout * 1e9)
        self._command_timeout_ns = int(config.command_timeout * 1e9)
        self.config = config
        self.throttle.period_ns = int(diagnostics_period_ns)
        self.progress.window_ns = int(config.progress_window * 1e9)

    # --- events ------------------------------------------------------------------------------

    def joint_state_received(self, now_ns: int) -> None:
        """A valid joint state arrived."""
        self._q_time_ns = now_ns

    def goal_received(self, now_ns: int, kind: GoalKind, moving: bool = False) -> None:
        """A valid goal arrived: a pose, or a joint reference (``moving``: its velocity is not zero).

        The latest goal of either kind wins; a pose goal drops the joint reference's motion.
        """
        self.goal_kind = GoalKind(kind)
        self._goal_time_ns = now_ns
        self._reference_moving = bool(moving) and self.goal_kind is GoalKind.JOINT
        self.progress.restart()
        self.unreachable_errors = None
        self.converged_ns = None
        if self.state in _UNTIL_NEW_GOAL:
            self._set(ControllerState.TRACKING, "new goal")

    def stop_requested(self) -> None:
        """``~/stop``: the goal is dropped and the commands come to rest; a new goal starts again."""
        self.goal_kind = None
        self._paused = False
        self._set(ControllerState.STOPPED, "stopped on request; the goal was dropped")

    def pause_requested(self, pause: bool) -> None:
        """``~/pause``: hold still (``True``) with the goal kept, or resume it (``False``)."""
        self._paused = bool(pause)
        if pause:
            self._set(ControllerState.PAUSED, "paused on request; resume to go on")
        elif self.state is ControllerState.PAUSED:
            self.progress.restart()
            self._set(ControllerState.TRACKING, "resumed")

    @property
    def paused(self) -> bool:
        """True between a pause and a resume."""
        return self._paused

    def twist_received(self, now_ns: int, moving: bool) -> None:
        """A valid feed-forward twist arrived (``moving``: not all zero)."""
        self._twist_time_ns = now_ns
        self._twist_moving = bool(moving)

    # --- the cycle -----------------------------------------------------------------------------

    def gate(self, now_ns: int) -> bool:
        """True when a control step should run; otherwise the state says why not, and the
        commands come to rest."""
        if self._paused:
            self._set(ControllerState.PAUSED, "paused on request; resume to go on")
            return False
        if self.state in _UNTIL_NEW_GOAL:
            return False  # until a new goal
        if self._q_time_ns is None:
            self._set(ControllerState.STALE_INPUT, "no joint state yet")
        elif now_ns - self._q_time_ns > self._joint_state_timeout_ns:
            self._set(ControllerState.STALE_INPUT, f"joint state {(now_ns - self._q_time_ns) * 1e-9:.2f} s old")
        elif self.goal_kind is None:
            if self.state is not ControllerState.IDLE:
                self._set(ControllerState.IDLE, "no goal yet")
        elif self.goal_kind in SERVO_KINDS and now_ns - self._goal_time_ns > self._command_timeout_ns:
            what = self.goal_kind
            self.goal_kind = None
            self._set(ControllerState.IDLE, f"no {what} command for {self.config.command_timeout:g} s: halted")
        elif self._goal_timeout_ns and now_ns - self._goal_time_ns > self._goal_timeout_ns:
            what = "goal" if self.goal_kind is GoalKind.POSE else "joint reference"
            self._set(ControllerState.STALE_INPUT, f"{what} {(now_ns - self._goal_time_ns) * 1e-9:.2f} s old")
        else:
            return True
        return False

    def feed_forward_fresh(self, now_ns: int) -> bool:
        """True while the newest twist is young enough to be used as feed-forward."""
        return self._twist_time_ns is not None and now_ns - self._twist_time_ns <= self._twist_timeout_ns

    def goal_fresh(self, now_ns: int) -> bool:
        """True while the newest goal is younger than the twist timeout: a joint reference's
        velocity is used as feed-forward only then (a stalled stream must not carry the arm on)."""
        return now_ns - self._goal_time_ns <= self._twist_timeout_ns

    def step_failed(self, error: Exception) -> None:
        """The control step raised: zeros go out."""
        self._set(ControllerState.STALE_INPUT, f"control step failed: {error}")

    def pose_step_done(
        self,
        output: PoseStepOutput,
        feed_forward_used: bool,
        now_ns: int,
        braking_joints: Sequence[int] = (),
        ramping: bool = False,
    ) -> None:
        """Classify a pose step. Converged only while the goal is not moving (no feed-forward
        motion), counting the task's error components only. A resting goal whose error stops
        falling (:class:`ProgressMonitor`) while the arm is singular or at joint limits (held
        by the law, or braked before one: ``braking_joints``, at every step of the window) is
        unreachable. ``ramping``: the commands still ramp towards the law's rates (last cycle's
        command was not the law's: held back by the limits, or at rest); the progress is judged
        from when they follow."""
        orientation_error, position_error = self.config.task.error_norms(
            output.orientation_error, output.position_error
        )
        goal_moving = feed_forward_used and self._twist_moving
        limited = sorted(set(output.limited_joints) | set(braking_joints))
        tolerances = (self.config.position_tolerance, self.config.orientation_tolerance)
        if (
            not goal_moving
            and position_error <= self.config.position_tolerance
            and orientation_error <= self.config.orientation_tolerance
        ):
            self.progress.restart()
            self._converged(now_ns)
        elif goal_moving:
            self.progress.restart()
            self._classify_limits(limited, "moving towards the goal")
        elif self.progress.stalled(now_ns, (position_error, orientation_error), tolerances, limited, ramping) and (
            output.singular or self.progress.limited_throughout
        ):
            self.unreachable_errors = (position_error, orientation_error)
            if held := self.progress.limited_throughout:
                why = f"joints at their limits: {', '.join(self.joint_names[i] for i in held)}"
            else:
                why = f"stretched and singular (manipulability {output.manipulability:.3g})"
            self._set(
                ControllerState.UNREACHABLE,
                f"goal out of reach, {why}; closest: {position_error:.4g} m, {orientation_error:.4g} rad away",
            )
        elif output.singular:
            self._set(
                ControllerState.SINGULAR, f"manipulability {output.manipulability:.3g}, damping {output.damping:.3g}"
            )
        else:
            self._classify_limits(limited, "moving towards the goal")

    def collision_blocked(self, blocked) -> None:
        """A collision constraint holds the arm off its goal (a :class:`~manip_kin.control.qp.blocked.Blocked`,
        or None: nothing happens): halted in ``blocked`` until a new goal, the detail naming the pair."""
        if blocked is None:
            return
        self._set(ControllerState.BLOCKED, f"goal not reachable without collision: {blocked.reason}")

    def servo_step_done(self, limited_joints: Sequence[int], singular: bool, scale: float) -> None:
        """Classify a twist or jog step (a velocity command never converges): singular when
        the motion is slowed by more than half for a singularity, else tracking or joint-limited."""
        if singular or scale < 0.5:
            self._set(ControllerState.SINGULAR, f"{self.goal_kind} command slowed to {scale:.0%} near a singularity")
        else:
            self._classify_limits(limited_joints, f"following the {self.goal_kind} command")

    def joint_step_done(self, output: JointStepOutput, feed_forward_used: bool, now_ns: int) -> None:
        """Classify a joint tracking step: converged when the reference rests (or its velocity
        is no longer used) and every joint is within tolerance of it."""
        error = float(np.max(np.abs(output.joint_error))) if len(output.joint_error) else 0.0
        reference_moving = feed_forward_used and self._reference_moving
        if not reference_moving and error <= self.config.joint_tolerance:
            self._converged(now_ns, "joint reference reached within tolerance")
        else:
            self._classify_limits(output.limited_joints, "following the joint reference")

    def _converged(self, now_ns: int, detail: str = "goal reached within tolerance") -> None:
        if self.converged_ns is None:
            self.converged_ns = now_ns
        self._set(ControllerState.CONVERGED, detail)

    def _classify_limits(self, limited_joints: Sequence[int], tracking_detail: str) -> None:
        if limited_joints:
            names = [self.joint_names[i] for i in limited_joints]
            self._set(ControllerState.JOINT_LIMITED, f"joints at a position limit: {', '.join(names)}")
        else:
            self._set(ControllerState.TRACKING, tracking_detail)

    def report_due(self, now_ns: int) -> bool:
        """True when a status should be published now (regular period, or a state change)."""
        return self.throttle.due(now_ns, self.state)

    @property
    def active(self) -> bool:
        """True when the last cycle ran a control step (errors and limits are meaningful)."""
        return self.state not in (ControllerState.IDLE, ControllerState.STALE_INPUT, *HALTED_STATES)

    @property
    def level(self) -> str:
        """Diagnostic level of the state: ``ok`` or ``warn``."""
        warn = (
            ControllerState.STALE_INPUT,
            ControllerState.SINGULAR,
            ControllerState.UNREACHABLE,
            ControllerState.BLOCKED,
        )
        return "warn" if self.state in warn else "ok"

    def _set(self, state: ControllerState, detail: str) -> None:
        self.state = state
        self.detail = detail
