"""The head the control step and the IK iteration share: the chain, then the pose error.

Both start from the joint values ``q`` and the goal pose rows ``g``: the chain's statements
(:meth:`manip_kin.codegen.chain.ChainSpec.emit`), the goal's entries, ``R_goal · Rᵀ`` and its
rotation vector (:mod:`manip_kin.codegen.inlined`, inlined from its own source), and the
position error.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from manip_kin.codegen.chain import ChainSpec
from manip_kin.codegen.inlined import rotvec_from_quaternion, shepperd_quaternion
from manip_kin.codegen.ir import Fragment, Names, Value, product, total
from manip_kin.codegen.source_inline import inline_lines

#: Functions the generated sources call by these names.
GENERATED_MATH = {"sqrt": math.sqrt, "atan2": math.atan2, "cos": math.cos, "sin": math.sin}


class PoseError(NamedTuple):
    """The locals and values :func:`chain_and_pose_error` defines."""

    joints: tuple[str, ...]  #: ``q``'s entries
    chain: tuple[Value, ...]  #: the chain's outputs (pose, then the Jacobian)
    goal_position: tuple[str, str, str]  #: the goal's x, y, z
    error: tuple[str, ...]  #: ``[orientation; position]`` error, 6 locals


def chain_and_pose_error(names: Names, spec: ChainSpec) -> Fragment[PoseError]:
    """``q`` and ``g`` (parameters, reserved by the caller) unpacked, the chain, the pose error."""
    n = spec.dof
    joints = tuple(names.fresh("q") for _ in range(n))
    lines = [", ".join(joints) + ("," if n == 1 else "") + " = q"]
    chain = spec.emit(names, joints)
    lines += chain.lines
    pose = chain.outputs
    goal = [[names.fresh("G") for _ in range(3)] for _ in range(3)]
    position = (names.fresh("GX"), names.fresh("GY"), names.fresh("GZ"))
    rows = ", ".join(f"({', '.join(goal[i])}, {position[i]})" for i in range(3))
    lines.append(f"{rows} = g[0], g[1], g[2]")
    # E = R_goal · Rᵀ: entry (i, j) = goal row i · current row j.
    current = [[pose[0], pose[1], pose[2]], [pose[4], pose[5], pose[6]], [pose[8], pose[9], pose[10]]]
    entries = []
    for i in range(3):
        for j in range(3):
            entries.append(names.fresh("M"))
            lines.append(f"{entries[-1]} = " + total([product(goal[i][k], current[j][k]) for k in range(3)]))
    # The rotation vector of M: rotations.rotvec_from_entries, inlined from its own source.
    quaternion = [names.fresh(f"Q{axis}") for axis in "XYZW"]
    error = tuple(names.fresh("E") for _ in range(6))
    lines += inline_lines(shepperd_quaternion, entries, quaternion, names, "SQ_")
    lines += inline_lines(rotvec_from_quaternion, quaternion, error[:3], names, "RV_")
    for axis, index in enumerate((3, 7, 11)):
        lines.append(f"{error[3 + axis]} = " + total([position[axis], product(-1.0, pose[index])]))
    return Fragment(lines, PoseError(joints, pose, position, error))
