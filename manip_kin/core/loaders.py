"""Robot models from YAML: a joint list, a standard DH table, or product-of-exponentials screws.

A robot YAML file is a mapping with ``name`` and exactly one of ``joints``, ``dh``, ``poe``
or ``urdf``. Common optional fields: ``units`` (``m`` or ``mm``) or ``scale`` (a factor
applied to every length, prismatic limits and speeds included), ``base_frame``,
``tool`` and ``ee_offset`` (poses), ``initial_positions``. Angles are radians; a scalar
may also be written ``pi``, ``-pi/2``, ``0.5 pi``, ``3*pi/4`` or ``165 deg``.

A pose is ``{xyz: [x, y, z]}`` plus one of ``rpy: [roll, pitch, yaw]``,
``ypr: [yaw, pitch, roll]``, ``quat_xyzw: [x, y, z, w]`` or ``rotation: [[r00, r01, r02], ...]``.

Joint list (the "fixed frame, then move about z" convention, or URDF-like axes)::

    joints:
      - name: j1
        type: revolute            # or prismatic
        origin: {xyz: [0, 0, 0.105], rotation: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}
        axis: [0, 0, 1]           # default z
        limits: {lower: -pi, upper: pi, velocity: 2.0}

DH table (standard, ``A = Rz(θ) Tz(d) Tx(a) Rx(α)``); rows without ``joint`` are fixed::

    dh:
      - {d: 0.4, theta: 0, a: 0, alpha: pi/2}
      - {joint: theta, name: theta1, d: 0, theta: 0, a: 0.3, alpha: 0, limits: {...}}
      - {joint: d, name: d2, d: 0.2, theta: pi/2, a: 0, alpha: pi/2, limits: {...}}

Product of exponentials (space-frame screws ``[ω; v]``, home pose ``M`` of the end effector)::

    poe:
      home: {xyz: [1.0, 0, 0]}
      screws:
        - {name: j1, screw: [0, 0, 1, 0, 0, 0], limits: {...}}

URDF reference: ``urdf: {file: arm.urdf, base_link: ..., tip_link: ...}`` (path relative
to the YAML file).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from manip_kin.core.model import Joint, JointType, RobotModel
from manip_kin.core.model_fields import FieldReader
from manip_kin.core.robot_files import MAX_MAGNITUDE, parse_yaml, read_robot_file, robot_file_kind
from manip_kin.core.rotations import (
    make_transform,
    rot_x,
    rot_z,
)
from manip_kin.errors import ModelFileError, bounded_repr

DESCRIPTION_KEYS = ("joints", "dh", "poe", "urdf")
TOP_LEVEL_KEYS = frozenset(
    DESCRIPTION_KEYS + ("name", "description", "units", "scale", "base_frame", "tool", "ee_offset", "initial_positions")
)


def _joints_from_list(reader: FieldReader, entries: list) -> tuple[list[Joint], np.ndarray]:
    joints = []
    for index, raw in enumerate(reader.sequence(entries, "joints")):
        field = f"joints[{index}]"
        entry = reader.mapping(raw, field)
        name = str(entry.get("name", f"joint{index + 1}"))
        field = f"joints[{name}]"
        joint_type = reader.joint_type(entry.get("type", "revolute"), f"{field}.type")
        axis = reader.vector(entry.get("axis", [0.0, 0.0, 1.0]), f"{field}.axis", 3)
        if np.linalg.norm(axis) < 1e-9:
            raise reader.fail(f"{field}.axis", "zero-length axis")
        joints.append(
            Joint(
                name=name,
                type=joint_type,
                origin=reader.pose(entry.get("origin", {}), f"{field}.origin"),
                axis=axis / np.linalg.norm(axis),
                link_name=str(entry.get("link", f"link{index + 1}")),
                **reader.limits(entry.get("limits"), f"{field}.limits", joint_type),
            )
        )
    return joints, np.eye(4)


def _dh_transform(d: float, theta: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH ``Rz(θ) Tz(d) Tx(a) Rx(α)``."""
    transform = make_transform(rot_z(theta), [0.0, 0.0, d])
    return transform @ make_transform(rot_x(alpha), [a, 0.0, 0.0])


def _joints_from_dh(reader: FieldReader, rows: list) -> tuple[list[Joint], np.ndarray]:
    joints: list[Joint] = []
    pending = np.eye(4)  # fixed rows not yet attached to a joint
    for index, raw in enumerate(reader.sequence(rows, "dh")):
        field = f"dh[{index}]"
        row = reader.mapping(raw, field)
        missing = [k for k in ("d", "theta", "a", "alpha") if k not in row]
        if missing:
            raise reader.fail(f"{field}.{missing[0]}", "missing; every DH row has d, theta, a, alpha")
        d = reader.length(row["d"], f"{field}.d")
        theta = reader.scalar(row["theta"], f"{field}.theta")
        a = reader.length(row["a"], f"{field}.a")
        alpha = reader.scalar(row["alpha"], f"{field}.alpha")
        variable = row.get("joint")
        if variable is None:
            pending = pending @ _dh_transform(d, theta, a, alpha)
            continue
        if variable not in ("theta", "d"):
            raise reader.fail(f"{field}.joint", f"{bounded_repr(variable)}; valid: theta (revolute) or d (prismatic)")
        joint_type = JointType.REVOLUTE if variable == "theta" else JointType.PRISMATIC
        name = str(row.get("name", f"joint{len(joints) + 1}"))
        # Rz(θ0 + q)… = Rz(q)·Rz(θ0)…, and Tz(d0 + q) commutes with Rz(θ): the motion comes
        # first, about/along the previous frame's z, then the row's fixed part.
        joints.append(
            Joint(
                name=name,
                type=joint_type,
                origin=pending,
                child_offset=_dh_transform(d, theta, a, alpha),
                link_name=str(row.get("link", f"link{len(joints) + 1}")),
                **reader.limits(row.get("limits"), f"{field}.limits", joint_type),
            )
        )
        pending = np.eye(4)
    if not joints:
        raise reader.fail("dh", "no row has a joint (joint: theta or joint: d)")
    return joints, pending


def _joints_from_poe(reader: FieldReader, description: Any) -> tuple[list[Joint], np.ndarray]:
    poe = reader.mapping(description, "poe")
    if "home" not in poe:
        raise reader.fail("poe.home", "missing; the end-effector pose at q = 0 is required")
    home = reader.pose(poe["home"], "poe.home")
    joints: list[Joint] = []
    previous_frame = np.eye(4)
    for index, raw in enumerate(reader.sequence(poe.get("screws"), "poe.screws")):
        entry = reader.mapping(raw, f"poe.screws[{index}]")
        name = str(entry.get("name", f"joint{index + 1}"))
        field = f"poe.screws[{name}]"
        screw = reader.vector(entry.get("screw"), f"{field}.screw", 6)
        omega, v = screw[:3], screw[3:] * reader.scale
        for i, component in enumerate(v, start=3):
            reader.bounded(float(component), f"{field}.screw[{i}]")
        if np.linalg.norm(omega) > 1e-9:
            if abs(np.linalg.norm(omega) - 1.0) > 1e-6:
                raise reader.fail(f"{field}.screw", f"|ω| = {np.linalg.norm(omega):.6g}; valid: 1 (revolute) or 0")
            joint_type = JointType.REVOLUTE
            axis = omega
            point = np.cross(omega, v)  # the point on the axis closest to the base origin
        else:
            if np.linalg.norm(v) < 1e-9:
                raise reader.fail(f"{field}.screw", "zero screw")
            joint_type = JointType.PRISMATIC
            axis = v / np.linalg.norm(v)
            point = previous_frame[:3, 3]
        # Joint frame at q = 0: at a point of the screw axis, aligned with the base.
        frame = make_transform(np.eye(3), point)
        joints.append(
            Joint(
                name=name,
                type=joint_type,
                origin=np.linalg.inv(previous_frame) @ frame,
                axis=axis,
                link_name=str(entry.get("link", f"link{index + 1}")),
                **reader.limits(entry.get("limits"), f"{field}.limits", joint_type),
            )
        )
        previous_frame = frame
    return joints, np.linalg.inv(previous_frame) @ home


def model_from_dict(description: Any, source: str, base_dir: Path | None = None) -> RobotModel:
    """Build a :class:`RobotModel` from parsed YAML (see the module docstring).

    Args:
        description: the parsed YAML mapping.
        source: file name (or other origin) used in error messages.
        base_dir: directory that relative ``urdf.file`` paths are relative to.
    """
    reader = FieldReader(source)
    data = reader.mapping(description, "<top level>")
    unknown = sorted(set(map(str, data)) - TOP_LEVEL_KEYS)
    if unknown:
        raise reader.fail(unknown[0], f"unknown key; valid: {', '.join(sorted(TOP_LEVEL_KEYS))}")
    present = [key for key in DESCRIPTION_KEYS if key in data]
    if len(present) != 1:
        raise reader.fail(
            "<top level>",
            f"found {present or 'none'} of {', '.join(DESCRIPTION_KEYS)}; exactly one describes the chain",
        )
    units = str(data.get("units", "m")).strip().lower()
    if units not in ("m", "mm"):
        raise reader.fail("units", f"{bounded_repr(units)}; valid: m, mm")
    reader.scale = reader.scalar(data.get("scale", 0.001 if units == "mm" else 1.0), "scale")
    if not reader.scale > 1.0 / MAX_MAGNITUDE:
        raise reader.fail("scale", f"{reader.scale}; valid: a factor > {1.0 / MAX_MAGNITUDE:g}")

    kind = present[0]
    if kind == "urdf":
        return _model_from_urdf_reference(reader, data, base_dir)
    if kind == "joints":
        joints, chain_end = _joints_from_list(reader, data["joints"])
    elif kind == "dh":
        joints, chain_end = _joints_from_dh(reader, data["dh"])
    else:
        joints, chain_end = _joints_from_poe(reader, data["poe"])
    ee_offset = chain_end @ reader.pose(data.get("ee_offset", {}), "ee_offset")
    tool = reader.pose(data["tool"], "tool") if data.get("tool") is not None else None
    initial = data.get("initial_positions")
    if initial is not None:
        initial = reader.vector(initial, "initial_positions", len(joints))
    return RobotModel(
        name=str(data.get("name", Path(source).stem)),
        joints=tuple(joints),
        ee_offset=ee_offset,
        tool=tool,
        base_frame=str(data.get("base_frame", "base_link")),
        initial_positions=initial,
        source=source,
    )


def _model_from_urdf_reference(reader: FieldReader, data: dict, base_dir: Path | None) -> RobotModel:
    from manip_kin.core.urdf import load_urdf

    reference = reader.mapping(data["urdf"], "urdf")
    if "file" not in reference:
        raise reader.fail("urdf.file", "missing; the path of the URDF file")
    path = Path(str(reference["file"]))
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    if not path.is_file():
        raise reader.fail("urdf.file", f"{path} does not exist")
    return load_urdf(
        path,
        base_link=reference.get("base_link"),
        tip_link=reference.get("tip_link"),
        name=str(data.get("name", path.stem)),
    )


def load_robot_yaml(path: str | Path) -> RobotModel:
    """Load a robot YAML file; errors name the file and the field (caps: :mod:`manip_kin.core.robot_files`)."""
    path = Path(path)
    data = read_robot_file(path)
    if robot_file_kind(data) == "urdf":
        raise ModelFileError(str(path), "<file>", "this is XML, not a robot YAML; load it as a URDF")
    return model_from_dict(parse_yaml(data, str(path)), str(path), path.parent)
