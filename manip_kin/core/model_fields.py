"""Typed values out of a parsed robot YAML file (see :mod:`manip_kin.core.loaders` for the format).

Scalars may be numbers or ``pi`` expressions (``-pi/2``, ``0.5 pi``, ``3*pi/4``) or degrees
(``165 deg``); lengths get the file's ``scale``; poses are ``xyz`` plus one rotation form. Every
mistake names the file and the field.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from manip_kin.core.model import JointType
from manip_kin.core.robot_files import MAX_MAGNITUDE
from manip_kin.core.rotations import check_rotation, make_transform, quat_to_matrix, rpy_to_matrix
from manip_kin.errors import ModelFileError, NotARotationError, bounded_repr

_PI_EXPRESSION = re.compile(
    r"^\s*(?P<sign>[+-])?\s*(?P<coef>\d+(\.\d*)?|\.\d+)?\s*\*?\s*pi\s*(/\s*(?P<den>\d+(\.\d*)?))?\s*$"
)
_DEGREES = re.compile(r"^\s*(?P<value>[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?)\s*(deg|degrees|°)\s*$")


class FieldReader:
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
