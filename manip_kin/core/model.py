"""The robot model: an immutable serial chain of revolute and prismatic joints.

Every way of describing an arm (joint list, DH table, product of exponentials,
URDF) is turned into the same model, built once and reused:

* joint ``i`` sits on the frame of joint ``i - 1`` (the base for joint 1) at the fixed
  transform ``origin``; it then rotates about (revolute) or slides along (prismatic)
  its unit ``axis``, given in its own frame; ``child_offset`` is a fixed transform from
  that moving frame to the link frame reported as "frame i" (identity except for DH
  tables, whose frame ``i`` lies at the end of the link).
* the end effector (``ee``) is frame ``n`` followed by ``ee_offset``; the optional
  ``tool`` is a fixed transform on the end effector.

Per-call work (forward kinematics, Jacobians) lives in :mod:`manip_kin.core.kinematics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from manip_kin.core.model_kernels import ModelKernels
from manip_kin.core.rotations import rotation_z_onto
from manip_kin.errors import JointCountError, ModelFileError, UnknownFrameError, check_finite


class JointType(str, Enum):
    """The two joint types of a serial chain."""

    REVOLUTE = "revolute"
    PRISMATIC = "prismatic"


@dataclass(frozen=True)
class Joint:
    """One joint of a serial chain.

    Attributes:
        name: joint name (URDF joint name when loaded from URDF).
        type: revolute (position in [rad]) or prismatic (position in [m]).
        origin: fixed transform from the previous joint's frame to this joint's
            frame at zero position, shape (4, 4).
        axis: unit axis of motion in this joint's frame, shape (3,).
        lower: lower position limit [rad] or [m].
        upper: upper position limit [rad] or [m].
        velocity_limit: maximum speed [rad/s] or [m/s], > 0.
        child_offset: fixed transform from the moving joint frame to the frame
            reported for this joint, shape (4, 4); identity except for DH models.
        link_name: name of the link this joint moves (URDF child link).
    """

    name: str
    type: JointType
    origin: np.ndarray
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    lower: float = -math.pi
    upper: float = math.pi
    velocity_limit: float = 2.0
    child_offset: np.ndarray = field(default_factory=lambda: np.eye(4))
    link_name: str = ""

    @property
    def is_revolute(self) -> bool:
        """True for a revolute joint."""
        return self.type is JointType.REVOLUTE


@dataclass(frozen=True)
class ChainArrays:
    """Joint-independent arrays that make per-call kinematics a few numpy calls.

    The chain is rewritten as ``F_1 Z(q_1) F_2 Z(q_2) … F_n Z(q_n)`` where ``Z`` is a
    rotation about or translation along z, and ``F_i`` folds the previous joint's
    child offset, this joint's origin and the rotation that aligns its axis with z.

    Attributes:
        fixed: ``F_i``, shape (n, 4, 4).
        basis: ``F_i Z(q)`` flattened is ``basis_i @ [cos q, sin q, q, 1]``, shape (n, 16, 4).
        revolute_mask: 1.0 for revolute joints, shape (n,).
        prismatic_mask: 1.0 for prismatic joints, shape (n,).
        frame_offsets: from joint i's moving (z-aligned) frame to reported frame i, shape (n, 4, 4).
        moving_to_ee: from joint n's moving frame to the end effector, shape (4, 4).
    """

    fixed: np.ndarray
    basis: np.ndarray
    revolute_mask: np.ndarray
    prismatic_mask: np.ndarray
    frame_offsets: np.ndarray
    moving_to_ee: np.ndarray


def _compile_chain(joints: tuple[Joint, ...], ee_offset: np.ndarray) -> ChainArrays:
    n = len(joints)
    fixed = np.empty((n, 4, 4))
    frame_offsets = np.empty((n, 4, 4))
    previous_post = np.eye(4)
    for i, joint in enumerate(joints):
        align = np.eye(4)
        align[:3, :3] = rotation_z_onto(joint.axis)
        # origin · Rot(axis, q) = (origin · A) · Rz(q) · Aᵀ with A z-to-axis.
        fixed[i] = previous_post @ joint.origin @ align
        unalign = np.eye(4)
        unalign[:3, :3] = align[:3, :3].T
        frame_offsets[i] = unalign @ joint.child_offset
        previous_post = frame_offsets[i]
    moving_to_ee = previous_post @ ee_offset
    revolute = np.array([1.0 if j.is_revolute else 0.0 for j in joints])
    prismatic = 1.0 - revolute
    # F · Z(q), flattened row-major, as a linear map of u = [cos q, sin q, q, 1]:
    # Rz(q) mixes columns 0 and 1, Tz(q) adds q times column 2 to column 3.
    basis = np.zeros((n, 4, 4, 4))
    for i in range(n):
        f = fixed[i]
        if revolute[i]:
            basis[i, :, 0, 0], basis[i, :, 0, 1] = f[:, 0], f[:, 1]  # col0 = c f0 + s f1
            basis[i, :, 1, 0], basis[i, :, 1, 1] = f[:, 1], -f[:, 0]  # col1 = c f1 - s f0
            basis[i, :, 2, 3], basis[i, :, 3, 3] = f[:, 2], f[:, 3]
        else:
            basis[i, :, 0, 3], basis[i, :, 1, 3], basis[i, :, 2, 3] = f[:, 0], f[:, 1], f[:, 2]
            basis[i, :, 3, 3], basis[i, :, 3, 2] = f[:, 3], f[:, 2]  # col3 = f3 + q f2
    return ChainArrays(
        fixed=fixed,
        basis=basis.reshape(n, 16, 4),
        revolute_mask=revolute,
        prismatic_mask=prismatic,
        frame_offsets=frame_offsets,
        moving_to_ee=moving_to_ee,
    )


@dataclass(frozen=True)
class RobotModel:
    """An immutable serial manipulator model.

    Attributes:
        name: robot name.
        joints: the joints from base to end effector.
        ee_offset: fixed transform from frame n to the end effector, shape (4, 4).
        tool: fixed transform from the end effector to the tool frame, shape (4, 4),
            or None when the robot has no tool.
        base_frame: frame id of the base (``base_link``).
        initial_positions: a start configuration (scenario start), shape (n,), or None.
        source: where the model came from (file path or description), for messages.
    """

    name: str
    joints: tuple[Joint, ...]
    ee_offset: np.ndarray = field(default_factory=lambda: np.eye(4))
    tool: np.ndarray | None = None
    base_frame: str = "base_link"
    initial_positions: np.ndarray | None = None
    source: str = ""
    chain: ChainArrays = field(init=False, repr=False, compare=False)
    lower: np.ndarray = field(init=False, repr=False, compare=False)
    upper: np.ndarray = field(init=False, repr=False, compare=False)
    velocity_limits: np.ndarray = field(init=False, repr=False, compare=False)
    # What is built from the model on first use (its generated kinematics, IK problems): an
    # object of its own, so the model's fields never change (see manip_kin.core.model_kernels).
    kernels: ModelKernels = field(init=False, repr=False, compare=False, default_factory=ModelKernels)

    def __post_init__(self):
        if not self.joints:
            raise ModelFileError(self.source or self.name, "joints", "a robot needs at least one joint")
        names = [j.name for j in self.joints]
        if len(set(names)) != len(names):
            raise ModelFileError(self.source or self.name, "joints", f"joint names repeat: {names}")
        where = self.source or self.name
        fixed = [
            (f"{j.name}.{part}", getattr(j, part)) for j in self.joints for part in ("origin", "axis", "child_offset")
        ]
        fixed += [("ee_offset", self.ee_offset)] + ([("tool", self.tool)] if self.tool is not None else [])
        for field_name, value in fixed:
            if not np.all(np.isfinite(np.asarray(value, dtype=float))):
                raise ModelFileError(where, field_name, "contains NaN or infinity; valid: finite numbers")
        for j in self.joints:
            if not j.lower <= j.upper:
                raise ModelFileError(self.source or self.name, f"{j.name}.limits", f"lower {j.lower} > upper {j.upper}")
            if not j.velocity_limit > 0:
                raise ModelFileError(
                    self.source or self.name,
                    f"{j.name}.velocity_limit",
                    f"{j.velocity_limit}; valid: a positive speed",
                )
        object.__setattr__(self, "chain", _compile_chain(self.joints, np.asarray(self.ee_offset, float)))
        object.__setattr__(self, "lower", np.array([j.lower for j in self.joints]))
        object.__setattr__(self, "upper", np.array([j.upper for j in self.joints]))
        object.__setattr__(self, "velocity_limits", np.array([j.velocity_limit for j in self.joints]))
        for array in (self.lower, self.upper, self.velocity_limits):
            array.setflags(write=False)
        if self.initial_positions is not None:
            start = self.check_q(self.initial_positions, "initial_positions")
            start.setflags(write=False)
            object.__setattr__(self, "initial_positions", start)

    @property
    def dof(self) -> int:
        """Number of joints n."""
        return len(self.joints)

    @property
    def joint_names(self) -> list[str]:
        """Joint names in model order."""
        return [j.name for j in self.joints]

    @property
    def has_tool(self) -> bool:
        """True when a tool frame is defined."""
        return self.tool is not None

    @property
    def is_prismatic(self) -> np.ndarray:
        """Boolean mask of prismatic joints, shape (n,)."""
        return self.chain.prismatic_mask > 0.5

    @property
    def default_frame(self) -> str:
        """``tool`` if the robot has one, else ``ee``."""
        return "tool" if self.has_tool else "ee"

    @property
    def frame_names(self) -> list[str]:
        """Every frame name: ``base``, ``1``..``n``, ``ee`` and ``tool`` (if any)."""
        names = ["base"] + [str(i) for i in range(1, self.dof + 1)] + ["ee"]
        return names + (["tool"] if self.has_tool else [])

    def frame_index(self, frame: str | int) -> int:
        """Index of a frame in the array of :func:`manip_kin.core.kinematics.all_frames`.

        0 is the base, 1..n the joint frames, n + 1 the end effector and n + 2 the tool.
        Accepts ``base``/the base frame id, ``ee``, ``tool``, an index 0..n (int or digits)
        and link names.
        """
        n = self.dof
        if isinstance(frame, (int, np.integer)) and not isinstance(frame, bool):
            # Integer indices address the whole frame array (ee = n + 1, tool = n + 2).
            if 0 <= int(frame) < len(self.frame_names):
                return int(frame)
        elif isinstance(frame, str):
            key = frame.strip()
            if key in ("base", self.base_frame):
                return 0
            if key == "ee":
                return n + 1
            if key == "tool" and self.has_tool:
                return n + 2
            if key.isdigit() and 0 <= int(key) <= n:
                return int(key)
            for i, joint in enumerate(self.joints, start=1):
                if joint.link_name and key == joint.link_name:
                    return i
        raise UnknownFrameError(frame, self.frame_names)

    def frame_name(self, index: int) -> str:
        """Name of frame ``index`` as listed by :attr:`frame_names`."""
        return self.frame_names[index]

    def check_q(self, q, what: str = "q") -> np.ndarray:
        """Joint vector as a float array of shape (n,), or a clear error."""
        array = np.asarray(q, dtype=float).reshape(-1)
        if array.shape[0] != self.dof:
            raise JointCountError(what, array.shape[0], self.dof)
        return check_finite(array, what)

    def within_limits(self, q, tolerance: float = 1e-9) -> bool:
        """True when every joint of ``q`` is inside its position limits."""
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.lower - tolerance) and np.all(q <= self.upper + tolerance))

    def clip_to_limits(self, q) -> np.ndarray:
        """``q`` clipped into the position limits, shape (n,)."""
        return np.clip(np.asarray(q, dtype=float), self.lower, self.upper)

    def random_configuration(self, rng: np.random.Generator, margin: float = 0.0) -> np.ndarray:
        """A uniformly random configuration within limits (shrunk by ``margin`` on each side).

        Infinite limits (continuous joints) are sampled in [-π, π] or [-1, 1] m.
        """
        lower = np.where(np.isfinite(self.lower), self.lower, np.where(self.is_prismatic, -1.0, -math.pi))
        upper = np.where(np.isfinite(self.upper), self.upper, np.where(self.is_prismatic, 1.0, math.pi))
        span = upper - lower
        return rng.uniform(lower + margin * span, upper - margin * span)

    def start_configuration(self) -> np.ndarray:
        """``initial_positions`` if given, else zeros clipped into the limits."""
        if self.initial_positions is not None:
            return np.array(self.initial_positions)
        return self.clip_to_limits(np.zeros(self.dof))
