"""``collision_objects`` (visualization_msgs/MarkerArray) into a :class:`~manip_kin.core.scene.Scene`.

The one reader of the topic for every node that keeps a scene (the controller's collision
limits, the physics plant): a bad marker is refused with its reason and the others in the
array still apply, so one typo does not drop the whole cell.
"""

from __future__ import annotations

from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.core.scene import SHAPE_OF_MARKER, MarkerAction, MarkerType, Scene, SceneUpdateError, make_obstacle
from manip_kin.ros.wire.messages import pose_to_matrix
from manip_kin.ros.wire.validation import InvalidMessageError, frame_problem

#: Topic name (relative) and message type.
TOPIC = "collision_objects"


def apply_marker(scene: Scene, marker: Marker, base_frame: str) -> str | None:
    """Apply one marker to ``scene``; None when applied, else why it was refused."""
    key = (marker.ns, int(marker.id))
    action = int(marker.action)
    if action == MarkerAction.DELETEALL:
        scene.clear()
        return None
    if action == MarkerAction.DELETE:
        scene.delete(key)
        return None
    if action != MarkerAction.ADD:
        return f"marker {marker.ns!r}/{marker.id}: action {action}; valid: ADD 0, DELETE 2, DELETEALL 3"
    problem = frame_problem(marker.header.frame_id, base_frame, f"marker {marker.ns!r}/{marker.id}")
    if problem is not None:
        return problem
    try:
        marker_type = MarkerType(int(marker.type))
    except ValueError:
        valid = ", ".join(f"{t.name} {t.value}" for t in MarkerType)
        return f"marker {marker.ns!r}/{marker.id}: type {marker.type}; valid: {valid}"
    try:
        pose = pose_to_matrix(marker.pose)
        scale = (marker.scale.x, marker.scale.y, marker.scale.z)
        scene.add(make_obstacle(key, SHAPE_OF_MARKER[marker_type], scale, pose, marker.mesh_resource))
    except (SceneUpdateError, InvalidMessageError) as error:
        return str(error)
    return None


def apply_marker_array(scene: Scene, msg: MarkerArray, base_frame: str) -> list[str]:
    """Apply every marker in order; returns the reasons of those refused (empty: all applied)."""
    problems = []
    for marker in msg.markers:
        problem = apply_marker(scene, marker, base_frame)
        if problem is not None:
            problems.append(problem)
    return problems
