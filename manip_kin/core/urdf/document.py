"""A URDF document read into a kinematic tree: links, joints, parent/child maps, chain walks.

:class:`UrdfTree` parses the XML and checks every field it reads; each error is a
:class:`~manip_kin.errors.ModelFileError` naming the source (a path, a topic) and the field
(``joint[panda_joint3]/origin@xyz``). :mod:`manip_kin.core.urdf.chain` turns a chain of it into
a model.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from manip_kin.core.robot_files import MAX_MAGNITUDE, parse_xml
from manip_kin.core.rotations import transform_from_xyz_rpy
from manip_kin.errors import ModelFileError, bounded_repr

#: Element written by :func:`manip_kin.core.urdf.model_to_urdf` naming its chain (``tip_link``,
#: ``tool_link``); the default chain when a reader is given no link names.
CHAIN_HINT_ELEMENT = "manip_kin_chain"

# URDF joint types that move along the chain.
MOVABLE_TYPES = ("revolute", "continuous", "prismatic")
URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` element, parsed; numbers in [m], [rad], [m/s], [rad/s]."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray  # (4, 4), child frame in parent frame at zero position
    axis: np.ndarray  # (3,), unit
    limit: dict[str, float]  # the <limit> attributes that are present
    has_mimic: bool


#: Name parts that make a leaf movable joint a gripper joint, left out of the default chain.
GRIPPER_NAME_PARTS = ("gripper", "finger", "jaw", "claw")


def is_gripper_joint(joint: UrdfJoint) -> bool:
    """True when the joint's or its child link's name contains a :data:`GRIPPER_NAME_PARTS` word."""
    names = f"{joint.name} {joint.child}".lower()
    return any(part in names for part in GRIPPER_NAME_PARTS)


class UrdfTree:
    """Parses one URDF document; every error names the source and the field."""

    def __init__(self, xml_text: str | bytes, source: str):
        self.source = source
        self.root = parse_xml(xml_text, source)  # bounded size, depth and element count
        if self.root.tag != "robot":
            raise self.fail("robot", f"the root element is <{self.root.tag}>; a URDF starts with <robot>")
        self.links = self._read_links()
        self._link_set = frozenset(self.links)
        self.joints = [self._read_joint(element, i) for i, element in enumerate(self.root.findall("joint"))]
        self.parent_joint: dict[str, UrdfJoint] = {}
        self.child_joints: dict[str, list[UrdfJoint]] = {name: [] for name in self.links}
        self._link_joints()
        self._check_acyclic()
        self._movable_below: dict[str, bool] = {}
        hint = self.root.find(CHAIN_HINT_ELEMENT)
        self.chain_hint = {} if hint is None else {k: v for k, v in hint.attrib.items() if v in self._link_set}

    def fail(self, field: str, problem: str) -> ModelFileError:
        return ModelFileError(self.source, field, problem)

    # --- elements

    def _read_links(self) -> list[str]:
        names: dict[str, None] = {}  # ordered, and a linear-time membership test
        for index, element in enumerate(self.root.findall("link")):
            name = element.get("name", "").strip()
            if not name:
                raise self.fail(f"link[#{index + 1}]@name", "missing; every <link> needs a name")
            if name in names:
                raise self.fail(f"link[{name[:80]}]@name", "two <link> elements have this name")
            names[name] = None
        return list(names)

    def _read_joint(self, element: ET.Element, index: int) -> UrdfJoint:
        name = element.get("name", "").strip()
        if not name:
            raise self.fail(f"joint[#{index + 1}]@name", "missing; every <joint> needs a name")
        where = f"joint[{name}]"
        joint_type = element.get("type", "").strip()
        if joint_type not in URDF_JOINT_TYPES:
            raise self.fail(f"{where}@type", f"{joint_type!r}; valid: {', '.join(URDF_JOINT_TYPES)}")
        origin = self.origin(element, where)
        axis = np.array([1.0, 0.0, 0.0])  # the URDF default axis is x, not z
        axis_element = element.find("axis")
        if axis_element is not None:
            axis = self.numbers(axis_element, "xyz", f"{where}/axis@xyz", default=(1.0, 0.0, 0.0))
            norm = float(np.linalg.norm(axis))  # components are capped: no overflow
            if norm < 1e-12 and joint_type in MOVABLE_TYPES:
                raise self.fail(f"{where}/axis@xyz", "has zero length; valid: a non-zero direction")
            axis = axis / norm if norm >= 1e-12 else np.array([1.0, 0.0, 0.0])
        limit: dict[str, float] = {}
        limit_element = element.find("limit")
        if limit_element is not None:
            for attribute in ("lower", "upper", "velocity", "effort"):
                if limit_element.get(attribute) is not None:
                    field = f"{where}/limit@{attribute}"
                    value = self._number(limit_element.get(attribute), field, allow_infinite=True)
                    # URDFs write ±1e16 for "no limit": beyond the cap a limit is infinite.
                    limit[attribute] = value if abs(value) <= MAX_MAGNITUDE else math.copysign(math.inf, value)
        return UrdfJoint(
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
        if name not in self._link_set:
            raise self.fail(f"{where}/{tag}@link", f"{bounded_repr(name)} is not a <link> of this robot")
        return name

    def origin(self, element: ET.Element, where: str) -> np.ndarray:
        """The transform of ``element``'s ``<origin xyz rpy>`` child (identity without one), shape (4, 4)."""
        origin_element = element.find("origin")
        if origin_element is None:
            return np.eye(4)
        xyz = self.numbers(origin_element, "xyz", f"{where}/origin@xyz", default=(0.0, 0.0, 0.0))
        rpy = self.numbers(origin_element, "rpy", f"{where}/origin@rpy", default=(0.0, 0.0, 0.0))
        return transform_from_xyz_rpy(xyz, rpy)

    def numbers(self, element: ET.Element, attribute: str, field: str, default) -> np.ndarray:
        """The whitespace-separated finite numbers of ``element@attribute`` (``default`` when absent)."""
        text = element.get(attribute)
        if text is None:
            return np.array(default, dtype=float)
        parts = text.split()
        if len(parts) != len(default):
            raise self.fail(field, f"{text!r} has {len(parts)} values; valid: {len(default)} numbers")
        return np.array([self._number(part, field, allow_infinite=False, whole=text) for part in parts])

    def _number(self, text: str, field: str, allow_infinite: bool, whole: str | None = None) -> float:
        shown = bounded_repr(whole if whole is not None else text)
        try:
            value = float(text)
        except ValueError:
            hint = "; run xacro on the file first" if "$" in (whole or text) else ""
            raise self.fail(field, f"{shown} is not numeric{hint}") from None
        if math.isnan(value) or (math.isinf(value) and not allow_infinite):
            raise self.fail(field, f"{shown} is not a finite number")
        if not allow_infinite and abs(value) > MAX_MAGNITUDE:
            raise self.fail(field, f"{shown} is out of range; valid: |value| <= {MAX_MAGNITUDE:g} (m, rad, axis)")
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
            if joint.child == joint.parent:
                raise self.fail(
                    f"joint[{joint.name}]/child@link",
                    f"link {joint.child!r} is both parent and child of this joint; URDF is a tree",
                )
            self.parent_joint[joint.child] = joint
            self.child_joints[joint.parent].append(joint)

    def _check_acyclic(self) -> None:
        """Every link below a root link: a link that is not lies on a cycle of joints."""
        reached = set()
        pending = [name for name in self.links if name not in self.parent_joint]
        while pending:
            link = pending.pop()
            reached.add(link)
            pending.extend(joint.child for joint in self.child_joints[link])
        for name in self.links:
            if name not in reached:
                joint = self.parent_joint[name]
                raise self.fail(
                    f"joint[{joint.name}]/child@link",
                    f"link {name!r} lies on a cycle of joints (it is its own ancestor); URDF is a tree",
                )

    def root_link(self) -> str:
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            problem = f"several root links: {roots}" if roots else "every link has a parent joint (a cycle)"
            raise self.fail("base_link", f"{problem}; name the base link explicitly")
        return roots[0]

    def check_link(self, name: str, field: str) -> str:
        if name not in self._link_set:
            shown = ", ".join(self.links[:20]) + (f" ... ({len(self.links)} links)" if len(self.links) > 20 else "")
            raise self.fail(field, f"unknown link {bounded_repr(name)}; links: {shown}")
        return name

    def _leads_to_movable(self, joint: UrdfJoint) -> bool:
        """True when ``joint`` or a joint below it is not fixed (memoised: linear over the tree)."""
        known = self._movable_below
        if joint.name not in known:
            # Post-order over the subtree without recursion; the tree is acyclic (checked).
            pending = [(joint, False)]
            while pending:
                current, expanded = pending.pop()
                if current.name in known:
                    continue
                children = self.child_joints[current.child]
                if expanded or current.type != "fixed" or not children:
                    below = any(known[child.name] for child in children) if expanded else False
                    known[current.name] = current.type != "fixed" or below
                    continue
                pending.append((current, True))
                pending.extend((child, False) for child in children if child.name not in known)
        return known[joint.name]

    def _walk_unbranched(self, link: str) -> tuple[str, list[UrdfJoint]]:
        """From ``link``, follow the only child joint (the only one leading on to a movable
        joint where there are several); returns the link where that stops and the joints
        leading on from it (several: a branch; none: the end)."""
        visited = {link}
        while True:
            children = self.child_joints[link]
            if len(children) != 1:
                children = [joint for joint in children if self._leads_to_movable(joint)]
            if len(children) != 1:
                return link, children
            link = children[0].child
            if link in visited:  # unreachable for a tree; guards a malformed file
                raise self.fail("tip_link", f"the joints below {link!r} form a cycle")
            visited.add(link)

    def default_tip(self, base: str) -> str:
        """The last link of the unbranched chain below ``base`` (see :mod:`manip_kin.core.urdf`).

        Raises:
            ModelFileError: the tree branches into several movable chains before any movable
                joint (two arms on one base, a mobile base with an arm and a head...): the
                message lists the end of each branch as a candidate ``tip_link``.
        """
        tip, branches = self._walk_unbranched(base)
        if len(branches) > 1 and not any(joint.type != "fixed" for joint in self.chain(base, tip, "tip_link")):
            candidates = [self._walk_unbranched(joint.child)[0] for joint in branches]
            raise self.fail(
                "tip_link",
                f"the tree below {base!r} branches at {tip!r} into several movable chains, so there is no "
                f"default tip; set the tip link (node parameter tip_link, CLI --tip-link) to one of "
                f"{', '.join(repr(c) for c in candidates)} or a link below one of them",
            )
        return self._without_gripper(base, tip)

    def _without_gripper(self, base: str, tip: str) -> str:
        """``tip``, or the parent link of the trailing gripper joints of the chain (see :mod:`manip_kin.core.urdf`).

        A gripper joint is a movable joint named (joint or child link) like a gripper or finger,
        with nothing movable below it: a leaf of the tree, as the Unitree Z1's ``jointGripper``.
        At least one movable joint stays.
        """
        while True:
            movable = [joint for joint in self.chain(base, tip, "tip_link") if joint.type != "fixed"]
            last = movable[-1] if movable else None
            if last is None or len(movable) < 2 or not is_gripper_joint(last):
                return tip
            if any(self._leads_to_movable(child) for child in self.child_joints[last.child]):
                return tip
            tip = last.parent

    def chain(self, base: str, tip: str, field: str) -> list[UrdfJoint]:
        """The joints from ``base`` down to ``tip``, base first."""
        joints: list[UrdfJoint] = []
        link = tip
        while link != base:
            joint = self.parent_joint.get(link)
            if joint is None or len(joints) > len(self.joints):
                raise self.fail(field, f"link {tip!r} is not below link {base!r}")
            joints.append(joint)
            link = joint.parent
        return joints[::-1]
