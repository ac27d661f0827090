"""A robot model (and its URDF, where it came from one) as a MuJoCo model, built with MjSpec.

Bodies follow the robot:

* **From a URDF** every link below the base link becomes a body placed by its joint's
  origin; the chain's joints move, every other joint (the Panda's fingers) is welded at
  zero. Each link keeps its ``<inertial>`` and its ``<collision>`` shapes (meshes resolved
  by :func:`manip_kin.core.mesh_uris.resolve_mesh_uri`; a mesh that cannot be found or that MuJoCo
  cannot read, e.g. Collada, is left out and named in the notes). A URDF without any
  ``<inertial>`` gets the default links below; one whose moving link (with the links welded
  to it) has no mass while others have is an error naming that link.
* **From a robot YAML, DH table or PoE** (no inertials), or a URDF without any: each link is
  a capsule of radius :data:`DEFAULT_LINK_RADIUS` from its joint to the next joint (the last
  one to the end effector), of mass :data:`DEFAULT_LINEAR_DENSITY` per metre of that length
  and at least :data:`MIN_LINK_MASS`; the capsule is also its collision shape.
* A chain link left without any collision shape gets that capsule as its collision shape
  (without mass).

The arm's geoms collide with obstacles only (``contype`` 1, ``conaffinity`` 0 on the arm;
0 and 1 on obstacles): self-collision is the controller's business, not the plant's.
Obstacles of a :class:`~manip_kin.core.scene.Scene` are static geoms of the world body, named
``obstacle NS/ID``. One position servo per joint (:mod:`manip_kin.plant.servo`) is a general
actuator; its gains are set on the compiled model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.core.mesh_uris import resolve_mesh_uri
from manip_kin.core.model import RobotModel
from manip_kin.core.rotations import matrix_to_quat
from manip_kin.core.scene import Scene, ShapeKind
from manip_kin.errors import ModelFileError

#: Default link capsule radius [m] (robots without inertials).
DEFAULT_LINK_RADIUS = 0.04
#: Default link mass per metre of link length [kg/m].
DEFAULT_LINEAR_DENSITY = 4.0
#: Smallest default link mass [kg] (a wrist link between coincident joint frames).
MIN_LINK_MASS = 0.2
#: Mesh file types MuJoCo reads.
MESH_SUFFIXES = (".stl", ".obj", ".msh")

OBSTACLE_PREFIX = "obstacle "


@dataclass(frozen=True)
class JointDynamics:
    """Joint friction model, the same for every joint: ``damping`` [N·m·s/rad | N·s/m],
    ``armature`` (reflected rotor inertia) [kg·m² | kg], ``friction`` (dry friction loss) [N·m | N]."""

    damping: float = 0.0
    armature: float = 0.0
    friction: float = 0.0


@dataclass
class SpecSource:
    """What the MuJoCo model is built from.

    Attributes:
        model: the robot chain.
        urdf_text: the URDF the model came from, or None (YAML, DH, PoE).
        urdf_dir: directory of the URDF file (relative mesh paths), or None.
        mesh_search_path: ``:``-separated package directories (see :mod:`manip_kin.core.mesh_uris`).
        notes: what the build left out or assumed, one sentence each (filled by the build).
    """

    model: RobotModel
    urdf_text: str | None = None
    urdf_dir: str | None = None
    mesh_search_path: str = ""
    notes: list[str] = field(default_factory=list)


def _place(element, transform: np.ndarray) -> None:
    x, y, z, w = matrix_to_quat(transform[:3, :3]).tolist()
    element.pos = transform[:3, 3].tolist()
    element.quat = [w, x, y, z]


def _arm_geom(body, **kwargs):
    return body.add_geom(contype=1, conaffinity=0, **kwargs)


def _segments(model: RobotModel) -> list[np.ndarray]:
    """For joint i, the vector from its moving frame to the next joint's frame (the last: to the ee), in that frame."""
    ends = []
    for i, joint in enumerate(model.joints):
        nxt = model.joints[i + 1].origin if i + 1 < model.dof else model.ee_offset
        ends.append((joint.child_offset @ nxt)[:3, 3])
    return ends


def _default_link(mujoco, body, end: np.ndarray, with_mass: bool) -> None:
    length = float(np.linalg.norm(end))
    mass = max(DEFAULT_LINEAR_DENSITY * length, MIN_LINK_MASS) if with_mass else 0.0
    extra = {"mass": mass} if with_mass else {"density": 0.0}
    if length < 1e-6:
        _arm_geom(body, type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[DEFAULT_LINK_RADIUS, 0, 0], **extra)
    else:
        _arm_geom(
            body,
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[0.0, 0.0, 0.0, *end.tolist()],
            size=[DEFAULT_LINK_RADIUS, 0, 0],
            **extra,
        )


def _add_joint(mujoco, body, joint, dynamics: JointDynamics) -> None:
    limited = math.isfinite(joint.lower) and math.isfinite(joint.upper)
    body.add_joint(
        name=joint.name,
        type=mujoco.mjtJoint.mjJNT_HINGE if joint.is_revolute else mujoco.mjtJoint.mjJNT_SLIDE,
        axis=joint.axis.tolist(),
        range=[joint.lower, joint.upper] if limited else [0.0, 0.0],
        limited=mujoco.mjtLimited.mjLIMITED_TRUE if limited else mujoco.mjtLimited.mjLIMITED_FALSE,
        damping=dynamics.damping,
        armature=dynamics.armature,
        frictionloss=dynamics.friction,
    )


def _chain_bodies(mujoco, spec, model: RobotModel, dynamics: JointDynamics) -> None:
    parent, placement = spec.worldbody, np.eye(4)
    for joint, end in zip(model.joints, _segments(model)):
        body = parent.add_body(name=joint.link_name or joint.name)
        _place(body, placement @ joint.origin)
        _add_joint(mujoco, body, joint, dynamics)
        _default_link(mujoco, body, end, with_mass=True)
        parent, placement = body, joint.child_offset


def _mesh_geom(mujoco, spec, body, uri: str, scale, placement, source: SpecSource, what: str, **kwargs) -> bool:
    """A mesh geom at ``placement`` (4, 4) in ``body`` (mesh frame as in the file); False when left out."""
    path = resolve_mesh_uri(uri, source.mesh_search_path, source.urdf_dir)
    if path is None or path.suffix.lower() not in MESH_SUFFIXES:
        why = (
            "not found"
            if path is None
            else f"{path.suffix} is not a mesh type MuJoCo reads ({', '.join(MESH_SUFFIXES)})"
        )
        source.notes.append(f"{what}: mesh {uri} left out ({why}; set mesh_search_path)")
        return False
    name = f"mesh{len(spec.meshes)}"
    spec.add_mesh(name=name, file=str(path), scale=list(scale))
    _place(body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, **kwargs), placement)
    return True


def _collision_geoms(mujoco, spec, body, shapes, source: SpecSource, link: str) -> int:
    added = 0
    for shape in shapes:
        kwargs = {"contype": 1, "conaffinity": 0, "density": 0.0}
        if shape.kind == "mesh":
            uri, what = shape.mesh_uri, f"link {link}"
            added += _mesh_geom(mujoco, spec, body, uri, shape.size, shape.origin, source, what, **kwargs)
            continue
        if shape.kind == "box":
            geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.5 * s for s in shape.size], **kwargs)
        elif shape.kind == "cylinder":
            radius, length = shape.size
            geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[radius, 0.5 * length, 0], **kwargs)
        else:
            geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[shape.size[0], 0, 0], **kwargs)
        _place(geom, shape.origin)
        added += 1
    return added


def _urdf_bodies(mujoco, spec, source: SpecSource, dynamics: JointDynamics) -> None:
    from manip_kin.core.urdf.document import UrdfTree
    from manip_kin.plant.urdf_links import read_link_dynamics

    model = source.model
    reader = UrdfTree(source.urdf_text, model.source or "robot_description")
    links = read_link_dynamics(reader)
    chain = {joint.name: joint for joint in model.joints}
    segments = dict(zip(model.joint_names, _segments(model)))
    with_inertials = any(inertial is not None and inertial.mass > 0 for inertial in links.inertials.values())
    if not with_inertials:
        source.notes.append(
            f"the URDF has no <inertial>: default links ({DEFAULT_LINEAR_DENSITY:g} kg/m capsules, "
            f"radius {DEFAULT_LINK_RADIUS:g} m, at least {MIN_LINK_MASS:g} kg; see docs/physics.md)"
        )
    welded = [j.name for j in reader.joints if j.type != "fixed" and j.name not in chain]
    if welded:
        source.notes.append(f"joints outside the chain are welded at zero: {', '.join(welded)}")
    bodies = {model.base_frame: spec.worldbody}
    _collision_geoms(mujoco, spec, spec.worldbody, links.collisions.get(model.base_frame, ()), source, model.base_frame)
    subtree_mass: dict[str, list[float]] = {}  # moving link -> masses welded to it
    owner = {model.base_frame: None}
    pending = list(reader.child_joints[model.base_frame])
    while pending:
        urdf_joint = pending.pop(0)
        body = bodies[urdf_joint.parent].add_body(name=urdf_joint.child)
        _place(body, urdf_joint.origin)
        bodies[urdf_joint.child] = body
        moving = urdf_joint.name in chain
        owner[urdf_joint.child] = urdf_joint.child if moving else owner[urdf_joint.parent]
        if moving:
            _add_joint(mujoco, body, chain[urdf_joint.name], dynamics)
            subtree_mass[urdf_joint.child] = []
            if not with_inertials:
                _default_link(mujoco, body, segments[urdf_joint.name], with_mass=True)
        inertial = links.inertials.get(urdf_joint.child)
        if with_inertials and inertial is not None and inertial.mass > 0:
            body.mass = inertial.mass
            ipos_quat = inertial.origin
            x, y, z, w = matrix_to_quat(ipos_quat[:3, :3]).tolist()
            body.ipos, body.iquat = ipos_quat[:3, 3].tolist(), [w, x, y, z]
            ixx, iyy, izz, ixy, ixz, iyz = inertial.inertia
            body.fullinertia = [ixx, iyy, izz, ixy, ixz, iyz]
            body.explicitinertial = True
            if owner[urdf_joint.child] is not None:
                subtree_mass[owner[urdf_joint.child]].append(inertial.mass)
        shapes = links.collisions.get(urdf_joint.child, ())
        added = _collision_geoms(mujoco, spec, body, shapes, source, urdf_joint.child)
        if moving and not added and with_inertials:
            _default_link(mujoco, body, segments[urdf_joint.name], with_mass=False)
            source.notes.append(f"link {urdf_joint.child}: no usable collision shape, a default capsule instead")
        pending.extend(reader.child_joints[urdf_joint.child])
    for link, masses in subtree_mass.items():
        if with_inertials and not sum(masses):
            raise ModelFileError(
                reader.source,
                f"link[{link}]/inertial",
                "missing or zero mass on a moving link (and on every link welded to it); the mujoco plant needs "
                "one (add an <inertial>, or run robot_state with plant:=kinematic)",
            )


def build_spec(source: SpecSource, dynamics: JointDynamics, timestep: float):
    """The arm as an ``mujoco.MjSpec`` (no obstacles, no actuators yet).

    Raises:
        ModelFileError: a malformed ``<inertial>``/``<collision>`` field, or a moving link without mass.
    """
    import mujoco

    spec = mujoco.MjSpec()
    spec.modelname = source.model.name
    spec.compiler.degree = False
    spec.compiler.autolimits = False
    spec.option.timestep = timestep
    spec.option.integrator = (
        mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    )  # the servo's damping, implicitly: stable when stiff
    if source.urdf_text is not None:
        _urdf_bodies(mujoco, spec, source, dynamics)
    else:
        _chain_bodies(mujoco, spec, source.model, dynamics)
    for joint in source.model.joints:
        spec.add_actuator(
            name=f"servo {joint.name}",
            target=joint.name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            gaintype=mujoco.mjtGain.mjGAIN_FIXED,
            biastype=mujoco.mjtBias.mjBIAS_AFFINE,
        )
    return spec


def add_obstacles(spec, scene: Scene, source: SpecSource) -> None:
    """Each obstacle of ``scene`` as a static geom of the world body (named ``obstacle NS/ID``)."""
    import mujoco

    world = spec.worldbody
    for obstacle in scene.obstacles:
        name = f"{OBSTACLE_PREFIX}{obstacle.key[0]}/{obstacle.key[1]}"
        kwargs = {"name": name, "contype": 0, "conaffinity": 1, "rgba": [0.8, 0.3, 0.2, 0.6]}
        if obstacle.shape is ShapeKind.MESH:
            pose = obstacle.pose_in_base
            _mesh_geom(mujoco, spec, world, obstacle.mesh_uri, obstacle.scale, pose, source, name, **kwargs)
            continue
        if obstacle.shape is ShapeKind.BOX:
            geom = world.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=list(obstacle.half_extents), **kwargs)
        elif obstacle.shape is ShapeKind.SPHERE:
            geom = world.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[obstacle.radius, 0, 0], **kwargs)
        else:
            size = [obstacle.radius, 0.5 * obstacle.height, 0]
            geom = world.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=size, **kwargs)
        _place(geom, obstacle.pose_in_base)


def urdf_dir_of(model: RobotModel) -> str | None:
    """Directory of the model's URDF file (for relative mesh paths), None when it has none."""
    source = Path(model.source) if model.source else None
    return str(source.parent) if source is not None and source.is_file() else None
