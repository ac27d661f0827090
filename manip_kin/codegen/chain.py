"""Straight-line Python code for one chain's forward kinematics and Jacobian.

Small numpy calls cost about a microsecond each whatever their size, so a 7-joint chain
evaluated with 4x4 products spends most of its time in call overhead. This module
unrolls the chain once, when a model is built, into plain float arithmetic: constant
transform entries are folded in, zero terms are dropped (the fixed rotations of most arms
are signed permutations), and what remains is a few hundred multiply-adds on local
variables. The result is checked against the numpy reference in the tests.

The emitter (:meth:`ChainSpec.emit`) returns a :class:`manip_kin.codegen.ir.Fragment` whose
outputs are the target frame's 4x4 pose, row-major (16 values), followed, when a Jacobian is
requested, by the geometric Jacobian ``[angular; linear]`` row-major (6n values). Each is a
constant where the structure fixes it (the pose's last row, an axis entry of a joint ahead of
every moving one, a zero lever arm's linear column), else a local or its negation. The
compiled ``chain(q)`` returns them as a flat tuple and carries its :class:`ChainSpec`, from which
the control step, the IK iteration and the damped solve emit the same values into their own code.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from manip_kin.codegen.ir import Fragment, Names, Value, render
from manip_kin.codegen.kernel_cache import kernel

# Entries this close to 0 or ±1 in the fixed transforms are taken as exact: the table
# rotations (and URDF rpy of ±π/2) leave 1e-17 residues that would only cost time.
_SNAP = 1e-14


def _snap(value: float) -> float:
    for exact in (0.0, 1.0, -1.0):
        if abs(value - exact) < _SNAP:
            return exact
    return value


def _negated(term: str) -> str:
    return term[1:] if term.startswith("-") else f"-{term}"


class _Emitter:
    """Collects generated statements; values are floats (constants) or variable names."""

    def __init__(self, names: Names):
        self.lines: list[str] = []
        self.names = names
        self.known: dict[str, str] = {}  # expression -> the variable already holding it

    def combine(self, terms: Sequence[tuple], constant: float = 0.0) -> object:
        """The value ``constant + Σ sign·a·b`` over ``terms`` of ``(a, b)`` or ``(a, b, sign)``.

        Emits a new variable unless the value is a constant or a plain alias.
        """
        parts: list[str] = []
        for term in terms:
            a, b = term[0], term[1]
            sign = term[2] if len(term) > 2 else 1.0
            if isinstance(a, float) and isinstance(b, float):
                constant += sign * a * b
                continue
            if isinstance(a, float):
                a, b = b, a
            # A value may be a negated alias "-name": fold its sign into the term.
            if a.startswith("-"):
                a, sign = a[1:], -sign
            if isinstance(b, str) and b.startswith("-"):
                b, sign = b[1:], -sign
            if isinstance(b, float):  # variable · constant
                factor = _snap(sign * b)
                if factor == 0.0:
                    continue
                parts.append(a if factor == 1.0 else f"-{a}" if factor == -1.0 else f"{factor!r}*{a}")
            else:
                parts.append(f"{a}*{b}" if sign > 0 else f"-{a}*{b}")
        constant = _snap(constant)
        if len(parts) % 2 == 0 and parts and _negated(parts[0]) in parts:
            if sorted(parts) == sorted(map(_negated, parts)):
                # Every term cancels (``o - o``: a frame at its joint's origin has a zero lever
                # arm): a structural constant, not a local that happens to be zero.
                parts = []
        if not parts:
            return constant
        if len(parts) == 1 and constant == 0.0 and "*" not in parts[0]:
            return parts[0]  # a plain or negated alias: no statement needed
        expression = " + ".join(parts).replace("+ -", "- ")
        if constant != 0.0:
            expression += f" - {-constant!r}" if constant < 0.0 else f" + {constant!r}"
        if expression in self.known:  # the same value computed before (e.g. a shared lever arm)
            return self.known[expression]
        name = self.names.fresh("v")
        self.known[expression] = name
        self.lines.append(f"{name} = {expression}")
        return name


def _times_constant(emit: _Emitter, state: list[list[object]], fixed: np.ndarray) -> list[list[object]]:
    """``state · fixed`` for 3x4 affine ``state`` and a constant 4x4 ``fixed``."""
    out = []
    for r in range(3):
        row = []
        for c in range(4):
            terms = [(state[r][k], float(fixed[k, c])) for k in range(3)]
            if c == 3:
                terms.append((state[r][3], 1.0))
            row.append(emit.combine(terms))
        out.append(row)
    return out


def _joint_step(
    emit: _Emitter, state: list[list[object]], fixed: np.ndarray, revolute: bool, joint: str
) -> list[list[object]]:
    """``state · F_i · (Rz(q_i) or Tz(q_i))``: the 3x4 affine state on to the moving frame of
    the joint whose value is the local ``joint``."""
    state = _times_constant(emit, state, fixed)
    if revolute:
        c, s = emit.names.fresh("c"), emit.names.fresh("s")
        emit.lines.append(f"{c} = cos({joint}); {s} = sin({joint})")
        for r in range(3):
            col0, col1 = state[r][0], state[r][1]
            # M · Rz(q): column 0 = c·m0 + s·m1, column 1 = c·m1 - s·m0
            state[r][0] = emit.combine([(col0, c), (col1, s)])
            state[r][1] = emit.combine([(col1, c), (col0, s, -1.0)])
    else:
        for r in range(3):
            state[r][3] = emit.combine([(state[r][3], 1.0), (state[r][2], joint)])
    return state


def _cross(emit: _Emitter, a: Sequence[object], b: Sequence[object]) -> list[object]:
    """``a × b`` of two 3-vectors of values."""
    return [
        emit.combine([(a[1], b[2]), (a[2], b[1], -1.0)]),
        emit.combine([(a[2], b[0]), (a[0], b[2], -1.0)]),
        emit.combine([(a[0], b[1]), (a[1], b[0], -1.0)]),
    ]


def _function_source(name: str, joints: Sequence[str], fragment: Fragment) -> str:
    """``def name(q)``: unpack the joint values into ``joints``, run ``fragment``, return its outputs as a flat tuple."""
    arguments = ", ".join(joints) + ("," if len(joints) == 1 else "")
    body = [f"    {arguments} = q"] + [f"    {line}" for line in fragment.lines]
    body.append("    return (" + ", ".join(render(v) for v in fragment.outputs) + ",)")
    return f"def {name}(q):\n" + "\n".join(body) + "\n"


def _function_names(n: int) -> tuple[Names, list[str]]:
    """The names of a ``def f(q)`` calling cos and sin, and its joint locals ``q0..``."""
    names = Names(["q", "cos", "sin"])
    return names, [names.fresh("q") for _ in range(n)]


@dataclass(frozen=True)
class ChainSpec:
    """What one chain's code depends on (hashable: the kernels' cache key), and its emitter.

    Attributes:
        shape: the shape of ``fixed``, (n, 4, 4).
        fixed: ``F_i`` of :class:`manip_kin.core.model.ChainArrays`, as bytes.
        revolute: joint types, True for revolute.
        tail: constant transform from joint ``count``'s moving frame to the target frame, as bytes.
        count: how many joints move the target frame.
        with_jacobian: the outputs include the geometric Jacobian of the target frame.
    """

    shape: tuple[int, ...]
    fixed: bytes
    revolute: tuple[bool, ...]
    tail: bytes
    count: int
    with_jacobian: bool

    @classmethod
    def of(
        cls, fixed: np.ndarray, revolute: Sequence[bool], tail: np.ndarray, count: int, with_jacobian: bool
    ) -> ChainSpec:
        """The spec of the first ``count`` joints of ``fixed`` (shape (n, 4, 4)), then ``tail`` (4, 4)."""
        fixed = np.ascontiguousarray(fixed, dtype=float)
        tail = np.ascontiguousarray(tail, dtype=float)
        revolute = tuple(bool(flag) for flag in revolute)
        return cls(fixed.shape, fixed.tobytes(), revolute, tail.tobytes(), int(count), bool(with_jacobian))

    @property
    def dof(self) -> int:
        return len(self.revolute)

    def emit(self, names: Names, joints: Sequence[str]) -> Fragment[tuple[Value, ...]]:
        """The chain's statements on the joint locals ``joints``, its locals from ``names``.

        Outputs: the pose (16 values, row-major), then with the Jacobian its 6 x n entries
        ``[angular; linear]`` row-major; constants where the structure fixes them.
        """
        fixed = np.frombuffer(self.fixed).reshape(self.shape)
        tail = np.frombuffer(self.tail).reshape(4, 4)
        emit = _Emitter(names)
        n = self.dof
        state: list[list[object]] = [[1.0 if r == c else 0.0 for c in range(4)] for r in range(3)]
        axes, origins = [], []
        for i in range(self.count):
            state = _joint_step(emit, state, fixed[i], self.revolute[i], joints[i])
            axes.append([state[r][2] for r in range(3)])
            origins.append([state[r][3] for r in range(3)])
        state = _times_constant(emit, state, tail)
        outputs: list[object] = [state[r][c] for r in range(3) for c in range(4)] + [0.0, 0.0, 0.0, 1.0]
        if self.with_jacobian:
            position = [state[r][3] for r in range(3)]
            angular = [[0.0] * n for _ in range(3)]
            linear = [[0.0] * n for _ in range(3)]
            for i in range(self.count):
                z, o = axes[i], origins[i]
                if self.revolute[i]:
                    lever = [emit.combine([(position[r], 1.0), (o[r], -1.0)]) for r in range(3)]
                    for r in range(3):
                        angular[r][i] = z[r]
                    for r, value in enumerate(_cross(emit, z, lever)):
                        linear[r][i] = value
                else:
                    for r in range(3):
                        linear[r][i] = z[r]
            outputs += [v for row in angular + linear for v in row]
        return Fragment(emit.lines, tuple(outputs))

    def constants(self) -> dict[int, float]:
        """Output index -> value of the outputs the structure fixes."""
        names, joints = _function_names(self.dof)
        return self.emit(names, joints).constants()

    def source(self) -> str:
        """Python source of ``chain(q)``: the outputs of :meth:`emit` as a flat tuple."""
        names, joints = _function_names(self.dof)
        return _function_source("chain", joints, self.emit(names, joints))


def compile_chain(
    fixed: np.ndarray,
    revolute: Sequence[bool],
    tail: np.ndarray,
    count: int,
    with_jacobian: bool,
    vectorized: bool = False,
) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """Compile :meth:`ChainSpec.source` into a function (through :mod:`manip_kin.codegen.kernel_cache`).

    The function carries its :class:`ChainSpec` as ``spec``. With ``vectorized`` the same code
    runs on numpy arrays: pass one array of N values per joint and every returned entry is an
    array of N values (or a constant).
    """
    spec = ChainSpec.of(fixed, revolute, tail, count, with_jacobian)
    namespace = {"cos": np.cos, "sin": np.sin} if vectorized else {"cos": math.cos, "sin": math.sin}
    # The geometry is the structure here: the source folds every fixed transform in.
    function = kernel("chain", (spec, vectorized), spec.source, "chain", namespace)
    function.spec = spec
    return function


def generate_frames_source(fixed: np.ndarray, revolute: Sequence[bool], frame_offsets: np.ndarray) -> str:
    """Python source of ``frames(q)``: every model frame and every joint's spatial twist in one pass.

    Returns a flat tuple: frames 0 (base, the identity) .. n as 4x4 row-major (16 values each),
    then the (6, n) matrix, row-major, whose column j is joint j's unit twist in base
    ``[ω; v]``: ``(z_j, o_j × z_j)`` for a revolute joint, ``(0, z_j)`` for a prismatic one,
    with ``z_j`` its axis and ``o_j`` its origin. A point ``p`` moving with joint j has the
    linear velocity ``v + ω × p`` per unit rate (the columns of its linear Jacobian).

    Args:
        fixed: ``F_i`` of :class:`manip_kin.core.model.ChainArrays`, shape (n, 4, 4).
        revolute: joint types, True for revolute.
        frame_offsets: from joint i's moving frame to model frame i, shape (n, 4, 4).
    """
    n = len(revolute)
    names, joints = _function_names(n)
    emit = _Emitter(names)
    state: list[list[object]] = [[1.0 if r == c else 0.0 for c in range(4)] for r in range(3)]
    outputs: list[object] = [1.0 if r == c else 0.0 for r in range(4) for c in range(4)]
    twists: list[list[object]] = [[0.0] * n for _ in range(6)]
    bottom = [0.0, 0.0, 0.0, 1.0]
    for i in range(n):
        state = _joint_step(emit, state, fixed[i], revolute[i], joints[i])
        z, o = [state[r][2] for r in range(3)], [state[r][3] for r in range(3)]
        if revolute[i]:
            for r in range(3):
                twists[r][i] = z[r]
            for r, value in enumerate(_cross(emit, o, z)):
                twists[3 + r][i] = value
        else:
            for r in range(3):
                twists[3 + r][i] = z[r]
        frame = _times_constant(emit, state, frame_offsets[i])
        outputs += [frame[r][c] for r in range(3) for c in range(4)] + bottom
    outputs += [v for row in twists for v in row]
    return _function_source("frames", joints, Fragment(emit.lines, tuple(outputs)))


def compile_frames(
    fixed: np.ndarray, revolute: Sequence[bool], frame_offsets: np.ndarray
) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """Compile :func:`generate_frames_source` into a function (through :mod:`manip_kin.codegen.kernel_cache`)."""
    fixed = np.ascontiguousarray(fixed, dtype=float)
    frame_offsets = np.ascontiguousarray(frame_offsets, dtype=float)
    revolute = tuple(bool(flag) for flag in revolute)
    key = (fixed.shape, fixed.tobytes(), revolute, frame_offsets.tobytes())
    return kernel(
        "frames",
        key,
        lambda: generate_frames_source(fixed, revolute, frame_offsets),
        "frames",
        {"cos": math.cos, "sin": math.sin},
    )
