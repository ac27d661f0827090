"""Robots with collision geometry for the collision and QP tests (and the bench).

* the Franka Panda of example-robot-data: URDF with STL collision meshes and its SRDF;
* a "ball arm": 3 revolute joints whose moving links carry one sphere each, so every distance
  to a sphere or box obstacle has a closed form the tests compute on their own.
"""

from __future__ import annotations

import coal
import numpy as np
from robot_data_files import PANDA, example_robot_data_urdf

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.model import RobotModel

PANDA_READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
#: Within the limits, the hand 4.7 cm into link 1 (found by sampling; `manip_kin check` agrees).
PANDA_FOLDED = np.array([0.806, -0.986, -0.609, -2.972, 0.362, 0.486, 0.172])


def panda_files():
    """``(urdf, srdf, mesh_search_path)`` of the example-robot-data Panda."""
    urdf = example_robot_data_urdf(PANDA)
    srdf = urdf.parents[1] / "srdf" / "panda.srdf"
    share = urdf.parents[4]  # <share>/example-robot-data/robots/panda_description/urdf/panda.urdf
    return urdf, srdf, str(share)


#: Sphere of each moving link: (link, centre in the link frame [m], radius [m]).
BALL_ARM_SPHERES = (("link2", (0.3, 0.0, 0.0), 0.05), ("link3", (0.25, 0.0, 0.0), 0.04))
#: The base box: centre [m] and full extents [m], in the base frame.
BALL_ARM_BASE_BOX = ((0.0, 0.0, 0.05), (0.2, 0.2, 0.1))

BALL_ARM_URDF = """<?xml version="1.0"?>
<robot name="ball_arm">
  <link name="base_link">
    <collision><origin xyz="0 0 0.05"/><geometry><box size="0.2 0.2 0.1"/></geometry></collision>
  </link>
  <link name="link1">
    <collision><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.03" length="0.2"/></geometry></collision>
  </link>
  <link name="link2">
    <collision><origin xyz="0.3 0 0"/><geometry><sphere radius="0.05"/></geometry></collision>
  </link>
  <link name="link3">
    <collision><origin xyz="0.25 0 0"/><geometry><sphere radius="0.04"/></geometry></collision>
  </link>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base_link"/><child link="link1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="2"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="link1"/><child link="link2"/><origin xyz="0 0 0.2"/><axis xyz="0 -1 0"/>
    <limit lower="-2" upper="2" velocity="2"/>
  </joint>
  <joint name="j3" type="revolute">
    <parent link="link2"/><child link="link3"/><origin xyz="0.3 0 0"/><axis xyz="0 -1 0"/>
    <limit lower="-2.5" upper="2.5" velocity="2"/>
  </joint>
  <joint name="tip_joint" type="fixed">
    <parent link="link3"/><child link="tip"/><origin xyz="0.25 0 0"/>
  </joint>
</robot>
"""


def ball_centres(model: RobotModel, q) -> list[tuple[str, np.ndarray, float]]:
    """``(link, centre in base, radius)`` of the ball arm's spheres at ``q``, from plain FK."""
    spheres = []
    for link, centre, radius in BALL_ARM_SPHERES:
        pose = frame_pose(model, q, link)
        spheres.append((link, pose[:3, :3] @ np.array(centre) + pose[:3, 3], radius))
    return spheres


def point_box_distance(point, centre, extents) -> float:
    """Distance from a point to an axis-aligned box (0 inside) [m]."""
    outside = np.maximum(np.abs(np.asarray(point) - np.asarray(centre)) - 0.5 * np.asarray(extents), 0.0)
    return float(np.linalg.norm(outside))


def ball_obstacle_distance(model: RobotModel, q, centre, radius: float) -> float:
    """The nearest of the ball arm's spheres to a sphere obstacle, in closed form [m]."""
    return min(float(np.linalg.norm(c - np.asarray(centre))) - r - radius for _, c, r in ball_centres(model, q))


def fresh_hand_link1_distance(model, q) -> float:
    """The hand–link1 distance from the STL meshes with fresh coal objects (not the law's code path)."""
    urdf = panda_files()[0]
    meshes = urdf.parents[1] / "meshes" / "collision"
    shapes = []
    for name in ("link1", "hand"):
        mesh = coal.MeshLoader().load(str(meshes / f"{name}.stl"), np.ones(3))
        mesh.buildConvexHull(True, "Qt")
        shapes.append(mesh.convex)
    poses = [frame_pose(model, q, "panda_link1"), frame_pose(model, q, "ee")]  # ee = panda_hand
    transforms = [coal.Transform3s(p[:3, :3], p[:3, 3]) for p in poses]
    result = coal.DistanceResult()
    return coal.distance(shapes[0], transforms[0], shapes[1], transforms[1], coal.DistanceRequest(), result)


def fresh_coal_distance(shape_a, pose_a, shape_b, pose_b) -> tuple[float, coal.DistanceResult]:
    """The distance of two coal shapes at poses in base (shape (4, 4)), with fresh coal objects, and
    coal's result (witness points, normal)."""
    result = coal.DistanceResult()
    distance = coal.distance(
        shape_a,
        coal.Transform3s(pose_a[:3, :3], pose_a[:3, 3]),
        shape_b,
        coal.Transform3s(pose_b[:3, :3], pose_b[:3, 3]),
        coal.DistanceRequest(),
        result,
    )
    return distance, result
