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

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from manip_kin.core.model import Joint, JointType, RobotModel
from manip_kin.core.robot_files import MAX_MAGNITUDE, parse_yaml, read_robot_file, robot_file_kind
from manip_kin.core.rotations import (
    check_rotation,
    make_transform,
    quat_to_matrix,
    rot_x,
    rot_z,
    rpy_to_matrix,
)
from manip_kin.errors import ModelFileError, NotARotationError, bounded_repr

DESCRIPTION_KEYS = ("joints", "dh", "poe", "urdf")
TOP_LEVEL_KEYS = frozenset(
    DESCRIPTION_KEYS + ("name", "description", "units", "scale", "base_frame", "tool", "ee_offset", "initial_positions")
)
_PI_EXPRESSION = re.compile(
    r"^\s*(?P<sign>[+-])?\s*(?P<coef>\d+(\.\d*)?|\.\d+)?\s*\*?\s*pi\s*(/\s*(?P<den>\d+(\.\d*)?))?\s*$"
)
_DEGREES = re.compile(r"^\s*(?P<value>[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?)\s*(deg|degrees|°)\s*$")


class _Reader:
    """Reads typed values out of parsed YAML, naming the file and field on any mistake.

    Numbers of geometry (lengths after ``scale``, angles, axis and screw components) must be
    finite and at most :data:`~manip_kin.core.robot_files.MAX_MAGNITUDE`; limits may be ``inf``
    (no limit), and a limit beyond that magnitude means no limit, as URDFs write ±1e16.
    """

    def __init__(self, source: str, scale: float = 1.0):
        self.source = source
        self.scale = scale

    def fail(self, field: str, problem: str) -> ModelFileError:
        return ModelFileError(self.source, field, problem)

    def scalar(self, value: Any, field: str, limit: bool = False) -> float:
        """A number; ``limit``: ±inf allowed, and a magnitude beyond the cap read as ±inf."""
        if isinstance(value, bool):
            raise self.fail(field, f"{value!r} is not a number")
        if isinstance(value, (int, float)):
            try:
                number = float(value)
            except OverflowError:
                number = math.inf if value > 0 else -math.inf
        elif isinstance(value, str):
            number = self._parse_expression(value, field)
        else:
            raise self.fail(field, f"{bounded_repr(value)} is not a number (valid: 0.5, pi/2, 165 deg)")
        if math.isnan(number):
            raise self.fail(field, "NaN is not a valid value")
        if limit:
            return number if abs(number) <= MAX_MAGNITUDE else math.copysign(math.inf, number)
        return self.bounded(number, field)

    def bounded(self, number: float, field: str) -> float:
        """``number`` unless it is infinite or larger in magnitude than the cap."""
        if not abs(number) <= MAX_MAGNITUDE:
            raise self.fail(
                field, f"{number:g} is out of range; valid: finite, |value| <= {MAX_MAGNITUDE:g} (m, rad, axis)"
            )
        return number

    def _parse_expression(self, text: str, field: str) -> float:
        lowered = text.strip().lower()
        try:
            return float(lowered)  # also "inf", "-inf" for continuous joints
        except ValueError:
            pass
        match = _PI_EXPRESSION.match(lowered)
        if match:
            coefficient = float(match["coef"]) if match["coef"] else 1.0
            denominator = float(match["den"]) if match["den"] else 1.0
            if denominator == 0:
                raise self.fail(field, f"{bounded_repr(text)} divides by zero; valid: pi/N with N > 0")
            sign = -1.0 if match["sign"] == "-" else 1.0
            return sign * coefficient * math.pi / denominator
        match = _DEGREES.match(lowered)
        if match:
            return math.radians(float(match["value"]))
        raise self.fail(field, f"{bounded_repr(text)} is not a number (valid: 0.5, pi/2, -3*pi/4, 165 deg)")

    def vector(self, value: Any, field: str, length: int) -> np.ndarray:
        if not isinstance(value, (list, tuple)) or len(value) != length:
            raise self.fail(field, f"{bounded_repr(value)} is not a list of {length} numbers")
        return np.array([self.scalar(v, f"{field}[{i}]") for i, v in enumerate(value)])

    def length_vector(self, value: Any, field: str) -> np.ndarray:
        lengths = self.vector(value, field, 3) * self.scale
        for i, length in enumerate(lengths):
            self.bounded(float(length), f"{field}[{i}]")
        return lengths

    def length(self, value: Any, field: str) -> float:
        return self.bounded(self.scalar(value, field) * self.scale, field)

    def mapping(self, value: Any, field: str) -> dict:
        if not isinstance(value, dict):
            raise self.fail(field, f"expected a mapping, got {type(value).__name__}")
        return value

    def sequence(self, value: Any, field: str) -> list:
        if not isinstance(value, list) or not value:
            raise self.fail(field, f"expected a non-empty list, got {bounded_repr(value)}")
        return value

    def pose(self, value: Any, field: str) -> np.ndarray:
        """A pose mapping as a 4x4 transform (see the module docstring)."""
        pose = self.mapping(value, field)
        known = {"xyz", "rpy", "ypr", "quat_xyzw", "rotation"}
        unknown = set(pose) - known
        if unknown:
            raise self.fail(f"{field}.{sorted(unknown)[0]}", f"unknown key; valid: {', '.join(sorted(known))}")
        rotation_keys = [k for k in ("rpy", "ypr", "quat_xyzw", "rotation") if k in pose]
        if len(rotation_keys) > 1:
            raise self.fail(field, f"give one of rpy, ypr, quat_xyzw, rotation, not {rotation_keys}")
        xyz = self.length_vector(pose.get("xyz", [0.0, 0.0, 0.0]), f"{field}.xyz")
        rotation = np.eye(3)
        if "rpy" in pose:
            rotation = rpy_to_matrix(*self.vector(pose["rpy"], f"{field}.rpy", 3))
        elif "ypr" in pose:
            yaw, pitch, roll = self.vector(pose["ypr"], f"{field}.ypr", 3)
            rotation = rpy_to_matrix(roll, pitch, yaw)
        elif "quat_xyzw" in pose:
            try:
                rotation = quat_to_matrix(self.vector(pose["quat_xyzw"], f"{field}.quat_xyzw", 4))
            except NotARotationError as error:
                raise self.fail(f"{field}.quat_xyzw", str(error)) from None
        elif "rotation" in pose:
            rows = pose["rotation"]
            if not isinstance(rows, list) or len(rows) != 3:
                raise self.fail(f"{field}.rotation", "expected 3 rows of 3 numbers")
            matrix = np.array([self.vector(r, f"{field}.rotation[{i}]", 3) for i, r in enumerate(rows)])
            try:
                rotation = check_rotation(matrix, "matrix", tolerance=1e-4)
            except NotARotationError as error:
                raise self.fail(f"{field}.rotation", str(error)) from None
            # Tables print rotations to a few digits: snap to the nearest exact rotation.
            u, _, vt = np.linalg.svd(rotation)
            rotation = u @ vt
        return make_transform(rotation, xyz)

    def joint_type(self, value: Any, field: str) -> JointType:
        try:
            return JointType(str(value).strip().lower())
        except ValueError:
            raise self.fail(field, f"{bounded_repr(value)} is not a joint type; valid: revolute, prismatic") from None

    def limits(self, value: Any, field: str, joint_type: JointType) -> dict[str, float]:
        """Joint limits; prismatic ones are lengths and get scaled."""
        scale = self.scale if joint_type is JointType.PRISMATIC else 1.0
        default_range = math.pi if joint_type is JointType.REVOLUTE else 1.0
        limits = self.mapping(value if value is not None else {}, field)
        unknown = set(limits) - {"lower", "upper", "velocity"}
        if unknown:
            raise self.fail(f"{field}.{sorted(unknown)[0]}", "unknown key; valid: lower, upper, velocity")
        lower = self.scalar(limits.get("lower", -default_range / scale), f"{field}.lower", limit=True) * scale
        upper = self.scalar(limits.get("upper", default_range / scale), f"{field}.upper", limit=True) * scale
        velocity = self.scalar(limits.get("velocity", 2.0 / scale), f"{field}.velocity", limit=True) * scale
        if lower == math.inf or upper == -math.inf:
            raise self.fail(f"{field}", f"lower {lower} and upper {upper}; valid: lower < +inf, upper > -inf")
        if lower > upper:
            raise self.fail(f"{field}", f"lower {lower} > upper {upper}")
        if not velocity > 0:
            raise self.fail(f"{field}.velocity", f"{velocity}; valid: a positive speed")
        return {"lower": lower, "upper": upper, "velocity_limit": velocity}


def _joints_from_list(reader: _Reader, entries: list) -> tuple[list[Joint], np.ndarray]:
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


def _joints_from_dh(reader: _Reader, rows: list) -> tuple[list[Joint], np.ndarray]:
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


def _joints_from_poe(reader: _Reader, description: Any) -> tuple[list[Joint], np.ndarray]:
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
    reader = _Reader(source)
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


def _model_from_urdf_reference(reader: _Reader, data: dict, base_dir: Path | None) -> RobotModel:
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
