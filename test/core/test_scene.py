"""Scene obstacles from collision_objects markers: shapes, actions, refusals."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import Pose
from hypothesis import given
from hypothesis import strategies as st
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.core.scene import Scene, SceneUpdateError, ShapeKind, make_obstacle
from manip_kin.ros.wire.scene_messages import apply_marker_array


def _marker(
    ns="cell",
    id=0,
    type=Marker.CUBE,
    action=Marker.ADD,
    scale=(0.2, 0.4, 0.6),
    xyz=(0.5, 0, 0.1),
    frame="base_link",
    quat=(0.0, 0.0, 0.0, 1.0),
    mesh="",
):
    marker = Marker(ns=ns, id=id, type=type, action=action, mesh_resource=mesh)
    marker.header.frame_id = frame
    marker.scale.x, marker.scale.y, marker.scale.z = scale
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = xyz
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = quat
    marker.pose = pose
    return marker


def test_add_replace_delete_deleteall():
    scene = Scene()
    problems = apply_marker_array(
        scene,
        MarkerArray(markers=[_marker(id=0), _marker(id=1, type=Marker.SPHERE, scale=(0.3, 0.3, 0.3))]),
        "base_link",
    )
    assert problems == []
    assert [o.shape for o in scene.obstacles] == [ShapeKind.BOX, ShapeKind.SPHERE]
    box = scene.obstacles[0]
    assert box.half_extents == pytest.approx((0.1, 0.2, 0.3))
    assert scene.obstacles[1].radius == pytest.approx(0.15)
    # A quarter turn about z: the marker's quaternion becomes the obstacle's rotation.
    s = math.sqrt(0.5)
    apply_marker_array(scene, MarkerArray(markers=[_marker(id=0, quat=(0, 0, s, s), xyz=(1, 2, 3))]), "base_link")
    assert len(scene) == 2
    np.testing.assert_allclose(scene.obstacles[0].pose_in_base[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(scene.obstacles[0].pose_in_base[:3, 3], [1, 2, 3])
    version = scene.version
    apply_marker_array(scene, MarkerArray(markers=[_marker(id=7, action=Marker.DELETE)]), "base_link")
    assert len(scene) == 2 and scene.version == version  # an unknown key: nothing changes
    apply_marker_array(scene, MarkerArray(markers=[_marker(id=1, action=Marker.DELETE)]), "base_link")
    assert [o.key for o in scene.obstacles] == [("cell", 0)]
    apply_marker_array(scene, MarkerArray(markers=[_marker(action=Marker.DELETEALL)]), "base_link")
    assert len(scene) == 0 and scene.version > version


def test_bad_markers_are_refused_with_reasons_and_the_rest_applies():
    scene = Scene()
    markers = [
        _marker(id=0, frame="world"),
        _marker(id=1, type=Marker.ARROW),
        _marker(id=2, scale=(0.1, -0.1, 0.1)),
        _marker(id=3, quat=(0, 0, 0, 0)),
        _marker(id=4, type=Marker.MESH_RESOURCE),
        _marker(id=5, xyz=(1e9, 0, 0)),
        _marker(id=6, type=Marker.CYLINDER, scale=(0.1, 0.1, 0.5)),
    ]
    problems = apply_marker_array(scene, MarkerArray(markers=markers), "base_link")
    assert len(problems) == 6
    assert "'world'" in problems[0] and "base_link" in problems[0]
    assert "type 0" in problems[1] and "CUBE 1" in problems[1]
    assert "scale" in problems[2]
    assert "quaternion" in problems[3]
    assert "mesh_resource" in problems[4]
    assert "1000 m" in problems[5]
    assert [o.key for o in scene.obstacles] == [("cell", 6)]
    assert scene.obstacles[0].height == pytest.approx(0.5)


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=3))
def test_any_scale_is_an_obstacle_or_a_refusal(scale):
    try:
        obstacle = make_obstacle(("n", 0), "box", scale, np.eye(4))
    except SceneUpdateError as error:
        assert "scale" in str(error)
    else:
        assert all(math.isfinite(v) and 0 < v <= 1e3 for v in obstacle.scale)
