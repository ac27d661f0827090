"""The checks every node applies to what it receives, before anything is computed from it.

Each ``*_problem(...)`` returns ``None`` for a usable message or a one-line reason that
names what was received and what is valid: a :class:`~manip_kin.errors.Problem`, a ``str``
carrying the :class:`~manip_kin.errors.ProblemKind` of the check that failed (a node keys its
throttled log line on it); ``check_*(...)`` raises :class:`InvalidMessageError` with the same
reason and kind. The bounds (reach, speeds, joint ranges) come from
:class:`manip_kin.core.bounds.InputBounds`, computed once per model.
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseStamped, TwistStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from manip_kin.errors import InputError, Problem, ProblemKind

#: Default tolerance on ``| |q| - 1 |`` for a goal quaternion: hand-typed quaternions
#: such as ``0 0.707 0 0.707`` pass, a zero or unnormalised one does not.
QUATERNION_TOLERANCE = 1e-2


class InvalidMessageError(InputError):
    """A message a node must reject: non-finite values, wrong length, wrong frame, bad quaternion.

    Bad input, so an :class:`~manip_kin.errors.InputError` (exit code 2 where it ends a CLI);
    ``kind`` (keyword, or that of a :class:`~manip_kin.errors.Problem` message) says which."""


class JointStateMapper:
    """Reorders ``JointState`` messages into model joint order, matching by name.

    The index map is rebuilt only when a message's name list differs from the last one,
    so the per-message cost is one list comparison and one fancy index.

    Args:
        joint_names: the model's joint names in model order.
        lower: smallest accepted position per joint (model order), shape (n,); default: none.
        upper: largest accepted position per joint, shape (n,); default: none.
    """

    def __init__(self, joint_names: Sequence[str], lower=None, upper=None):
        self.joint_names = list(joint_names)
        n = len(self.joint_names)
        # Finite bounds (an infinite one becomes the largest float), so that the range check
        # alone refuses ±inf as well as NaN.
        largest = np.finfo(float).max
        self.lower = np.full(n, -largest) if lower is None else np.maximum(np.asarray(lower, dtype=float), -largest)
        self.upper = np.full(n, largest) if upper is None else np.minimum(np.asarray(upper, dtype=float), largest)
        self._ranges = tuple(zip(self.lower.tolist(), self.upper.tolist()))
        self._last_names: list[str] | None = None
        self._index: np.ndarray | None = None
        self._problem: Problem | None = None

    def positions(self, msg: JointState) -> np.ndarray:
        """Positions of ``msg`` in model order, shape (n,).

        Raises:
            InvalidMessageError: a model joint missing or named twice, position and name
                counts differing, a non-finite position or one far outside the joint's range.
        """
        names = msg.name
        if names != self._last_names:
            self._rebuild(list(names))
        if self._problem is not None:
            raise InvalidMessageError(self._problem)
        position = (
            np.frombuffer(msg.position, dtype=np.float64)
            if isinstance(msg.position, array.array)
            else np.asarray(msg.position, dtype=float)
        )
        if position.shape[0] != len(names):
            raise InvalidMessageError(
                f"joint state has {len(names)} names but {position.shape[0]} positions; valid: one position per name",
                kind=ProblemKind.LENGTH,
            )
        return self.check_positions(position[self._index])

    def velocities(self, msg: JointState) -> np.ndarray | None:
        """Velocities of ``msg`` in model order, shape (n,), or None unless it has one per name.

        Call after :meth:`positions` accepted ``msg`` (it builds the joint order). The values
        are not checked: whoever uses them decides what is plausible.
        """
        velocity = msg.velocity
        if self._index is None or len(velocity) != len(msg.name):
            return None
        return np.asarray(velocity, dtype=float)[self._index]

    def check_positions(self, ordered: np.ndarray) -> np.ndarray:
        """``ordered`` (model order) if finite and within the accepted ranges, else :class:`InvalidMessageError`."""
        # The 1 kHz path: two comparisons accept a good state (both are False for NaN).
        if np.greater_equal(ordered, self.lower).all() and np.less_equal(ordered, self.upper).all():
            return ordered
        if not np.isfinite(ordered).all():
            raise InvalidMessageError(
                "joint state positions contain NaN or infinity; valid: finite numbers", kind=ProblemKind.NON_FINITE
            )
        outside = np.flatnonzero((ordered < self.lower) | (ordered > self.upper))
        if outside.size:
            i = int(outside[0])
            raise InvalidMessageError(
                f"joint state position of {self.joint_names[i]} is {ordered[i]:.6g}, out of range; "
                f"valid: [{self.lower[i]:.6g}, {self.upper[i]:.6g}] (limits with a margin)",
                kind=ProblemKind.RANGE,
            )
        return ordered

    def checked_values(self, values: Sequence[float]) -> np.ndarray:
        """:meth:`check_positions` of plain floats (model order), as an array: the 1 kHz path,
        where Python comparisons on n ≈ 6 floats cost a third of numpy's calls."""
        for value, (lower, upper) in zip(values, self._ranges):
            if not lower <= value <= upper:  # False for NaN too
                return self.check_positions(np.array(values, dtype=float))  # raises, saying what is wrong
        return np.array(values, dtype=float)

    def _rebuild(self, names: list[str]) -> None:
        self._last_names = names
        lookup = {name: i for i, name in enumerate(names)}
        repeated = sorted({name for name in names if names.count(name) > 1 and name in self.joint_names})
        if repeated:
            self._problem = Problem(
                ProblemKind.LENGTH, f"joint state names {repeated} more than once; valid: each joint once"
            )
            self._index = None
            return
        missing = [name for name in self.joint_names if name not in lookup]
        if missing:
            self._problem = Problem(
                ProblemKind.LENGTH, f"joint state lacks joints {missing}; valid: names including {self.joint_names}"
            )
            self._index = None
            return
        self._problem = None
        self._index = np.array([lookup[name] for name in self.joint_names], dtype=np.intp)


def frame_problem(frame_id: str, base_frame: str, what: str) -> Problem | None:
    """Reason to reject a header frame that is not the base frame (no tf2 here), or None."""
    if frame_id != base_frame:
        return Problem(
            ProblemKind.FRAME,
            f"{what} frame_id {frame_id!r} is not the base frame; valid: {base_frame!r} (no tf2 transforms)",
        )
    return None


def pose_problem(
    msg: PoseStamped,
    base_frame: str,
    what: str = "pose",
    quaternion_tolerance: float = QUATERNION_TOLERANCE,
    max_distance: float = math.inf,
) -> Problem | None:
    """Reason to reject a goal ``PoseStamped``, or None when it is usable.

    Checks, in order: frame id equals ``base_frame``; position and quaternion finite;
    position within ``max_distance`` [m] of the base origin (see
    :class:`manip_kin.core.bounds.InputBounds`); quaternion length within
    ``quaternion_tolerance`` of 1.
    """
    problem = frame_problem(msg.header.frame_id, base_frame, what)
    if problem:
        return problem
    p, o = msg.pose.position, msg.pose.orientation
    values = (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
    if not all(math.isfinite(v) for v in values):
        return Problem(
            ProblemKind.NON_FINITE, f"{what} contains NaN or infinity {values}; valid: finite position and quaternion"
        )
    distance = math.hypot(p.x, p.y, p.z)
    if distance > max_distance:
        return Problem(
            ProblemKind.REACH,
            f"{what} position ({p.x:.6g}, {p.y:.6g}, {p.z:.6g}) is {distance:.6g} m from the base; "
            f"valid: within {max_distance:.4g} m (twice the arm's reach radius)",
        )
    # hypot: no overflow to inf for huge finite components, no underflow to 0 for subnormal ones.
    norm = math.hypot(o.x, o.y, o.z, o.w)
    if not abs(norm - 1.0) <= quaternion_tolerance:
        return Problem(
            ProblemKind.QUATERNION,
            f"{what} quaternion ({o.x:g}, {o.y:g}, {o.z:g}, {o.w:g}) has length {norm:.6g}; "
            f"valid: unit length within {quaternion_tolerance:g}",
        )
    return None


def twist_problem(
    msg: TwistStamped,
    base_frame: str,
    what: str = "twist",
    max_linear: float = math.inf,
    max_angular: float = math.inf,
) -> Problem | None:
    """Reason to reject a ``TwistStamped`` (wrong frame, non-finite, faster than ``max_linear``
    [m/s] or ``max_angular`` [rad/s]), or None."""
    problem = frame_problem(msg.header.frame_id, base_frame, what)
    if problem:
        return problem
    a, v = msg.twist.angular, msg.twist.linear
    values = (a.x, a.y, a.z, v.x, v.y, v.z)
    if not all(math.isfinite(value) for value in values):
        return Problem(ProblemKind.NON_FINITE, f"{what} contains NaN or infinity {values}; valid: finite numbers")
    linear = math.hypot(v.x, v.y, v.z)
    angular = math.hypot(a.x, a.y, a.z)
    if linear > max_linear or angular > max_angular:
        return Problem(
            ProblemKind.SPEED,
            f"{what} of {linear:.6g} m/s, {angular:.6g} rad/s is too fast; "
            f"valid: at most {max_linear:.4g} m/s and {max_angular:.4g} rad/s (twice what the arm can do)",
        )
    return None


def command_problem(
    values: np.ndarray, dof: int, what: str = "joint velocity command", max_abs: np.ndarray | None = None
) -> Problem | None:
    """Reason to reject a joint-rate command (wrong length, non-finite, absurd), or None.

    ``max_abs`` (shape (dof,)) bounds each |rate|: a command a little over a velocity limit
    is scaled into the limits by the arm; one far beyond is a mistake.
    """
    if values.shape[0] != dof:
        return Problem(
            ProblemKind.LENGTH, f"{what} has {values.shape[0]} values; valid: {dof} (one per joint, model order)"
        )
    # The 1 kHz path: one comparison accepts a good command (it is False for NaN and ±inf too).
    if max_abs is not None and np.less_equal(np.abs(values), max_abs).all():
        return None
    if not np.isfinite(values).all():
        return Problem(ProblemKind.NON_FINITE, f"{what} contains NaN or infinity; valid: finite numbers")
    if max_abs is not None:
        over = np.flatnonzero(np.abs(values) > max_abs)
        if over.size:
            i = int(over[0])
            return Problem(
                ProblemKind.SPEED,
                f"{what} value {i} is {values[i]:.6g}, absurd; valid: |value| <= {max_abs[i]:.4g} (100x its velocity limit)",
            )
    return None


def _raise_if(problem: Problem | None) -> None:
    if problem is not None:
        raise InvalidMessageError(problem)


def check_command(msg: Float64MultiArray, dof: int, what: str = "joint velocity command") -> np.ndarray:
    """The data of a valid command as a vector of shape (dof,), or :class:`InvalidMessageError`."""
    values = np.array(msg.data, dtype=float)
    _raise_if(command_problem(values, dof, what))
    return values
