"""Named access to the flat values a compiled chain returns (``codegen.chain``, the hot path):
the controlled frame's pose, 4x4 row-major (16 values), then, with the Jacobian, its geometric
Jacobian, 6 rows of ``n`` (angular rows 0-2, linear rows 3-5), row-major."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["POSE_VALUES", "jacobian_entry", "jacobian_of", "jacobian_row", "pose_of", "zero_joint_column"]

#: How many values the pose takes before the Jacobian starts.
POSE_VALUES = 16


def jacobian_entry(n: int, row: int, joint: int) -> int:
    """The index of ``J[row, joint]`` (row 0..5, joint 0..n-1) in the values of an ``n``-joint chain."""
    return POSE_VALUES + row * n + joint


def jacobian_row(values: Sequence[float], n: int, row: int) -> Sequence[float]:
    """Row ``row`` of the Jacobian, ``n`` values."""
    start = POSE_VALUES + row * n
    return values[start : start + n]


def pose_of(values: Sequence[float]) -> Sequence[float]:
    """The pose's 16 values, row-major."""
    return values[:POSE_VALUES]


def jacobian_of(values: Sequence[float], n: int) -> np.ndarray:
    """The Jacobian as an array, shape (6, n) (a view where ``values`` is an array)."""
    if isinstance(values, np.ndarray):
        return values[POSE_VALUES:].reshape(6, n)
    return np.fromiter(values[POSE_VALUES:], float, 6 * n).reshape(6, n)


def zero_joint_column(values: list[float], n: int, joint: int) -> None:
    """Set the Jacobian's column of ``joint`` to zero in place (a joint held at a limit)."""
    for row in range(6):
        values[POSE_VALUES + row * n + joint] = 0.0
