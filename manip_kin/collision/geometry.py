"""Collision shapes: a URDF's ``<collision>`` elements on the model frames they move with, and obstacles.

Every link of the URDF that has ``<collision>`` elements gets one :class:`LinkGeometry` per
element, attached to the model frame it moves with (:meth:`RobotModel.frame_index` numbering,
0 = base, i = the child link of joint i):

* a chain link is frame i itself;
* a link below it through fixed joints (``panda_link8``, ``panda_hand`` after the tip) is
  frame i times the fixed joints' product;
* a link below it through a movable joint that is not on the chain (the Panda's fingers)
  is placed with that joint at its zero position, clipped into its limits;
* a link outside the base's subtree is fixed on the base.

Shapes follow the URDF: ``<box size>`` full extents, ``<cylinder radius length>`` along
local z, ``<sphere radius>``, ``<mesh filename scale>`` (see :mod:`manip_kin.collision.meshes`).
Each shape carries a bounding sphere (centre in its own frame, radius), the cheap lower bound
on distances that lets a control cycle skip the far pairs.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.collision.meshes import convex_vertices, load_convex_mesh
from manip_kin.core.kinematics import compiled_frames
from manip_kin.core.mesh_uris import require_mesh_file
from manip_kin.core.model import RobotModel
from manip_kin.core.rotations import angle_axis_to_matrix, invert_transform
from manip_kin.core.scene import Obstacle, ShapeKind
from manip_kin.core.urdf.document import UrdfJoint, UrdfTree
from manip_kin.errors import ModelFileError


@dataclass(frozen=True)
class CollisionShape:
    """One convex shape in its own frame.

    Attributes:
        kind: box, sphere, cylinder or mesh (its convex hull).
        size: box full extents (x, y, z) [m]; sphere (radius,) [m]; cylinder (radius, length)
            [m]; mesh: scale factors (x, y, z) [1].
        source: the mesh file, else "".
        centre: bounding-sphere centre in the shape frame, shape (3,) [m].
        radius: bounding-sphere radius [m].
        coal_shape: the ``coal.CollisionGeometry`` the queries use.
    """

    kind: ShapeKind
    size: tuple[float, ...]
    source: str
    centre: np.ndarray
    radius: float
    coal_shape: object = field(repr=False, compare=False)


def make_shape(kind: ShapeKind, size, mesh_path: Path | None = None, where: str = "", field_name: str = ""):
    """A :class:`CollisionShape` (box extents, sphere radius, cylinder radius and length, mesh scale)."""
    import coal

    size = tuple(float(v) for v in size)
    centre = np.zeros(3)
    if kind is ShapeKind.BOX:
        shape, radius = coal.Box(*size), 0.5 * math.sqrt(sum(v * v for v in size))
    elif kind is ShapeKind.SPHERE:
        shape, radius = coal.Sphere(size[0]), size[0]
    elif kind is ShapeKind.CYLINDER:
        shape, radius = coal.Cylinder(size[0], size[1]), math.hypot(size[0], 0.5 * size[1])
    else:
        shape = load_convex_mesh(mesh_path, size, where, field_name)
        vertices = convex_vertices(shape)
        centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        radius = float(np.linalg.norm(vertices - centre, axis=1).max())
    centre.setflags(write=False)
    return CollisionShape(kind, size, str(mesh_path or ""), centre, float(radius), shape)


def obstacle_shape(obstacle: Obstacle, mesh_search_path: str = "") -> CollisionShape:
    """The shape of a scene obstacle (marker conventions, see :mod:`manip_kin.core.scene`).

    Raises:
        ModelFileError: a mesh obstacle whose file cannot be found or read.
    """
    where = f"obstacle {obstacle.key[0]!r}/{obstacle.key[1]}"
    if obstacle.shape is ShapeKind.BOX:
        return make_shape(ShapeKind.BOX, obstacle.scale)
    if obstacle.shape is ShapeKind.SPHERE:
        return make_shape(ShapeKind.SPHERE, (obstacle.radius,))
    if obstacle.shape is ShapeKind.CYLINDER:
        return make_shape(ShapeKind.CYLINDER, (obstacle.radius, obstacle.height))
    try:
        path = require_mesh_file(obstacle.mesh_uri, mesh_search_path)
    except FileNotFoundError as error:
        raise ModelFileError(where, "mesh_resource", str(error)) from None
    return make_shape(ShapeKind.MESH, obstacle.scale, path, where, "mesh_resource")


@dataclass(frozen=True)
class LinkGeometry:
    """One ``<collision>`` element of a link, on the model frame it moves with.

    Attributes:
        link: URDF link name.
        frame: model frame index it moves with (0 = base, 1..n = joint frames).
        offset: pose of the shape in that frame, shape (4, 4).
        shape: the shape.
    """

    link: str
    frame: int
    offset: np.ndarray
    shape: CollisionShape


def _joint_at_rest(joint: UrdfJoint) -> np.ndarray:
    """The parent-to-child transform of a URDF joint at 0 clipped into its limits, shape (4, 4)."""
    if joint.type in ("fixed", "floating", "planar"):
        return joint.origin
    position = 0.0
    if joint.type != "continuous":
        position = min(max(0.0, joint.limit.get("lower", 0.0)), joint.limit.get("upper", 0.0))
    motion = np.eye(4)
    if joint.type == "prismatic":
        motion[:3, 3] = joint.axis * position
    else:
        motion[:3, :3] = angle_axis_to_matrix(position, joint.axis)
    return joint.origin @ motion


def _from_root(reader: UrdfTree, link: str) -> np.ndarray:
    transform = np.eye(4)
    for _ in range(len(reader.joints) + 1):
        joint = reader.parent_joint.get(link)
        if joint is None:
            break
        transform = _joint_at_rest(joint) @ transform
        link = joint.parent
    return transform


def link_anchor(model: RobotModel, reader: UrdfTree, link: str) -> tuple[int, np.ndarray]:
    """``(model frame index, pose of link in that frame)`` for any link of the URDF."""
    anchors = {model.base_frame: 0}
    anchors.update({joint.link_name: i for i, joint in enumerate(model.joints, start=1) if joint.link_name})
    transform, current = np.eye(4), link
    for _ in range(len(reader.joints) + 1):
        if current in anchors:
            return anchors[current], transform
        joint = reader.parent_joint.get(current)
        if joint is None:
            break
        transform = _joint_at_rest(joint) @ transform
        current = joint.parent
    # Not below the base (a link above it, another branch of the tree): fixed on the base.
    return 0, invert_transform(_from_root(reader, model.base_frame)) @ _from_root(reader, link)


def _urdf_shape(reader: UrdfTree, element: ET.Element, where: str, mesh_search_path: str) -> CollisionShape:
    geometry = element.find("geometry")
    shapes = [] if geometry is None else list(geometry)
    if len(shapes) != 1:
        raise reader.fail(f"{where}/geometry", f"{len(shapes)} shapes; valid: one of box, cylinder, sphere, mesh")
    shape = shapes[0]
    at = f"{where}/geometry/{shape.tag}"
    if shape.tag == "box":
        size = reader.numbers(shape, "size", f"{at}@size", default=(math.nan,) * 3)
        kind, values = ShapeKind.BOX, size
    elif shape.tag == "sphere":
        kind, values = ShapeKind.SPHERE, reader.numbers(shape, "radius", f"{at}@radius", default=(math.nan,))
    elif shape.tag == "cylinder":
        radius = reader.numbers(shape, "radius", f"{at}@radius", default=(math.nan,))
        length = reader.numbers(shape, "length", f"{at}@length", default=(math.nan,))
        kind, values = ShapeKind.CYLINDER, np.concatenate([radius, length])
    elif shape.tag == "mesh":
        uri = shape.get("filename", "").strip()
        if not uri:
            raise reader.fail(f"{at}@filename", "missing; a mesh needs a file name")
        scale = reader.numbers(shape, "scale", f"{at}@scale", default=(1.0, 1.0, 1.0))
        if not np.all(scale > 0):
            raise reader.fail(f"{at}@scale", f"{scale.tolist()}; valid: three factors > 0")
        relative_to = Path(reader.source).parent if Path(reader.source).is_file() else None
        try:
            path = require_mesh_file(uri, mesh_search_path, relative_to)
        except FileNotFoundError as error:
            raise reader.fail(f"{at}@filename", str(error)) from None
        return make_shape(ShapeKind.MESH, scale, path, reader.source, f"{at}@filename")
    else:
        raise reader.fail(at, f"<{shape.tag}>; valid: box, cylinder, sphere, mesh")
    if not np.all(np.isfinite(values)) or not np.all(values > 0):
        raise reader.fail(at, f"{values.tolist()} (missing or not > 0); valid: positive sizes [m]")
    return make_shape(kind, values)


def link_geometries(model: RobotModel, reader: UrdfTree, mesh_search_path: str = "") -> tuple[LinkGeometry, ...]:
    """Every ``<collision>`` element of the URDF as a :class:`LinkGeometry`, in document order.

    Raises:
        ModelFileError: a malformed element or a mesh that cannot be found or read; the
            message names the URDF and the field, e.g. ``link[panda_link3]/collision[1]/geometry/mesh@filename``.
    """
    geometries = []
    for element in reader.root.findall("link"):
        link = element.get("name", "").strip()
        collisions = element.findall("collision")
        if not collisions:
            continue
        frame, link_pose = link_anchor(model, reader, link)
        for index, collision in enumerate(collisions, start=1):
            where = f"link[{link}]/collision[{index}]"
            shape = _urdf_shape(reader, collision, where, mesh_search_path)
            offset = link_pose @ reader.origin(collision, where)
            offset.setflags(write=False)
            geometries.append(LinkGeometry(link, frame, offset, shape))
    return tuple(geometries)


def adjacent_links(reader: UrdfTree, links_with_geometry: set[str]) -> set[tuple[str, str]]:
    """Pairs of links with geometry joined by a joint, or by a chain of links without geometry
    (as MoveIt's setup assistant counts adjacency), as sorted tuples."""
    from manip_kin.collision.srdf import link_pair

    pairs = set()
    for link in links_with_geometry:
        joint, parent = reader.parent_joint.get(link), None
        for _ in range(len(reader.joints) + 1):
            if joint is None:
                break
            parent = joint.parent
            if parent in links_with_geometry:
                pairs.add(link_pair(link, parent))
                break
            joint = reader.parent_joint.get(parent)
    return pairs


def model_frames(model: RobotModel, q: np.ndarray) -> np.ndarray:
    """Frames 0 (base) .. n of the model in base at ``q`` (n,), shape (n + 1, 4, 4)."""
    return frames_and_twists(model, q)[0]


def frame_values(model: RobotModel, q: np.ndarray) -> tuple[float, ...]:
    """Frames 0 (base) .. n in base (16 values each, row-major 4x4), then the joints' unit twists
    ``[ω; v]`` in base (6 x n, row-major), at ``q`` (n,), flat: the generated function's own
    output (see :func:`~manip_kin.codegen.chain.generate_frames_source`), which the native
    narrow phase takes as it is."""
    return compiled_frames(model)(q.tolist())


def frames_and_twists(model: RobotModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frames 0 (base) .. n in base, shape (n + 1, 4, 4), and the joints' unit twists
    ``[ω; v]`` in base, shape (6, n), at ``q`` (n,) (:func:`frame_values`).

    One generated function for all of them: a numpy chain of 4x4 products costs its call
    overhead per frame.
    """
    n = model.dof
    values = frame_values(model, q)
    # fromiter with a count: np.array infers the type of each of the ~170 floats (4x the time).
    values = np.fromiter(values, float, len(values))
    return values[: 16 * (n + 1)].reshape(n + 1, 4, 4), values[16 * (n + 1) :].reshape(6, n)


def world_poses(frames: np.ndarray, frame_of_shape: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Poses in base of shapes on model frames.

    Args:
        frames: :func:`model_frames`, shape (n + 1, 4, 4).
        frame_of_shape: model frame index of each shape, shape (G,).
        offsets: pose of each shape in its frame, shape (G, 4, 4).

    Returns:
        shape (G, 4, 4).
    """
    return np.matmul(frames[frame_of_shape], offsets)


def sphere_centres(poses: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Bounding-sphere centres in base of shapes at ``poses`` (G, 4, 4), centres (G, 3) in their frames: (G, 3)."""
    return (poses[:, :3, :3] @ centres[:, :, None])[:, :, 0] + poses[:, :3, 3]


def sphere_gaps(centres_a: np.ndarray, centres_b: np.ndarray, radius_sums: np.ndarray) -> np.ndarray:
    """Distance between bounding spheres, row by row: a lower bound on the shapes' distance, shape (P,) [m].

    Args:
        centres_a, centres_b: sphere centres, shape (P, 3) [m].
        radius_sums: the two radii added, shape (P,) [m].
    """
    difference = centres_a - centres_b
    return np.sqrt((difference * difference).sum(axis=1)) - radius_sums


#: Stands in for an unbounded prismatic travel in :func:`joint_reach` (an inf would make 0 · inf = nan).
_FAR = 1e12


def joint_reach(model: RobotModel, frames: np.ndarray, offsets: np.ndarray, centres: np.ndarray, radii: np.ndarray):
    """How far a point of each shape's bounding sphere can move per unit of each joint's motion, shape (n, G).

    Entry (j, g) bounds ``|∂x/∂q_j|`` over every configuration for every point ``x`` of shape
    g's bounding sphere: 1 [m/m] for a prismatic joint, and for a revolute one the largest
    possible distance from the joint's origin to ``x`` [m/rad]: the lengths of the links between
    (each fixed, a prismatic joint's travel added), the shape's offset and its radius. 0 where
    joint j does not move the shape. So a shape moves by at most ``Σ_j |Δq_j| · reach[j, g]``
    between two configurations, whatever the path.

    Args:
        frames: model frame of each shape, shape (G,).
        offsets: pose of each shape in its frame, shape (G, 4, 4).
        centres: bounding-sphere centres in the shapes' frames, shape (G, 3) [m].
        radii: bounding-sphere radii, shape (G,) [m].
    """
    chain, n = model.chain, model.dof
    travel = np.minimum(np.maximum(np.abs(model.lower), np.abs(model.upper)), _FAR) * chain.prismatic_mask
    # |o_i - o_{i-1}|, at most: from joint i-1's origin to joint i's.
    segments = np.linalg.norm(chain.fixed[:, :3, 3], axis=1) + travel
    centre_offsets = np.linalg.norm((offsets[:, :3, :3] @ centres[:, :, None])[:, :, 0] + offsets[:, :3, 3], axis=1)
    reach = np.zeros((n, len(frames)))
    for g, frame in enumerate(np.asarray(frames).tolist()):
        if frame == 0:
            continue
        tail = float(np.linalg.norm(chain.frame_offsets[frame - 1][:3, 3]) + centre_offsets[g] + radii[g])
        for j in range(frame):
            reach[j, g] = 1.0 if chain.prismatic_mask[j] else min(float(segments[j + 1 : frame].sum()) + tail, _FAR)
    return reach
