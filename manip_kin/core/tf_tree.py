"""Every link's transform from a URDF and a joint state, as robot_state_publisher computes them.

ROS-free: a :class:`LinkTree` is read once from URDF text (the ``robot_description``);
:func:`moving_transforms` then gives one parent → child transform per movable joint
whose position is known, :func:`static_transforms` one per fixed joint. Frame ids are
the URDF link names, optionally prefixed (``frame_prefix``, as robot_state_publisher's
parameter). :func:`compose` chains transforms into link poses in the root link.

Like robot_state_publisher: ``revolute`` and ``continuous`` joints rotate about their
axis, ``prismatic`` ones slide along it, ``<mimic>`` joints follow their leader
(``multiplier * q + offset``); ``floating`` and ``planar`` joints get no transform (a
joint state cannot say where they are). Joint names the tree does not know are
ignored, and a movable joint without a position is left out of that message.

:class:`StampDecimator` is the one rule that picks which joint states become ``/tf``
(at most ``rate_hz``, by stamp): the live ``robot_state`` and the recorder's synthesis
use it, so a recording's synthesised ``/tf`` has the stamps the live one would have.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from manip_kin.core.rotations import angle_axis_to_matrix, matrix_to_quat, quat_to_matrix
from manip_kin.core.urdf.document import MOVABLE_TYPES, UrdfTree
from manip_kin.errors import InvalidArgumentError, ModelFileError


@dataclass(frozen=True)
class TreeJoint:
    """One URDF joint as TF needs it.

    Attributes:
        name: joint name (the ``name`` entry of a JointState).
        type: URDF joint type.
        parent, child: link names (frame ids before the prefix).
        origin: child frame in the parent frame at zero position, shape (4, 4).
        axis: unit axis in the joint frame, shape (3,).
        mimic: ``(leader joint, multiplier, offset)`` for a ``<mimic>`` joint, else None.
    """

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    mimic: tuple[str, float, float] | None = None

    def motion(self, position: float) -> np.ndarray:
        """Parent → child transform at ``position`` [rad | m], shape (4, 4)."""
        transform = np.array(self.origin, dtype=float)
        if self.type == "prismatic":
            transform[:3, 3] += transform[:3, :3] @ (self.axis * position)
        elif self.type in ("revolute", "continuous"):
            transform[:3, :3] = transform[:3, :3] @ angle_axis_to_matrix(position, self.axis)
        return transform


@dataclass(frozen=True)
class LinkTransform:
    """One stamped-to-be transform: ``child`` expressed in ``parent``.

    Attributes:
        parent, child: frame ids (prefix applied).
        translation: [m], shape (3,).
        rotation_xyzw: unit quaternion ``(x, y, z, w)``, shape (4,).
    """

    parent: str
    child: str
    translation: np.ndarray
    rotation_xyzw: np.ndarray

    @classmethod
    def from_matrix(cls, parent: str, child: str, matrix: np.ndarray) -> LinkTransform:
        """From a 4x4 transform."""
        return cls(parent, child, np.array(matrix[:3, 3], dtype=float), matrix_to_quat(matrix[:3, :3]))

    def matrix(self) -> np.ndarray:
        """The 4x4 transform."""
        transform = np.eye(4)
        transform[:3, :3] = quat_to_matrix(self.rotation_xyzw)
        transform[:3, 3] = self.translation
        return transform


@dataclass(frozen=True)
class LinkTree:
    """The joints of a URDF tree, split into movable and fixed ones.

    Attributes:
        root: the root link (the frame everything composes to).
        movable: revolute, continuous and prismatic joints, file order.
        fixed: fixed joints, file order.
        unsupported: names of floating/planar joints (no transform published).
        links: every link name.
    """

    root: str
    movable: tuple[TreeJoint, ...]
    fixed: tuple[TreeJoint, ...]
    unsupported: tuple[str, ...]
    links: tuple[str, ...]

    @classmethod
    def from_urdf(cls, urdf_text: str | bytes, source: str = "robot_description") -> LinkTree:
        """Read a URDF document (errors name ``source`` and the field, see :mod:`manip_kin.core.urdf`)."""
        reader = UrdfTree(urdf_text, source)
        mimics = _mimics(reader, source)
        movable, fixed, unsupported = [], [], []
        for joint in reader.joints:
            tree_joint = TreeJoint(
                joint.name, joint.type, joint.parent, joint.child, joint.origin, joint.axis, mimics.get(joint.name)
            )
            if joint.type in MOVABLE_TYPES:
                movable.append(tree_joint)
            elif joint.type == "fixed":
                fixed.append(tree_joint)
            else:
                unsupported.append(joint.name)
        return cls(reader.root_link(), tuple(movable), tuple(fixed), tuple(unsupported), tuple(reader.links))

    @property
    def movable_names(self) -> tuple[str, ...]:
        """Names of the movable joints."""
        return tuple(j.name for j in self.movable)


def _mimics(reader: UrdfTree, source: str) -> dict[str, tuple[str, float, float]]:
    found = {}
    for element in reader.root.findall("joint"):
        mimic = element.find("mimic")
        if mimic is None:
            continue
        name = element.get("name", "").strip()
        where = f"joint[{name}]/mimic"
        try:
            found[name] = (
                mimic.get("joint", "").strip(),
                float(mimic.get("multiplier", "1")),
                float(mimic.get("offset", "0")),
            )
        except ValueError:
            raise ModelFileError(source, where, "multiplier and offset must be numbers") from None
    return found


def _frame(prefix: str, link: str) -> str:
    return f"{prefix}{link}" if prefix else link


def static_transforms(tree: LinkTree, frame_prefix: str = "") -> list[LinkTransform]:
    """One transform per fixed joint (``/tf_static``)."""
    return [
        LinkTransform.from_matrix(_frame(frame_prefix, j.parent), _frame(frame_prefix, j.child), j.origin)
        for j in tree.fixed
    ]


def joint_positions(names: Iterable[str], positions: Iterable[float]) -> dict[str, float]:
    """``{name: position}`` from a JointState's parallel lists (finite values only)."""
    return {n: float(p) for n, p in zip(names, positions, strict=False) if math.isfinite(float(p))}


def moving_transforms(tree: LinkTree, positions: Mapping[str, float], frame_prefix: str = "") -> list[LinkTransform]:
    """One transform per movable joint with a known position (``/tf``).

    Args:
        tree: the URDF's joints.
        positions: ``{joint name: position [rad | m]}``; unknown names are ignored.
        frame_prefix: prepended to every frame id.
    """
    result = []
    for joint in tree.movable:
        if joint.mimic is not None:
            leader, multiplier, offset = joint.mimic
            if leader not in positions:
                continue
            position = multiplier * positions[leader] + offset
        elif joint.name in positions:
            position = positions[joint.name]
        else:
            continue
        result.append(
            LinkTransform.from_matrix(
                _frame(frame_prefix, joint.parent), _frame(frame_prefix, joint.child), joint.motion(position)
            )
        )
    return result


def compose(transforms: Iterable[LinkTransform], root: str) -> dict[str, np.ndarray]:
    """Pose of every frame reachable from ``root`` in ``root``, as a TF listener would chain them.

    Returns:
        ``{frame id: 4x4 pose in root}``, ``root`` included (identity).
    """
    children: dict[str, list[LinkTransform]] = {}
    for transform in transforms:
        children.setdefault(transform.parent, []).append(transform)
    poses = {root: np.eye(4)}
    pending = [root]
    while pending:
        parent = pending.pop()
        for transform in children.get(parent, ()):
            if transform.child not in poses:
                poses[transform.child] = poses[parent] @ transform.matrix()
                pending.append(transform.child)
    return poses


class StampDecimator:
    """Picks stamps at most ``rate_hz`` apart: the first one, then each at least a period after the last taken.

    Args:
        rate_hz: the highest rate [Hz], > 0.
    """

    def __init__(self, rate_hz: float):
        if not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise InvalidArgumentError(f"TF rate {rate_hz!r} Hz; valid: a positive finite rate")
        self.period_ns = int(round(1e9 / rate_hz))
        self._last_ns: int | None = None

    def due(self, stamp_ns: int) -> bool:
        """True (and remembered) when ``stamp_ns`` should be published."""
        last = self._last_ns
        if last is not None and last <= stamp_ns < last + self.period_ns:
            return False  # a stamp before the last one (a restart) starts over
        self._last_ns = stamp_ns
        return True
