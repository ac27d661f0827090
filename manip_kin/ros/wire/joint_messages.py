"""Joint-space messages ↔ numpy: ``JointTrajectory`` goals and ``JointState`` joint references.

The joint reference the generator streams to the controller is a ``sensor_msgs/JointState``
on ``joint_reference``: names, positions [rad | m] and velocities [rad/s | m/s] (the
feed-forward), stamped when sampled. A standard message that names its joints, so any
node that can publish a joint state can drive ``cartesian_controller`` in joint space.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Duration
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from manip_kin.core.model import RobotModel
from manip_kin.errors import ProblemKind
from manip_kin.motion.joint_trajectory import TrajectoryPoint
from manip_kin.ros.wire.messages import to_double_array
from manip_kin.ros.wire.validation import InvalidMessageError


def duration_to_seconds(duration: Duration) -> float:
    """A ``builtin_interfaces/Duration`` in seconds."""
    return duration.sec + duration.nanosec * 1e-9


def seconds_to_duration(seconds: float) -> Duration:
    """Seconds (>= 0) as a ``builtin_interfaces/Duration``."""
    nanoseconds = int(round(seconds * 1e9))
    return Duration(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def trajectory_points(msg: JointTrajectory) -> tuple[list[str], list[TrajectoryPoint]]:
    """The joint names and points of a ``JointTrajectory`` (checked later by
    :func:`manip_kin.motion.joint_trajectory.plan_joint_trajectory`)."""
    points = [
        TrajectoryPoint(duration_to_seconds(p.time_from_start), list(p.positions), list(p.velocities))
        for p in msg.points
    ]
    return list(msg.joint_names), points


def make_joint_trajectory(
    joint_names: Sequence[str], points: Sequence[TrajectoryPoint], frame_id: str = ""
) -> JointTrajectory:
    """A ``JointTrajectory`` message (header stamp left for the sender)."""
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.joint_names = list(joint_names)
    for point in points:
        entry = JointTrajectoryPoint()
        entry.positions = to_double_array(np.asarray(point.positions, dtype=float))
        if len(point.velocities):
            entry.velocities = to_double_array(np.asarray(point.velocities, dtype=float))
        entry.time_from_start = seconds_to_duration(point.time_from_start)
        msg.points.append(entry)
    return msg


class JointReferenceReader:
    """Model-order positions and velocities of a joint reference (``JointState``), checked.

    Args:
        model: the robot (joint names and position limits).
        tolerance: how far outside a position limit a reference may lie [rad | m].
    """

    def __init__(self, model: RobotModel, tolerance: float = 1e-9):
        self.model = model
        self._lower = model.lower - tolerance
        self._upper = model.upper + tolerance
        self._names: list[str] | None = None
        self._index: np.ndarray | None = None

    def read(self, msg: JointState) -> tuple[np.ndarray, np.ndarray]:
        """``(positions, velocities)`` in model order, shapes (n,) (velocities zero when absent).

        Raises:
            InvalidMessageError: joints missing, counts differing from the names, non-finite
                values, or a position outside the joint limits.
        """
        names = list(msg.name)
        if names != self._names:
            lookup = {name: i for i, name in enumerate(names)}
            repeated = sorted({name for name in names if names.count(name) > 1})
            if repeated:
                raise InvalidMessageError(
                    f"joint reference names {repeated} more than once; valid: each joint once", kind=ProblemKind.LENGTH
                )
            missing = [name for name in self.model.joint_names if name not in lookup]
            if missing:
                raise InvalidMessageError(
                    f"joint reference lacks joints {missing}; valid: names including {self.model.joint_names}",
                    kind=ProblemKind.LENGTH,
                )
            self._names = names
            self._index = np.array([lookup[name] for name in self.model.joint_names], dtype=np.intp)
        position = np.asarray(msg.position, dtype=float)
        velocity = np.asarray(msg.velocity, dtype=float)
        if position.shape[0] != len(names) or velocity.shape[0] not in (0, len(names)):
            raise InvalidMessageError(
                f"joint reference has {len(names)} names, {position.shape[0]} positions and "
                f"{velocity.shape[0]} velocities; valid: one position per name, velocities none or one per name",
                kind=ProblemKind.LENGTH,
            )
        q = position[self._index]
        qdot = velocity[self._index] if velocity.shape[0] else np.zeros_like(q)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qdot))):
            raise InvalidMessageError(
                "joint reference contains NaN or infinity; valid: finite numbers", kind=ProblemKind.NON_FINITE
            )
        outside = np.flatnonzero((q < self._lower) | (q > self._upper))
        if outside.size:
            j = int(outside[0])
            raise InvalidMessageError(
                f"joint reference puts '{self.model.joint_names[j]}' at {q[j]:.6g}, outside its limits "
                f"[{self.model.lower[j]:.6g}, {self.model.upper[j]:.6g}]",
                kind=ProblemKind.RANGE,
            )
        return q, qdot
