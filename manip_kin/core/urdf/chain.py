"""A chain of a URDF tree as a :class:`~manip_kin.core.model.RobotModel` (:func:`load_urdf`, :func:`load_urdf_string`).

See :mod:`manip_kin.core.urdf` for the rules: fixed joints folded, default tip, tool link, and a
missing or zero velocity limit read as "no limit given" (an infinite velocity limit).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from manip_kin.core.model import Joint, JointType, RobotModel
from manip_kin.core.robot_files import read_robot_file
from manip_kin.core.urdf.document import MOVABLE_TYPES, UrdfJoint, UrdfTree

# What the movable URDF joint types become in the model.
_MODEL_JOINT_TYPES = {
    "revolute": JointType.REVOLUTE,
    "continuous": JointType.REVOLUTE,
    "prismatic": JointType.PRISMATIC,
}


def joints_without_velocity_limit(model: RobotModel) -> list[str]:
    """Names of the joints whose URDF gave no velocity limit (missing or zero): limit ``inf``."""
    return [joint.name for joint in model.joints if math.isinf(joint.velocity_limit)]


def _model_joint(reader: UrdfTree, joint: UrdfJoint, origin: np.ndarray) -> Joint:
    """A model joint from a movable URDF joint, with ``origin`` already including folded fixed joints."""
    where = f"joint[{joint.name}]"
    if joint.has_mimic:
        raise reader.fail(f"{where}/mimic", "mimic joints are not supported in the chain; choose a tip link before it")
    limit = joint.limit
    if joint.type == "continuous":
        lower, upper = -math.inf, math.inf
    else:
        # The URDF spec makes lower and upper optional with default 0.
        lower, upper = limit.get("lower", 0.0), limit.get("upper", 0.0)
        if lower > upper:
            raise reader.fail(f"{where}/limit", f"lower {lower} > upper {upper}")
    # Many published URDFs leave the velocity out or write 0 for "not specified": no limit.
    velocity = limit.get("velocity", 0.0)
    if not velocity >= 0:
        raise reader.fail(f"{where}/limit@velocity", f"{velocity}; valid: a speed >= 0 (0: no limit given)")
    if velocity == 0:
        velocity = math.inf
    return Joint(
        name=joint.name,
        type=_MODEL_JOINT_TYPES[joint.type],
        origin=origin,
        axis=joint.axis.copy(),
        lower=lower,
        upper=upper,
        velocity_limit=velocity,
        link_name=joint.child,
    )


def _fixed_transform(reader: UrdfTree, joints: Iterable[UrdfJoint], field: str) -> np.ndarray:
    """Product of the origins of fixed joints; any other joint type is an error."""
    transform = np.eye(4)
    for joint in joints:
        if joint.type != "fixed":
            problem = f"joint {joint.name!r} between tip and tool is {joint.type}; valid: fixed"
            raise reader.fail(field, problem)
        transform = transform @ joint.origin
    return transform


def _build_model(
    reader: UrdfTree,
    base_link: str | None,
    tip_link: str | None,
    tool_link: str | None,
    name: str | None,
) -> RobotModel:
    if not (base_link or tip_link or tool_link) and "tip_link" in reader.chain_hint:
        # A manip_kin export names its own chain (ee and tool, see model_to_urdf).
        tip_link, tool_link = reader.chain_hint["tip_link"], reader.chain_hint.get("tool_link")
    base = reader.check_link(base_link, "base_link") if base_link else reader.root_link()
    tip = reader.check_link(tip_link, "tip_link") if tip_link else reader.default_tip(base)
    joints: list[Joint] = []
    pending = np.eye(4)  # fixed joints seen since the last movable joint
    for joint in reader.chain(base, tip, "tip_link"):
        if joint.type == "fixed":
            pending = pending @ joint.origin
        elif joint.type in MOVABLE_TYPES:
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
    reader = UrdfTree(xml_text, source)
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
    text = read_robot_file(path)
    return _build_model(UrdfTree(text, str(path)), base_link, tip_link, tool_link, name)
