"""The dynamic parts of a URDF's links: ``<inertial>`` and ``<collision>``, checked field by field.

The kinematic loader (:mod:`manip_kin.core.urdf`) reads joints only; the physics plant also needs
each link's mass, centre of mass and inertia, and its collision shapes. Errors are
:class:`~manip_kin.errors.ModelFileError` naming the source and the field
(``link[panda_link3]/inertial/mass@value``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from manip_kin.core.urdf.document import UrdfTree


@dataclass(frozen=True)
class Inertial:
    """A link's inertial: ``mass`` [kg] at ``origin`` (4, 4) in the link frame, ``inertia``
    ``(ixx, iyy, izz, ixy, ixz, iyz)`` [kg·m²] about the centre of mass in the origin's axes."""

    mass: float
    origin: np.ndarray
    inertia: tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class CollisionShape:
    """One ``<collision>``: ``kind`` box/cylinder/sphere/mesh at ``origin`` (4, 4) in the link frame.

    ``size``: box full extents (3,) [m]; cylinder ``(radius, length)``; sphere ``(radius,)``;
    mesh: the per-axis scale (3,). ``mesh_uri``: the mesh's ``filename`` ("" otherwise).
    """

    kind: str
    origin: np.ndarray
    size: tuple[float, ...]
    mesh_uri: str = ""


@dataclass(frozen=True)
class LinkDynamics:
    """Per link name: its inertial (None when absent) and its collision shapes."""

    inertials: dict[str, Inertial | None]
    collisions: dict[str, tuple[CollisionShape, ...]]


def _origin(reader: UrdfTree, element: ET.Element | None, where: str) -> np.ndarray:
    return np.eye(4) if element is None else reader.origin(element, where)


def _positive(reader: UrdfTree, element: ET.Element, attribute: str, field: str, allow_zero: bool = False) -> float:
    text = element.get(attribute)
    if text is None:
        raise reader.fail(field, "missing")
    value = reader._number(text, field, allow_infinite=False)
    if value < 0 or (value == 0 and not allow_zero):
        raise reader.fail(field, f"{text!r}; valid: a number {'>=' if allow_zero else '>'} 0")
    return value


def _inertial(reader: UrdfTree, link: ET.Element, where: str) -> Inertial | None:
    element = link.find("inertial")
    if element is None:
        return None
    where = f"{where}/inertial"
    mass_element = element.find("mass")
    if mass_element is None:
        raise reader.fail(f"{where}/mass", "missing; an <inertial> needs <mass value=...>")
    mass = _positive(reader, mass_element, "value", f"{where}/mass@value", allow_zero=True)
    inertia_element = element.find("inertia")
    values = [0.0] * 6
    if inertia_element is not None:
        for i, name in enumerate(("ixx", "iyy", "izz", "ixy", "ixz", "iyz")):
            text = inertia_element.get(name, "0")
            values[i] = reader._number(text, f"{where}/inertia@{name}", allow_infinite=False)
        if min(values[:3]) < 0:
            raise reader.fail(f"{where}/inertia", f"negative diagonal {values[:3]}; valid: ixx, iyy, izz >= 0")
    return Inertial(mass, _origin(reader, element, where), tuple(values))


def _collision(reader: UrdfTree, element: ET.Element, where: str) -> CollisionShape | None:
    geometry = element.find("geometry")
    if geometry is None or len(geometry) == 0:
        raise reader.fail(f"{where}/geometry", "missing; valid: box, cylinder, sphere or mesh")
    shape = geometry[0]
    field = f"{where}/geometry/{shape.tag}"
    origin = _origin(reader, element, where)
    if shape.tag == "box":
        size = reader.numbers(shape, "size", f"{field}@size", default=(0.0, 0.0, 0.0))
        if not np.all(size > 0):
            raise reader.fail(f"{field}@size", f"{size.tolist()}; valid: three extents > 0")
        return CollisionShape("box", origin, tuple(size.tolist()))
    if shape.tag == "cylinder":
        radius = _positive(reader, shape, "radius", f"{field}@radius")
        return CollisionShape("cylinder", origin, (radius, _positive(reader, shape, "length", f"{field}@length")))
    if shape.tag == "sphere":
        return CollisionShape("sphere", origin, (_positive(reader, shape, "radius", f"{field}@radius"),))
    if shape.tag == "mesh":
        uri = shape.get("filename", "").strip()
        if not uri:
            raise reader.fail(f"{field}@filename", "missing")
        scale = reader.numbers(shape, "scale", f"{field}@scale", default=(1.0, 1.0, 1.0))
        return CollisionShape("mesh", origin, tuple(scale.tolist()), uri)
    raise reader.fail(field, f"<{shape.tag}>; valid: box, cylinder, sphere, mesh")


def read_link_dynamics(reader: UrdfTree) -> LinkDynamics:
    """Inertials and collision shapes of every link of ``reader``'s document."""
    inertials: dict[str, Inertial | None] = {}
    collisions: dict[str, tuple[CollisionShape, ...]] = {}
    for link in reader.root.findall("link"):
        name = link.get("name", "").strip()
        where = f"link[{name}]"
        inertials[name] = _inertial(reader, link, where)
        shapes = [_collision(reader, c, f"{where}/collision[{i + 1}]") for i, c in enumerate(link.findall("collision"))]
        collisions[name] = tuple(shapes)
    return LinkDynamics(inertials, collisions)
