"""What a distance query returns: a pair's distance and witness points, a cycle's damper rows
(:class:`~manip_kin.collision.distances.CollisionChecker` makes them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def obstacle_name(key: tuple[str, int]) -> str:
    """How an obstacle appears in a pair: ``obstacle:<ns>/<id>``."""
    return f"obstacle:{key[0]}/{key[1]}"


@dataclass(frozen=True)
class PairDistance:
    """The distance between two shapes, in base.

    Attributes:
        first: link name.
        second: link name, or :func:`obstacle_name` of an obstacle.
        distance: signed distance [m]; negative = penetration depth.
        point_first: witness point on ``first``, shape (3,) [m].
        point_second: witness point on ``second``, shape (3,) [m].
        normal: unit vector from ``first`` to ``second``, shape (3,).
    """

    first: str
    second: str
    distance: float
    point_first: np.ndarray
    point_second: np.ndarray
    normal: np.ndarray

    @property
    def pair(self) -> tuple[str, str]:
        """``(first, second)``."""
        return (self.first, self.second)

    @property
    def label(self) -> str:
        """``first–second`` for logs and status."""
        return f"{self.first}-{self.second}"


@dataclass(frozen=True)
class DamperRows:
    """The collision limit of one cycle: ``A q̇ <= b``, one row per shape pair within ``d_i``.

    Attributes:
        labels: the pair of each row, ``first-second`` (see :attr:`PairDistance.label`).
        distances: the pair distances, shape (k,) [m].
        matrix: ``A``, shape (k, n).
        bound: ``b``, shape (k,) [m/s].
        nearest: the nearest pair (None when no pair is within ``d_i``).
    """

    labels: tuple[str, ...]
    distances: np.ndarray
    matrix: np.ndarray
    bound: np.ndarray
    nearest: PairDistance | None
