"""URDF in and out: load a serial chain from a URDF, write a model as a URDF for RViz.

Loading (:func:`load_urdf`, :func:`load_urdf_string`) walks the kinematic tree from a
base link to a tip link and turns it into a :class:`~manip_kin.model.RobotModel`:

* ``revolute`` and ``continuous`` joints become revolute joints (continuous ones get
  infinite position limits), ``prismatic`` joints stay prismatic;
* ``fixed`` joints are folded into the origin of the next movable joint, and the fixed
  joints after the last movable joint become the model's ``ee_offset``;
* ``floating`` and ``planar`` joints and ``<mimic>`` joints on the chain are rejected
  with a :class:`~manip_kin.errors.ModelFileError` naming the joint;
* each model joint reports the frame of its URDF child link (``link_name``), so
  ``frame_pose(model, q, "panda_link4")`` works;
* an optional ``tool_link`` below the tip (fixed joints only) becomes the model's ``tool``.

Default tip link: starting at the root, follow the only child joint of each link. When a
link has several child joints, follow the only one whose subtree holds a movable joint
(decorative fixed branches such as the UR ``base`` frame are skipped); stop where no
child, or more than one child, leads on to a movable joint. For the Franka Panda of
example-robot-data this stops at ``panda_hand``, where the two finger joints branch off,
so the model is the 7-DoF arm with ``ee`` at the hand flange (no fingers, no TCP). For
the Panda TCP and the UR5 tool flange, name the tip::

    from manip_kin.urdf import example_robot_data_urdf, load_urdf

    panda = load_urdf(example_robot_data_urdf("panda_description/urdf/panda.urdf"),
                      tip_link="panda_hand_tcp")
    ur5 = load_urdf(example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf"),
                    base_link="base_link", tip_link="tool0")

Writing (:func:`model_to_urdf`) produces a URDF with simple visuals (a cylinder per link
segment, a sphere per joint) that ``robot_state_publisher``, RViz and Foxglove can draw;
:func:`load_urdf_string` reads it back to the same kinematics (see its docstring).
"""

from __future__ import annotations

import math
import site
import sysconfig
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manip_kin.errors import ModelFileError
from manip_kin.model import Joint, JointType, RobotModel
from manip_kin.rotations import rotation_z_onto, transform_from_xyz_rpy

__all__ = [
    "example_robot_data_urdf",
    "load_urdf",
    "load_urdf_string",
    "model_to_urdf",
]

# URDF joint types that move along the chain, and what they become in the model.
_MOVABLE_TYPES = {
    "revolute": JointType.REVOLUTE,
    "continuous": JointType.REVOLUTE,
    "prismatic": JointType.PRISMATIC,
}
_URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")

# A continuous joint may omit <limit>; the model still needs a positive speed limit.
DEFAULT_CONTINUOUS_VELOCITY = 2.0  # [rad/s]

# The model has no effort limits, but URDF requires the attribute on <limit>.
EXPORT_EFFORT = 100.0  # [N·m] or [N]
# URDF has no infinite limits except "continuous"; ROS parsers reject "inf".
EXPORT_INFINITE_LIMIT = 1.0e6  # [rad] or [m]

_EXAMPLE_ROBOT_DATA_ROBOTS = Path("cmeel.prefix") / "share" / "example-robot-data" / "robots"


# --- locating example-robot-data -------------------------------------------------------------


def _site_package_dirs() -> list[Path]:
    """Every site-packages directory of this interpreter, without duplicates, in search order."""
    candidates = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    try:
        candidates += site.getsitepackages()
    except AttributeError:  # some virtualenv versions ship a site.py without it
        pass
    if site.ENABLE_USER_SITE:
        candidates.append(site.getusersitepackages())
    unique: list[Path] = []
    for candidate in candidates:
        path = Path(candidate)
        if path not in unique:
            unique.append(path)
    return unique


def example_robot_data_urdf(relative_path: str | Path) -> Path:
    """Path of a URDF shipped by the ``example-robot-data`` PyPI package.

    Args:
        relative_path: path below the package's ``robots/`` directory, e.g.
            ``"panda_description/urdf/panda.urdf"`` or ``"ur_description/urdf/ur5_robot.urdf"``.

    Returns:
        The absolute path of the existing file.

    Raises:
        FileNotFoundError: the package is not installed, or it has no such file.
    """
    searched = [directory / _EXAMPLE_ROBOT_DATA_ROBOTS for directory in _site_package_dirs()]
    installed = [robots for robots in searched if robots.is_dir()]
    if not installed:
        raise FileNotFoundError(
            "example-robot-data is not installed (no "
            f"{_EXAMPLE_ROBOT_DATA_ROBOTS} under {', '.join(str(d) for d in _site_package_dirs())}); "
            "install it with `pip install example-robot-data`"
        )
    for robots in installed:
        candidate = robots / relative_path
        if candidate.is_file():
            return candidate.resolve()
    raise FileNotFoundError(
        f"example-robot-data has no {relative_path}; looked in {', '.join(str(r) for r in installed)}"
    )


# --- parsing ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class _UrdfJoint:
    """One ``<joint>`` element, parsed; numbers in [m], [rad], [m/s], [rad/s]."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray  # (4, 4), child frame in parent frame at zero position
    axis: np.ndarray  # (3,), unit
    limit: dict[str, float]  # the <limit> attributes that are present
    has_mimic: bool


class _UrdfReader:
    """Parses one URDF document; every error names the source and the field."""

    def __init__(self, xml_text: str | bytes, source: str):
        self.source = source
        try:
            self.root = ET.fromstring(xml_text)
        except ET.ParseError as error:
            line, column = error.position  # expat counts columns from 0, editors from 1
            problem = f"malformed XML: {str(error).split(':')[0]}"
            raise ModelFileError(source, f"line {line}, column {column + 1}", problem) from None
        if self.root.tag != "robot":
            raise self.fail("robot", f"the root element is <{self.root.tag}>; a URDF starts with <robot>")
        self.links = self._read_links()
        self.joints = [self._read_joint(element, i) for i, element in enumerate(self.root.findall("joint"))]
        self.parent_joint: dict[str, _UrdfJoint] = {}
        self.child_joints: dict[str, list[_UrdfJoint]] = {name: [] for name in self.links}
        self._link_joints()

    def fail(self, field: str, problem: str) -> ModelFileError:
        return ModelFileError(self.source, field, problem)

    # --- elements

    def _read_links(self) -> list[str]:
        names: list[str] = []
        for index, element in enumerate(self.root.findall("link")):
            name = element.get("name", "").strip()
            if not name:
                raise self.fail(f"link[#{index + 1}]@name", "missing; every <link> needs a name")
            if name in names:
                raise self.fail(f"link[{name}]@name", "two <link> elements have this name")
            names.append(name)
        return names

    def _read_joint(self, element: ET.Element, index: int) -> _UrdfJoint:
        name = element.get("name", "").strip()
        if not name:
            raise self.fail(f"joint[#{index + 1}]@name", "missing; every <joint> needs a name")
        where = f"joint[{name}]"
        joint_type = element.get("type", "").strip()
        if joint_type not in _URDF_JOINT_TYPES:
            raise self.fail(f"{where}@type", f"{joint_type!r}; valid: {', '.join(_URDF_JOINT_TYPES)}")
        origin = np.eye(4)
        origin_element = element.find("origin")
        if origin_element is not None:
            xyz = self._numbers(origin_element, "xyz", f"{where}/origin@xyz", default=(0.0, 0.0, 0.0))
            rpy = self._numbers(origin_element, "rpy", f"{where}/origin@rpy", default=(0.0, 0.0, 0.0))
            origin = transform_from_xyz_rpy(xyz, rpy)
        axis = np.array([1.0, 0.0, 0.0])  # the URDF default axis is x, not z
        axis_element = element.find("axis")
        if axis_element is not None:
            axis = self._numbers(axis_element, "xyz", f"{where}/axis@xyz", default=(1.0, 0.0, 0.0))
            norm = float(np.linalg.norm(axis))
            if norm < 1e-12 and joint_type in _MOVABLE_TYPES:
                raise self.fail(f"{where}/axis@xyz", "has zero length; valid: a non-zero direction")
            axis = axis / norm if norm >= 1e-12 else np.array([1.0, 0.0, 0.0])
        limit: dict[str, float] = {}
        limit_element = element.find("limit")
        if limit_element is not None:
            for attribute in ("lower", "upper", "velocity", "effort"):
                if limit_element.get(attribute) is not None:
                    field = f"{where}/limit@{attribute}"
                    limit[attribute] = self._number(limit_element.get(attribute), field, allow_infinite=True)
        return _UrdfJoint(
            name=name,
            type=joint_type,
            parent=self._link_reference(element, "parent", where),
            child=self._link_reference(element, "child", where),
            origin=origin,
            axis=axis,
            limit=limit,
            has_mimic=element.find("mimic") is not None,
        )

    def _link_reference(self, element: ET.Element, tag: str, where: str) -> str:
        reference = element.find(tag)
        name = "" if reference is None else reference.get("link", "").strip()
        if not name:
            raise self.fail(f"{where}/{tag}@link", f'missing; a joint needs <{tag} link="..."/>')
        if name not in self.links:
            raise self.fail(f"{where}/{tag}@link", f"{name!r} is not a <link> of this robot")
        return name

    def _numbers(self, element: ET.Element, attribute: str, field: str, default) -> np.ndarray:
        text = element.get(attribute)
        if text is None:
            return np.array(default, dtype=float)
        parts = text.split()
        if len(parts) != len(default):
            raise self.fail(field, f"{text!r} has {len(parts)} values; valid: {len(default)} numbers")
        return np.array([self._number(part, field, allow_infinite=False, whole=text) for part in parts])

    def _number(self, text: str, field: str, allow_infinite: bool, whole: str | None = None) -> float:
        shown = repr(whole if whole is not None else text)
        try:
            value = float(text)
        except ValueError:
            hint = "; run xacro on the file first" if "$" in (whole or text) else ""
            raise self.fail(field, f"{shown} is not numeric{hint}") from None
        if math.isnan(value) or (math.isinf(value) and not allow_infinite):
            raise self.fail(field, f"{shown} is not a finite number")
        return value

    # --- tree

    def _link_joints(self) -> None:
        names = set()
        for joint in self.joints:
            if joint.name in names:
                raise self.fail(f"joint[{joint.name}]@name", "two <joint> elements have this name")
            names.add(joint.name)
            if joint.child in self.parent_joint:
                other = self.parent_joint[joint.child].name
                raise self.fail(
                    f"joint[{joint.name}]/child@link",
                    f"link {joint.child!r} is already the child of joint {other!r}; URDF is a tree",
                )
            self.parent_joint[joint.child] = joint
            self.child_joints[joint.parent].append(joint)

    def root_link(self) -> str:
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            problem = f"several root links: {roots}" if roots else "every link has a parent joint (a cycle)"
            raise self.fail("base_link", f"{problem}; name the base link explicitly")
        return roots[0]

    def check_link(self, name: str, field: str) -> str:
        if name not in self.links:
            raise self.fail(field, f"unknown link {name!r}; links: {', '.join(self.links)}")
        return name

    def _leads_to_movable(self, joint: _UrdfJoint) -> bool:
        """True when ``joint`` or a joint below it is not fixed."""
        pending, seen = [joint], set()
        while pending:
            current = pending.pop()
            if current.type != "fixed":
                return True
            if current.name not in seen:  # a malformed file may hold a cycle
                seen.add(current.name)
                pending.extend(self.child_joints[current.child])
        return False

    def default_tip(self, base: str) -> str:
        """The last link of the unbranched chain below ``base`` (see the module docstring)."""
        link = base
        visited = {link}
        while True:
            children = self.child_joints[link]
            if len(children) != 1:
                children = [joint for joint in children if self._leads_to_movable(joint)]
            if len(children) != 1:
                return link
            link = children[0].child
            if link in visited:  # unreachable for a tree; guards a malformed file
                raise self.fail("tip_link", f"the joints below {base!r} form a cycle")
            visited.add(link)

    def chain(self, base: str, tip: str, field: str) -> list[_UrdfJoint]:
        """The joints from ``base`` down to ``tip``, base first."""
        joints: list[_UrdfJoint] = []
        link = tip
        while link != base:
            joint = self.parent_joint.get(link)
            if joint is None or len(joints) > len(self.joints):
                raise self.fail(field, f"link {tip!r} is not below link {base!r}")
            joints.append(joint)
            link = joint.parent
        return joints[::-1]


# --- building the model ------------------------------------------------------------------------


def _model_joint(reader: _UrdfReader, joint: _UrdfJoint, origin: np.ndarray) -> Joint:
    """A model joint from a movable URDF joint, with ``origin`` already including folded fixed joints."""
    where = f"joint[{joint.name}]"
    if joint.has_mimic:
        raise reader.fail(f"{where}/mimic", "mimic joints are not supported in the chain; choose a tip link before it")
    limit = joint.limit
    if joint.type == "continuous":
        lower, upper = -math.inf, math.inf
        velocity = limit.get("velocity", DEFAULT_CONTINUOUS_VELOCITY)
    else:
        if "velocity" not in limit:
            problem = f"missing; a {joint.type} joint needs <limit velocity=...>"
            raise reader.fail(f"{where}/limit@velocity", problem)
        # The URDF spec makes lower and upper optional with default 0.
        lower, upper, velocity = limit.get("lower", 0.0), limit.get("upper", 0.0), limit["velocity"]
        if lower > upper:
            raise reader.fail(f"{where}/limit", f"lower {lower} > upper {upper}")
    if not (velocity > 0 and math.isfinite(velocity)):
        raise reader.fail(f"{where}/limit@velocity", f"{velocity}; valid: a positive finite speed")
    return Joint(
        name=joint.name,
        type=_MOVABLE_TYPES[joint.type],
        origin=origin,
        axis=joint.axis.copy(),
        lower=lower,
        upper=upper,
        velocity_limit=velocity,
        link_name=joint.child,
    )


def _fixed_transform(reader: _UrdfReader, joints: Iterable[_UrdfJoint], field: str) -> np.ndarray:
    """Product of the origins of fixed joints; any other joint type is an error."""
    transform = np.eye(4)
    for joint in joints:
        if joint.type != "fixed":
            problem = f"joint {joint.name!r} between tip and tool is {joint.type}; valid: fixed"
            raise reader.fail(field, problem)
        transform = transform @ joint.origin
    return transform


def _build_model(
    reader: _UrdfReader,
    base_link: str | None,
    tip_link: str | None,
    tool_link: str | None,
    name: str | None,
) -> RobotModel:
    base = reader.check_link(base_link, "base_link") if base_link else reader.root_link()
    tip = reader.check_link(tip_link, "tip_link") if tip_link else reader.default_tip(base)
    joints: list[Joint] = []
    pending = np.eye(4)  # fixed joints seen since the last movable joint
    for joint in reader.chain(base, tip, "tip_link"):
        if joint.type == "fixed":
            pending = pending @ joint.origin
        elif joint.type in _MOVABLE_TYPES:
            joints.append(_model_joint(reader, joint, pending @ joint.origin))
            pending = np.eye(4)
        else:
            raise reader.fail(
                f"joint[{joint.name}]@type",
                f"{joint.type} joints are not supported in a serial chain (between {base!r} and {tip!r})",
            )
    if not joints:
        raise reader.fail("tip_link", f"no movable joint between base link {base!r} and tip link {tip!r}")
    tool = None
    if tool_link:
        reader.check_link(tool_link, "tool_link")
        tool = _fixed_transform(reader, reader.chain(tip, tool_link, "tool_link"), "tool_link")
    return RobotModel(
        name=name or reader.root.get("name") or Path(reader.source).stem,
        joints=tuple(joints),
        ee_offset=pending,
        tool=tool,
        base_frame=base,
        source=reader.source,
    )


def load_urdf_string(
    xml_text: str | bytes,
    source: str = "robot_description",
    base_link: str | None = None,
    tip_link: str | None = None,
    name: str | None = None,
    tool_link: str | None = None,
) -> RobotModel:
    """Build a serial-chain model from URDF text.

    Args:
        xml_text: the URDF document (xacro already expanded).
        source: what the text is, for error messages (a path, a topic name).
        base_link: first link of the chain; default: the root link of the tree.
        tip_link: last link of the chain, whose frame becomes ``ee``; default: where the
            unbranched chain below the base ends (see the module docstring).
        name: model name; default: the ``<robot name>``.
        tool_link: optional link below ``tip_link``, joined to it by fixed joints only,
            whose frame becomes the model's ``tool``.

    Returns:
        The model; its ``base_frame`` is the base link name and each joint's
        ``link_name`` is its URDF child link.

    Raises:
        ModelFileError: malformed XML, unknown links, a tip not below the base, a
            non-numeric attribute, or a floating/planar/mimic joint on the chain; the
            message names ``source`` and the field, e.g. ``joint[panda_joint3]/origin@xyz``.

    A URDF written by :func:`model_to_urdf` reads back with
    ``load_urdf_string(text, tip_link="ee", tool_link="tool" if model.has_tool else None)``
    to a model with the same joints, end effector and tool.
    """
    reader = _UrdfReader(xml_text, source)
    return _build_model(reader, base_link, tip_link, tool_link, name)


def load_urdf(
    path: str | Path,
    base_link: str | None = None,
    tip_link: str | None = None,
    name: str | None = None,
    tool_link: str | None = None,
) -> RobotModel:
    """Build a serial-chain model from a URDF file; see :func:`load_urdf_string`.

    Errors name ``path`` as the source.
    """
    path = Path(path)
    try:
        text = path.read_bytes()
    except OSError as error:
        raise ModelFileError(str(path), "<file>", f"cannot read: {error.strerror}") from None
    return _build_model(_UrdfReader(text, str(path)), base_link, tip_link, tool_link, name)


# --- writing ---------------------------------------------------------------------------------

_LINK_RADIUS = 0.02  # [m] cylinder drawn along each link segment
_JOINT_RADIUS = 0.035  # [m] sphere drawn at each joint
_FRAME_RADIUS = 0.015  # [m] sphere drawn at the end effector and tool
_MATERIALS = {"manip_kin_link": "0.75 0.75 0.78 1", "manip_kin_joint": "0.95 0.55 0.1 1"}


def _urdf_rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] with ``rpy_to_matrix(roll, pitch, yaw)`` equal to ``rotation`` to rounding.

    Yaw is taken first and roll and pitch are then solved in the yaw-removed matrix
    (M. Day, "Extracting Euler angles from a rotation matrix"), which stays exact
    right up to gimbal lock; :func:`manip_kin.rotations.matrix_to_rpy` switches to a
    yaw = 0 formula below cos(pitch) = 1e-9 and is off by up to 1e-9 just inside it.
    """
    r = np.asarray(rotation, dtype=float)
    yaw = math.atan2(r[1, 0], r[0, 0])
    cy, sy = math.cos(yaw), math.sin(yaw)
    pitch = math.atan2(-r[2, 0], cy * r[0, 0] + sy * r[1, 0])
    roll = math.atan2(sy * r[0, 2] - cy * r[1, 2], cy * r[1, 1] - sy * r[0, 1])
    return roll, pitch, yaw


def _format(values: Iterable[float]) -> str:
    # repr keeps all 17 significant digits so a round trip is exact to rounding.
    return " ".join(repr(float(value) + 0.0) for value in values)


def _origin_element(parent: ET.Element, transform: np.ndarray) -> None:
    ET.SubElement(
        parent,
        "origin",
        xyz=_format(transform[:3, 3]),
        rpy=_format(_urdf_rpy(transform[:3, :3])),
    )


def _add_visual(link: ET.Element, transform: np.ndarray, shape: str, material: str, **size: float) -> None:
    visual = ET.SubElement(link, "visual")
    _origin_element(visual, transform)
    geometry = ET.SubElement(visual, "geometry")
    ET.SubElement(geometry, shape, **{key: _format([value]) for key, value in size.items()})
    ET.SubElement(visual, "material", name=material)


def _add_segment(link: ET.Element, end: np.ndarray) -> None:
    """A cylinder in ``link`` from its origin to the point ``end`` [m] (link frame); none if too short."""
    length = float(np.linalg.norm(end))
    if length < 1e-6:
        return
    pose = np.eye(4)
    pose[:3, :3] = rotation_z_onto(end / length)
    pose[:3, 3] = end / 2.0  # a URDF cylinder is centred on its origin, along its z axis
    _add_visual(link, pose, "cylinder", "manip_kin_link", radius=_LINK_RADIUS, length=length)


class _UniqueNames:
    """Hands out names, suffixing ``_2``, ``_3``… when one is already taken."""

    def __init__(self, reserved: Iterable[str] = ()):
        self.taken = set(reserved)

    def claim(self, wanted: str) -> str:
        name, count = wanted, 1
        while name in self.taken:
            count += 1
            name = f"{wanted}_{count}"
        self.taken.add(name)
        return name


def _limit_text(value: float) -> float:
    return float(np.clip(value, -EXPORT_INFINITE_LIMIT, EXPORT_INFINITE_LIMIT))


def _add_joint(
    robot: ET.Element, name: str, joint_type: str, parent: str, child: str, origin: np.ndarray
) -> ET.Element:
    element = ET.SubElement(robot, "joint", name=name, type=joint_type)
    _origin_element(element, origin)
    ET.SubElement(element, "parent", link=parent)
    ET.SubElement(element, "child", link=child)
    return element


def _add_movable_joint(robot: ET.Element, joint: Joint, parent: str, child: str) -> None:
    continuous = joint.is_revolute and math.isinf(joint.lower) and math.isinf(joint.upper)
    joint_type = "continuous" if continuous else joint.type.value
    element = _add_joint(robot, joint.name, joint_type, parent, child, joint.origin)
    axis = np.asarray(joint.axis, dtype=float)
    ET.SubElement(element, "axis", xyz=_format(axis / np.linalg.norm(axis)))
    limits = {"effort": _format([EXPORT_EFFORT]), "velocity": _format([joint.velocity_limit])}
    if not continuous:
        limits["lower"] = _format([_limit_text(joint.lower)])
        limits["upper"] = _format([_limit_text(joint.upper)])
    ET.SubElement(element, "limit", **limits)


def model_to_urdf(model: RobotModel) -> str:
    """A URDF document describing ``model``, with simple visuals, for RViz and Foxglove.

    Links: ``model.base_frame``; per joint ``joint.link_name`` (``link{i}`` when empty),
    at the model's frame ``i``; ``ee``; and ``tool`` when the model has one. Joints: the
    model's joints under their own names (so JointState messages match), plus fixed
    joints ``ee_joint``, ``tool_joint`` and, for a joint whose ``child_offset`` is not
    the identity (DH models), ``<joint>_offset`` from an intermediate link
    ``<link>_joint_frame`` (the moving joint frame) to the link at frame ``i``. Names
    already taken get a ``_2``… suffix.

    Visuals: a cylinder (radius 0.02 m) from each link's origin to the origin of each of
    its children (drawn in the parent, so it does not move with the child's joint), a
    sphere at every movable joint and a small one at ``ee`` and ``tool``.

    URDF cannot say everything a model can: effort limits are written as
    ``EXPORT_EFFORT``; infinite limits other than a fully continuous revolute joint are
    clipped to ``±EXPORT_INFINITE_LIMIT``; ``initial_positions`` is dropped. Read back with
    ``load_urdf_string(text, tip_link="ee", tool_link="tool" if model.has_tool else None)``
    the joints, ``ee`` and ``tool`` poses are the same for every configuration; joint
    frames of DH joints come back as the moving joint frame (``<link>_joint_frame``),
    since URDF places a link on its joint axis.

    Returns:
        The URDF text, with an XML declaration.
    """
    robot = ET.Element("robot", name=model.name or "robot")
    for material, rgba in _MATERIALS.items():
        ET.SubElement(ET.SubElement(robot, "material", name=material), "color", rgba=rgba)
    link_names = _UniqueNames()
    joint_names = _UniqueNames(model.joint_names)
    # ee and tool first: a reader relies on those two names (tip_link="ee").
    ee_name = link_names.claim("ee")
    tool_name = link_names.claim("tool") if model.has_tool else None
    base = link_names.claim(model.base_frame or "base_link")

    links: dict[str, ET.Element] = {}

    def new_link(name: str) -> ET.Element:
        links[name] = ET.SubElement(robot, "link", name=name)
        return links[name]

    def fixed_child(parent: str, child: str, joint_name: str, transform: np.ndarray) -> ET.Element:
        link = new_link(child)
        _add_joint(robot, joint_names.claim(joint_name), "fixed", parent, child, transform)
        _add_segment(links[parent], transform[:3, 3])
        return link

    new_link(base)
    parent = base
    for index, joint in enumerate(model.joints, start=1):
        frame_link = link_names.claim(joint.link_name or f"link{index}")
        has_offset = not np.allclose(joint.child_offset, np.eye(4), rtol=0.0, atol=1e-15)
        moving_link = link_names.claim(f"{frame_link}_joint_frame") if has_offset else frame_link
        _add_visual(new_link(moving_link), np.eye(4), "sphere", "manip_kin_joint", radius=_JOINT_RADIUS)
        _add_movable_joint(robot, joint, parent, moving_link)
        _add_segment(links[parent], np.asarray(joint.origin, dtype=float)[:3, 3])
        if has_offset:
            offset = np.asarray(joint.child_offset, dtype=float)
            fixed_child(moving_link, frame_link, f"{joint.name}_offset", offset)
        parent = frame_link
    ee_link = fixed_child(parent, ee_name, "ee_joint", np.asarray(model.ee_offset, dtype=float))
    _add_visual(ee_link, np.eye(4), "sphere", "manip_kin_joint", radius=_FRAME_RADIUS)
    if tool_name is not None:
        tool_link = fixed_child(ee_name, tool_name, "tool_joint", np.asarray(model.tool, dtype=float))
        _add_visual(tool_link, np.eye(4), "sphere", "manip_kin_joint", radius=_FRAME_RADIUS)
    ET.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"
