"""Scene obstacles: the shapes that ``collision_objects`` puts in the robot's cell, without ROS.

The topic is a ``visualization_msgs/MarkerArray`` in the base frame, so Foxglove and RViz draw
the same scene the controller avoids and the physics plant collides with. A marker's
``(ns, id)`` names an obstacle; its action means what it means for markers:

* ``ADD`` (0, also ``MODIFY``): put or replace the obstacle;
* ``DELETE`` (2): remove it (unknown keys are ignored, as for markers);
* ``DELETEALL`` (3): remove every obstacle.

Shapes follow the marker conventions: a ``CUBE`` (1) is centred on its pose with full
extents ``scale = (x, y, z)``; a ``SPHERE`` (2) has diameter ``scale.x``; a ``CYLINDER`` (3)
has its axis along its local z, diameter ``scale.x`` and height ``scale.z``; a
``MESH_RESOURCE`` (10) is the mesh at ``mesh_resource`` scaled per axis by ``scale``.
Any other marker type is refused with a reason (see :class:`SceneUpdateError`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum, StrEnum

import numpy as np

from manip_kin.errors import InputError

#: The largest obstacle extent or distance from the base accepted [m]: a cell, not a planet.
MAX_SCENE_EXTENT = 1e3


class SceneUpdateError(InputError):
    """A marker that cannot become an obstacle (shape, size, pose or action)."""


class ShapeKind(StrEnum):
    """Obstacle shapes (the marker types ``collision_objects`` accepts)."""

    BOX = "box"
    SPHERE = "sphere"
    CYLINDER = "cylinder"
    MESH = "mesh"


class MarkerType(IntEnum):
    """``visualization_msgs/Marker`` type constants that map to a :class:`ShapeKind`."""

    CUBE = 1
    SPHERE = 2
    CYLINDER = 3
    MESH_RESOURCE = 10


class MarkerAction(IntEnum):
    """``visualization_msgs/Marker`` action constants."""

    ADD = 0
    DELETE = 2
    DELETEALL = 3


SHAPE_OF_MARKER = {
    MarkerType.CUBE: ShapeKind.BOX,
    MarkerType.SPHERE: ShapeKind.SPHERE,
    MarkerType.CYLINDER: ShapeKind.CYLINDER,
    MarkerType.MESH_RESOURCE: ShapeKind.MESH,
}
MARKER_OF_SHAPE = {shape: marker for marker, shape in SHAPE_OF_MARKER.items()}


@dataclass(frozen=True)
class Obstacle:
    """One obstacle in the base frame.

    Attributes:
        key: ``(ns, id)`` of the marker that made it.
        shape: its :class:`ShapeKind`.
        scale: marker scale ``(x, y, z)`` [m] (see the module docstring for what it means
            per shape; for a mesh, the per-axis scale factor [1]).
        pose_in_base: pose of the shape's centre in the base frame, shape (4, 4).
        mesh_uri: the mesh resource (``package://…``, ``file://…``) for a mesh, else "".
    """

    key: tuple[str, int]
    shape: ShapeKind
    scale: tuple[float, float, float]
    pose_in_base: np.ndarray
    mesh_uri: str = ""

    @property
    def half_extents(self) -> tuple[float, float, float]:
        """Box half extents [m] (box only)."""
        return (0.5 * self.scale[0], 0.5 * self.scale[1], 0.5 * self.scale[2])

    @property
    def radius(self) -> float:
        """Sphere or cylinder radius [m]: half of ``scale.x``."""
        return 0.5 * self.scale[0]

    @property
    def height(self) -> float:
        """Cylinder height [m]: ``scale.z``."""
        return self.scale[2]


def make_obstacle(
    key: tuple[str, int], shape: ShapeKind | str, scale: Iterable[float], pose_in_base, mesh_uri: str = ""
) -> Obstacle:
    """A checked :class:`Obstacle`.

    Raises:
        SceneUpdateError: an unknown shape, a scale that is not three finite values in
            (0, 1000] m, a pose that is not a finite rigid transform within 1000 m of the base,
            or a mesh without a URI.
    """
    name = f"obstacle {key[0]!r}/{key[1]}"
    try:
        shape = ShapeKind(shape)
    except ValueError:
        raise SceneUpdateError(f"{name}: shape {str(shape)[:40]!r}; valid: {', '.join(ShapeKind)}") from None
    scale = tuple(float(v) for v in scale)
    if len(scale) != 3 or not all(math.isfinite(v) and 0.0 < v <= MAX_SCENE_EXTENT for v in scale):
        shown = ", ".join(f"{v:.3g}" for v in scale[:3])
        raise SceneUpdateError(f"{name}: scale ({shown}); valid: three values in (0, {MAX_SCENE_EXTENT:g}]")
    pose = np.array(pose_in_base, dtype=float)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise SceneUpdateError(f"{name}: pose is not a finite 4x4 transform")
    if np.abs(pose[:3, 3]).max() > MAX_SCENE_EXTENT:
        raise SceneUpdateError(f"{name}: position beyond {MAX_SCENE_EXTENT:g} m of the base")
    rotation = pose[:3, :3]
    if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) or np.linalg.det(rotation) < 0:
        raise SceneUpdateError(f"{name}: orientation is not a rotation")
    if shape is ShapeKind.MESH and not mesh_uri:
        raise SceneUpdateError(f"{name}: a mesh needs its mesh_resource URI")
    pose.flags.writeable = False
    return Obstacle(key, shape, scale, pose, mesh_uri if shape is ShapeKind.MESH else "")


class Scene:
    """The obstacles, updated by marker actions; :attr:`version` counts changes.

    Consumers (collision checking, the physics plant) rebuild their geometry only when
    :attr:`version` moved since they last looked.
    """

    def __init__(self):
        self._obstacles: dict[tuple[str, int], Obstacle] = {}
        self.version = 0

    def add(self, obstacle: Obstacle) -> None:
        """Put or replace ``obstacle`` (by its key)."""
        self._obstacles[obstacle.key] = obstacle
        self.version += 1

    def delete(self, key: tuple[str, int]) -> bool:
        """Remove the obstacle with ``key``; False when there was none."""
        if self._obstacles.pop(key, None) is None:
            return False
        self.version += 1
        return True

    def clear(self) -> None:
        """Remove every obstacle."""
        if self._obstacles:
            self._obstacles.clear()
            self.version += 1

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The obstacles, in the order they were first added."""
        return tuple(self._obstacles.values())

    def __len__(self) -> int:
        return len(self._obstacles)
