"""A 6R arm of the OPW type built from its OPW parameters, as URDF text, with an independent FK.

The parameters are of the size of a 6 kg industrial arm, with every offset non-zero (a1, a2,
b), axis 3 pointing against axis 2, a mounting yaw and a joint frame rolled about its own axis,
so a detector that relies on aligned frames or on names fails.
"""

from __future__ import annotations

import math

import numpy as np
from kin_reference import euler_rpy, homogeneous, rodrigues

OPW = {"a1": 0.15, "a2": -0.11, "b": 0.06, "c1": 0.45, "c2": 0.6, "c3": 0.64, "c4": 0.1}

# (name, origin xyz, origin rpy, axis, lower, upper) per joint, parent frame to child frame.
JOINTS = [
    ("j1", (0.1, -0.05, 0.02), (0.0, 0.0, 0.3), (0, 0, 1), -math.pi, math.pi),
    ("j2", (OPW["a1"], 0.0, OPW["c1"]), (0.0, 0.0, 0.0), (0, 1, 0), -math.pi, math.pi),
    ("j3", (0.0, OPW["b"], OPW["c2"]), (0.0, 0.0, 0.0), (0, -1, 0), -math.pi, math.pi),
    ("j4", (0.5 * OPW["c3"], 0.0, OPW["a2"]), (0.4, 0.0, 0.0), (1, 0, 0), -math.pi, math.pi),
    ("j5", (0.5 * OPW["c3"], 0.0, 0.0), (0.0, 0.0, 0.0), (0, 1, 0), -math.pi, math.pi),
    ("j6", (OPW["c4"], 0.0, 0.0), (0.0, 0.0, 0.0), (1, 0, 0), -2 * math.pi, 2 * math.pi),
]
TOOL = ((0.05, 0.02, 0.1), (0.1, 0.2, 0.3))  # tool0 on link6: xyz, rpy


def opw_urdf(name: str = "opw_test_arm") -> str:
    """URDF text: base_link, link1..link6 and a fixed tool0."""
    links = ["base_link"] + [f"link{i}" for i in range(1, 7)] + ["tool0"]
    parts = [f'<robot name="{name}">'] + [f'  <link name="{link}"/>' for link in links]
    for i, (joint, xyz, rpy, axis, lower, upper) in enumerate(JOINTS):
        parts.append(
            f'  <joint name="{joint}" type="revolute"><parent link="{links[i]}"/><child link="{links[i + 1]}"/>'
            f'<origin xyz="{" ".join(map(repr, xyz))}" rpy="{" ".join(map(repr, rpy))}"/>'
            f'<axis xyz="{" ".join(map(str, axis))}"/>'
            f'<limit lower="{lower!r}" upper="{upper!r}" velocity="2.0" effort="100"/></joint>'
        )
    xyz, rpy = TOOL
    parts.append(
        '  <joint name="tool_mount" type="fixed"><parent link="link6"/><child link="tool0"/>'
        f'<origin xyz="{" ".join(map(repr, xyz))}" rpy="{" ".join(map(repr, rpy))}"/></joint>'
    )
    parts.append("</robot>")
    return "\n".join(parts)


def opw_reference_pose(q) -> np.ndarray:
    """tool0 in base_link by multiplying the URDF's transforms (no manip_kin code)."""
    pose = np.eye(4)
    for (_, xyz, rpy, axis, _, _), value in zip(JOINTS, q):
        pose = pose @ homogeneous(euler_rpy(*rpy), xyz) @ homogeneous(rodrigues(axis, value))
    xyz, rpy = TOOL
    return pose @ homogeneous(euler_rpy(*rpy), xyz)
