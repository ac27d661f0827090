"""A model as a URDF with simple visuals, for robot_state_publisher, RViz and Foxglove (:func:`model_to_urdf`)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from xml.sax.saxutils import quoteattr

import numpy as np

from manip_kin.core.model import Joint, RobotModel
from manip_kin.core.rotations import rotation_z_onto
from manip_kin.core.urdf.document import CHAIN_HINT_ELEMENT

# The model has no effort limits, but URDF requires the attribute on <limit>.
EXPORT_EFFORT = 100.0  # [N·m] or [N]
# URDF has no infinite limits except "continuous"; ROS parsers reject "inf".
EXPORT_INFINITE_LIMIT = 1.0e6  # [rad] or [m]

_LINK_RADIUS = 0.02  # [m] cylinder drawn along each link segment
_JOINT_RADIUS = 0.035  # [m] sphere drawn at each joint
_FRAME_RADIUS = 0.015  # [m] sphere drawn at the end effector and tool
_MATERIALS = {"manip_kin_link": "0.75 0.75 0.78 1", "manip_kin_joint": "0.95 0.55 0.1 1"}


def _urdf_rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] with ``rpy_to_matrix(roll, pitch, yaw)`` equal to ``rotation`` to rounding.

    Yaw is taken first and roll and pitch are then solved in the yaw-removed matrix
    (M. Day, "Extracting Euler angles from a rotation matrix"), which stays exact
    right up to gimbal lock; :func:`manip_kin.core.rotations.matrix_to_rpy` switches to a
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
    # No velocity limit is written as 0, as many URDFs do (and as the reader takes it back).
    velocity = 0.0 if math.isinf(joint.velocity_limit) else joint.velocity_limit
    limits = {"effort": _format([EXPORT_EFFORT]), "velocity": _format([velocity])}
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

    A ``<manip_kin_chain tip_link="ee" tool_link="tool"/>`` element names the chain, so that
    :func:`~manip_kin.core.urdf.load_urdf_string` without link names reads back the same ``ee``
    and ``tool`` (other URDF readers ignore it).

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
    # Which chain this is, for a reader that gets no link names (a controller reading
    # robot_description): URDF parsers ignore elements they do not know.
    hint = {"tip_link": ee_name, **({"tool_link": tool_name} if tool_name is not None else {})}
    ET.SubElement(robot, CHAIN_HINT_ELEMENT, **hint)
    ET.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def with_chain_hint(urdf_text: str, tip_link: str, tool_link: str | None = None) -> str:
    """``urdf_text`` unchanged but for one element naming its chain (what :func:`model_to_urdf` writes),
    so a reader given no link names (a controller reading ``robot_description``) takes this chain."""
    attributes = f" tip_link={quoteattr(tip_link)}" + (f" tool_link={quoteattr(tool_link)}" if tool_link else "")
    end = urdf_text.rfind("</robot>")
    if end < 0:
        return urdf_text
    return f"{urdf_text[:end]}  <{CHAIN_HINT_ELEMENT}{attributes}/>\n{urdf_text[end:]}"
