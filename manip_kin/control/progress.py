"""Whether a resting goal's task error still falls: the controller's unreachable-goal detector."""

from __future__ import annotations

from collections.abc import Sequence

#: Unreachable: over this long [s] of a resting goal, the task error fell by less than
#: :data:`PROGRESS_FRACTION` of itself while the arm was singular or at joint limits.
PROGRESS_WINDOW_S = 0.5
PROGRESS_FRACTION = 0.02


class ProgressMonitor:
    """Whether the task error still falls: the unreachable-goal detector.

    Every :attr:`window_ns` it compares the task's position and orientation errors with those
    at the window's start; a window in which neither fell by :data:`PROGRESS_FRACTION` (the
    components already within tolerance not counted) is a stall. Exponential convergence at
    gain K falls by ``1 - exp(-K T)`` a window (33 % at K = 0.8 1/s, T = 0.5 s), so a stall is
    not slow progress.

    It also keeps the joints limited at every step of the window (:attr:`limited_throughout`,
    of the window that ended last): a joint on its limit stays limited, while a singular arm's
    rates swing wide enough to hold a joint for a cycle far from its limit (seen: 0.6 rad).

    The first window after a restart starts once the commands follow the law's rates: while
    they still ramp up within the acceleration and jerk limits, the arm moves too little to
    judge (seen: a goal 3 m away, joint1 at 2 rad/s², found unreachable after 0.5 s). It starts
    one window after the first step at the latest, as at a singularity the law's rates can
    change faster than the commands follow, for as long as the arm stays there.
    """

    def __init__(self, window_ns: int):
        self.window_ns = int(window_ns)
        self.restart()

    def restart(self) -> None:
        """Forget the history (a new goal, a moving goal, a resumed motion)."""
        self._start_ns: int | None = None
        self._first_ns: int | None = None
        self._start_errors = (0.0, 0.0)
        self._limited: set[int] = set()
        self.limited_throughout: tuple[int, ...] = ()

    def stalled(
        self,
        now_ns: int,
        errors: tuple[float, float],
        tolerances: tuple[float, float],
        limited: Sequence[int] = (),
        ramping: bool = False,
    ) -> bool:
        """True when the window that ends now made no progress (then a new window starts).
        ``limited``: the joints limited at this step; ``ramping``: the commands still ramp
        towards the law's rates (held back by the acceleration or jerk limits)."""
        if self._start_ns is None:
            if self._first_ns is None:
                self._first_ns = now_ns
            if not ramping or now_ns - self._first_ns >= self.window_ns:
                self._start_ns, self._start_errors, self._limited = now_ns, errors, set(limited)
            return False
        self._limited.intersection_update(limited)
        if now_ns - self._start_ns < self.window_ns:
            return False
        progress = any(
            start > tolerance and error < (1.0 - PROGRESS_FRACTION) * start
            for error, start, tolerance in zip(errors, self._start_errors, tolerances)
        )
        self.limited_throughout = tuple(sorted(self._limited))
        self._start_ns, self._start_errors, self._limited = now_ns, errors, set(limited)
        return not progress
