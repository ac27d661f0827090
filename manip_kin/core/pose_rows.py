"""Which components of a pose a controller or IK solver is asked to achieve.

A pose error has six components ``[rx, ry, rz, x, y, z]``: the rotation vector (angle-axis
of the relative rotation, in base) and the position difference (in base). An arm with
fewer than six joints cannot achieve an arbitrary pose, so it is given a partial task:

* ``full``: all six (the default for arms with six or more joints);
* ``position``: ``x, y, z`` (e.g. the 3-DoF rpp arm);
* ``orientation``: ``rx, ry, rz``;
* ``position_yaw``: ``rz, x, y, z`` (a SCARA: position and rotation about the base z axis);
* or any comma-separated subset, e.g. ``"rz,x,y"``, or a mask of six 0/1 values.

:func:`default_task` picks one for a model from the directions its joints can move the frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.core.plain_floats import float_list
from manip_kin.errors import InvalidArgumentError

COMPONENTS = ("rx", "ry", "rz", "x", "y", "z")
NAMED_TASKS = {
    "full": (0, 1, 2, 3, 4, 5),
    "position": (3, 4, 5),
    "orientation": (0, 1, 2),
    "position_yaw": (2, 3, 4, 5),
}
_VALID = "full, position, orientation, position_yaw, a comma list of rx,ry,rz,x,y,z, or six 0/1 mask values"


@dataclass(frozen=True)
class Task:
    """A subset of the six pose-error components.

    Attributes:
        rows: indices into ``[rx, ry, rz, x, y, z]``, increasing, at least one.
    """

    rows: tuple[int, ...]

    def __post_init__(self):
        rows = tuple(sorted(set(int(r) for r in self.rows)))
        if not rows or rows[0] < 0 or rows[-1] > 5:
            raise InvalidArgumentError(
                f"task rows {self.rows!r}; valid: a non-empty subset of 0..5 ({', '.join(COMPONENTS)})"
            )
        object.__setattr__(self, "rows", rows)

    @property
    def name(self) -> str:
        """``full``, ``position``, … or the comma-separated components."""
        for name, rows in NAMED_TASKS.items():
            if rows == self.rows:
                return name
        return ",".join(COMPONENTS[r] for r in self.rows)

    @property
    def mask(self) -> tuple[bool, ...]:
        """Six booleans over ``[rx, ry, rz, x, y, z]``."""
        return tuple(r in self.rows for r in range(6))

    @property
    def size(self) -> int:
        """Number of task components m."""
        return len(self.rows)

    @cached_property
    def orientation_rows(self) -> tuple[int, ...]:
        """The task's rotation components (indices 0..2)."""
        return tuple(r for r in self.rows if r < 3)

    @cached_property
    def position_rows(self) -> tuple[int, ...]:
        """The task's position components (indices 3..5)."""
        return tuple(r for r in self.rows if r >= 3)

    @property
    def is_contiguous(self) -> bool:
        """True when the rows form one slice (then Jacobian rows are a view, not a copy)."""
        return self.rows == tuple(range(self.rows[0], self.rows[-1] + 1))

    def error_norms(self, orientation_error: Sequence[float], position_error: Sequence[float]) -> tuple[float, float]:
        """Norms of the task's orientation [rad] and position [m] components of an error.

        Runs every control cycle: plain floats and loops (indexing a numpy array element by
        element costs more than the arithmetic).
        """
        orientation = float_list(orientation_error)
        position = float_list(position_error)
        orientation_squares = position_squares = 0.0
        for r in self.orientation_rows:
            orientation_squares += float(orientation[r]) ** 2
        for r in self.position_rows:
            position_squares += float(position[r - 3]) ** 2
        return orientation_squares**0.5, position_squares**0.5


FULL_TASK = Task(NAMED_TASKS["full"])


def parse_task(spec: str | Sequence | Task | None, model: RobotModel | None = None) -> Task:
    """A :class:`Task` from a name, a comma list, a six-value mask or a Task.

    Args:
        spec: see the module docstring; None or ``"auto"`` means :func:`default_task` of ``model``
            (``full`` without a model).
        model: the robot, for the automatic choice.
    """
    if isinstance(spec, Task):
        return spec
    if spec is None or (isinstance(spec, str) and spec.strip().lower() in ("", "auto")):
        return default_task(model) if model is not None else FULL_TASK
    if isinstance(spec, str):
        key = spec.strip().lower()
        if key in NAMED_TASKS:
            return Task(NAMED_TASKS[key])
        parts = [part.strip() for part in key.split(",") if part.strip()]
        unknown = [part for part in parts if part not in COMPONENTS]
        if not parts or unknown:
            raise InvalidArgumentError(f"task {spec!r}; valid: {_VALID}")
        return Task(tuple(COMPONENTS.index(part) for part in parts))
    values = list(spec)
    if len(values) != 6 or any(v not in (0, 1, True, False) for v in values):
        raise InvalidArgumentError(f"task mask {values!r}; valid: six 0/1 values over rx, ry, rz, x, y, z")
    rows = tuple(i for i, v in enumerate(values) if v)
    if not rows:
        raise InvalidArgumentError("task mask selects no component; valid: at least one 1 among six values")
    return Task(rows)


def default_task(model: RobotModel, frame: str | int | None = None) -> Task:
    """The task an arm can actually achieve: ``full`` with six or more joints, else a partial one.

    With fewer than six joints: position, plus the rotation components (about base x, y, z)
    the joints can change at all — found from the angular Jacobian rows at a few random
    configurations — if the joints are enough for them; otherwise position only. A SCARA
    gets ``position_yaw``, the rpp arm ``position``.
    """
    if model.dof >= 6:
        return FULL_TASK
    return model.kernels.get(("default task", frame), _achievable_task, model, frame)


def _achievable_task(model: RobotModel, frame: str | int | None) -> Task:
    from manip_kin.core.kinematics import jacobian

    rng = np.random.default_rng(0)
    angular = np.zeros(3)
    for _ in range(5):
        angular += np.abs(jacobian(model, model.random_configuration(rng), frame).angular).sum(axis=1)
    rotating = tuple(int(r) for r in np.flatnonzero(angular > 1e-9))
    return Task(rotating + (3, 4, 5)) if 3 + len(rotating) <= model.dof else Task((3, 4, 5))
