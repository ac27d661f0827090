"""``collision.png`` of ``manip_kin plot``: the arm, the obstacles and the nearest pair of a recorded run.

Drawn when the recording holds the controller's collision status (``nearest_pair`` on
``/diagnostics``, from a ``cartesian_controller`` with ``collision_avoidance``):

* left, in 3D: the arm (from the recording's ``/tf``, else from ``robot_description`` and the
  joint states) at the start and at the nearest approach,
  the obstacles of ``collision_objects`` at the end of the run (boxes, spheres and cylinders as
  wireframes, a mesh as a box of its scale), and the nearest pair's witness points joined by
  a line at the nearest approach;
* right: the nearest distance over time.

:func:`load_nearest` reads the status into arrays (testable without matplotlib).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.viz.arm_animation import ArmFrames, draw_arm, set_arm_view

FIGURE = "collision.png"


@dataclass
class NearestSeries:
    """The controller's nearest pair over a run.

    Attributes:
        time: seconds since the first ``/diagnostics`` message, shape (N,).
        pair: the pair's label at each sample, ``first-second``.
        distance: its distance [m], shape (N,).
        points: the witness points on the first and second shape [m], shape (N, 2, 3).
    """

    time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pair: list[str] = field(default_factory=list)
    distance: np.ndarray = field(default_factory=lambda: np.zeros(0))
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    safety_distance: float | None = None


def load_nearest(path: str | Path, namespace: str = "") -> NearestSeries:
    """The nearest pair from the controller's statuses in ``namespace`` (empty when there are none)."""
    from manip_kin.pipeline.status import normalize_namespace
    from manip_kin.recording import read_messages

    name = (normalize_namespace(namespace) + "/cartesian_controller").lstrip("/")
    rows = []
    first_ns = None
    safety = ""
    for _topic, message, log_ns, _publish_ns in read_messages(path, topics=["/diagnostics"]):
        first_ns = log_ns if first_ns is None else first_ns
        for status in message.status:
            if status.name != name:
                continue
            values = {kv.key: kv.value for kv in status.values}
            numbers = values.get("nearest_points", "").split()
            if not values.get("nearest_pair") or len(numbers) != 6:
                continue
            try:
                points = np.array([float(v) for v in numbers]).reshape(2, 3)
                distance = float(values["nearest_distance"])
            except (KeyError, ValueError):
                continue  # a status this version did not write: left out
            rows.append(((log_ns - first_ns) * 1e-9, values["nearest_pair"], distance, points))
            safety = values.get("collision_safety_distance", "") or safety
    if not rows:
        return NearestSeries()
    return NearestSeries(
        np.array([r[0] for r in rows]),
        [r[1] for r in rows],
        np.array([r[2] for r in rows]),
        np.array([r[3] for r in rows]),
        float(safety) if safety else None,
    )


def _box_edges(half: np.ndarray, pose: np.ndarray) -> list[np.ndarray]:
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    world = corners @ pose[:3, :3].T + pose[:3, 3]
    edges = []
    for a in range(8):
        for b in range(a + 1, 8):
            if bin(a ^ b).count("1") == 1:  # corners that differ in one axis
                edges.append(world[[a, b]])
    return edges


def _draw_obstacle(axis, obstacle, colour) -> np.ndarray:
    """Wireframe of one obstacle; returns points that bound it (for the view)."""
    pose = obstacle.pose_in_base
    shape = str(obstacle.shape)
    if shape == "sphere" or shape == "cylinder":
        u = np.linspace(0, 2 * np.pi, 25)
        r = obstacle.radius
        if shape == "sphere":
            v = np.linspace(0, np.pi, 13)
            local = (
                np.stack(
                    [
                        np.outer(np.cos(u), np.sin(v)),
                        np.outer(np.sin(u), np.sin(v)),
                        np.outer(np.ones_like(u), np.cos(v)),
                    ],
                    -1,
                )
                * r
            )
        else:
            z = np.array([-0.5, 0.5]) * obstacle.height
            local = np.stack(
                [
                    np.outer(np.cos(u), np.ones(2)) * r,
                    np.outer(np.sin(u), np.ones(2)) * r,
                    np.outer(np.ones_like(u), z),
                ],
                -1,
            )
        world = local @ pose[:3, :3].T + pose[:3, 3]
        axis.plot_wireframe(world[..., 0], world[..., 1], world[..., 2], color=colour, linewidth=0.6)
        return world.reshape(-1, 3)
    half = np.array(obstacle.half_extents if shape == "box" else (0.5 * np.array(obstacle.scale)))
    edges = _box_edges(half, pose)
    for edge in edges:
        axis.plot(*edge.T, color=colour, linewidth=1.0)
    return np.vstack(edges)


def arm_from_joint_states(run) -> ArmFrames | None:
    """The arm's frame origins from ``robot_description`` and the joint states of a
    :class:`~manip_kin.viz.run_data.RunData` (for a recording without ``/tf``), or None."""
    from manip_kin.core.kinematics import frame_poses
    from manip_kin.core.urdf import load_urdf_string
    from manip_kin.errors import ManipKinError

    if not run.robot_description or not len(run.joint_time):
        return None
    try:
        model = load_urdf_string(run.robot_description, source="/robot_description")
    except ManipKinError:
        return None
    by_name = [run.joint_names.index(name) for name in model.joint_names if name in run.joint_names]
    if len(by_name) != model.dof:
        return None
    positions = np.array([frame_poses(model, q[by_name])[: model.dof + 2, :3, 3] for q in run.joint_position])
    frames = ("base", *model.joint_names, "ee")
    edges = tuple((k, k + 1) for k in range(len(frames) - 1))
    return ArmFrames(run.joint_time, np.zeros(len(run.joint_time), dtype=np.int64), frames, positions, edges)


def plot_collision(arm: ArmFrames | None, scene, nearest: NearestSeries, out: str | Path, title: str = "") -> Path:
    """Write the figure (see the module docstring) to ``out``; returns its path.

    Args:
        arm: the arm over time (:func:`~manip_kin.viz.arm_animation.load_arm_frames` or
            :func:`arm_from_joint_states`), or None (not drawn).
        scene: the obstacles (:func:`manip_kin.viz.physics_render.recorded_scene`), or None.
        nearest: the controller's nearest pair (:func:`load_nearest`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure = plt.figure(figsize=(12, 6))
    axis = figure.add_subplot(1, 2, 1, projection="3d")
    bounds = [np.zeros((1, 3))]
    closest = int(np.argmin(nearest.distance)) if len(nearest.time) else None
    if arm is not None:
        draw_arm(axis, arm, 0, (0.7, 0.7, 0.8), f"arm at t = {arm.time[0]:.1f} s")
        at = len(arm.time) - 1
        if closest is not None:
            at = int(np.clip(np.searchsorted(arm.time, nearest.time[closest]), 0, len(arm.time) - 1))
        draw_arm(axis, arm, at, (0.2, 0.2, 0.35), f"arm at t = {arm.time[at]:.1f} s (nearest approach)")
        # The frame farthest from the root at the start stands for the tool: its path.
        tip = int(np.argmax(np.linalg.norm(arm.positions[0] - arm.positions[0, :1], axis=1)))
        axis.plot(*arm.positions[:, tip].T, color="tab:purple", linewidth=1.2, label=f"{arm.frames[tip]} path")
        bounds.append(arm.positions.reshape(-1, 3))
    for k, obstacle in enumerate(scene.obstacles if scene is not None else ()):
        bounds.append(_draw_obstacle(axis, obstacle, "tab:red"))
        axis.plot([], [], color="tab:red", label="obstacles" if k == 0 else None)
    if closest is not None:
        segment = nearest.points[closest]
        axis.plot(
            *segment.T,
            color="tab:green",
            linewidth=2.5,
            marker="o",
            markersize=4,
            label=f"nearest: {nearest.pair[closest]} {nearest.distance[closest]:.3f} m",
        )
        bounds.append(segment)
    set_arm_view(axis, np.vstack(bounds))
    axis.view_init(elev=20.0, azim=-50.0)  # obliquely: the obstacle's depth shows
    axis.set_title(f"{title}: arm, obstacles, nearest pair" if title else "arm, obstacles, nearest pair")
    axis.legend(loc="upper left", fontsize="small")
    distance_axis = figure.add_subplot(1, 2, 2)
    if len(nearest.time):
        distance_axis.plot(nearest.time, nearest.distance, color="tab:green", label="nearest pair distance")
        if nearest.safety_distance is not None:
            distance_axis.axhline(
                nearest.safety_distance, color="tab:red", linestyle="--", label="collision_safety_distance"
            )
        distance_axis.legend(loc="upper right", fontsize="small")
    distance_axis.set_xlabel("time [s]")
    distance_axis.set_ylabel("distance [m]")
    distance_axis.set_title("nearest checked pair (cartesian_controller, /diagnostics)")
    distance_axis.grid(True, alpha=0.3)
    figure.tight_layout()
    figure.savefig(out, dpi=80)
    plt.close(figure)
    return Path(out)
