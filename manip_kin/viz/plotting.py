"""Figures of a recorded run for a person to read (``manip_kin plot``).

:func:`load_run` turns a recording into plain arrays (no plotting, testable);
:func:`plot_run` draws the figures with matplotlib's non-interactive Agg backend:

* ``tool_position.png``: tool position vs its reference (goal pose) over time
* ``errors.png``: position and orientation error norms, log scale
* ``velocities.png``: tool and end-effector linear and angular speed
* ``joint_positions.png``: every joint with its position limits
* ``joint_rate_commands.png``: the joint-rate commands
* ``path_3d.png``: the tool path against the planned line, and the arm at a few instants
  (drawn from the recording's ``/tf`` when it has one, else from the model's kinematics)
* ``arm_tf.png`` (recordings with ``/tf``): the arm at a few instants, from TF alone

An animation of the arm (:func:`manip_kin.viz.arm_animation.write_animation`) is ``manip_kin plot
--gif`` / ``--mp4``.

Times are seconds since the first message of the run (receive time).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.core.rotations import matrix_to_rotvec, quat_to_matrix
from manip_kin.errors import ManipKinError
from manip_kin.viz.arm_animation import ArmFrames, draw_arm_picture, load_arm_frames
from manip_kin.viz.figure_axes import equal_3d_axes

FIGURES = (
    "tool_position.png",
    "errors.png",
    "velocities.png",
    "joint_positions.png",
    "joint_rate_commands.png",
    "path_3d.png",
)
TF_FIGURE = "arm_tf.png"
#: The topics plotted and the type each must have; a topic of another type is not read.
PLOTTED_TOPIC_TYPES = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/joint_velocity_commands": "std_msgs/msg/Float64MultiArray",
    "/tool_pose": "geometry_msgs/msg/PoseStamped",
    "/ee_pose": "geometry_msgs/msg/PoseStamped",
    "/goal_pose": "geometry_msgs/msg/PoseStamped",
    "/tool_twist": "geometry_msgs/msg/TwistStamped",
    "/ee_twist": "geometry_msgs/msg/TwistStamped",
    "/planned_path": "nav_msgs/msg/Path",
    "/robot_description": "std_msgs/msg/String",
}


@dataclass
class PoseSeries:
    """Stamped poses: time [s] shape (N,), position [m] shape (N, 3), quaternion xyzw shape (N, 4)."""

    time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    position: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    quaternion: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))


@dataclass
class TwistSeries:
    """Stamped twists: time [s] (N,), angular [rad/s] (N, 3), linear [m/s] (N, 3)."""

    time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    angular: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    linear: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass
class RunData:
    """Everything the figures need from one recording, as arrays.

    Attributes:
        joint_names: from the first JointState.
        joint_time: [s], shape (N,); joint_position shape (N, n) [rad | m].
        command_time: [s], shape (M,); command shape (M, n) [rad/s | m/s].
        tool, goal, ee: pose series; tool_twist, ee_twist: twist series.
        planned_paths: each planned line as positions, shape (K, 3).
        robot_description: the URDF published by robot_state ('' if not recorded).
        arm: the frames of the recording's TF over time, or None without ``/tf``.
        found_by_type: plotted topic -> the recorded topic read for it, where that was
            found by its type (remapped, e.g. to a ros2_control controller's topic).
    """

    joint_names: list[str] = field(default_factory=list)
    joint_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    joint_position: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    command_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    tool: PoseSeries = field(default_factory=PoseSeries)
    goal: PoseSeries = field(default_factory=PoseSeries)
    ee: PoseSeries = field(default_factory=PoseSeries)
    tool_twist: TwistSeries = field(default_factory=TwistSeries)
    ee_twist: TwistSeries = field(default_factory=TwistSeries)
    planned_paths: list[np.ndarray] = field(default_factory=list)
    robot_description: str = ""
    arm: ArmFrames | None = None
    found_by_type: dict[str, str] = field(default_factory=dict)


def _pose_series(samples: list[tuple[float, object]]) -> PoseSeries:
    if not samples:
        return PoseSeries()
    time = np.array([t for t, _ in samples])
    position = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for _, m in samples])
    quaternion = np.array(
        [[m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w] for _, m in samples]
    )
    return PoseSeries(time, position, quaternion)


def _twist_series(samples: list[tuple[float, object]]) -> TwistSeries:
    if not samples:
        return TwistSeries()
    time = np.array([t for t, _ in samples])
    angular = np.array([[m.twist.angular.x, m.twist.angular.y, m.twist.angular.z] for _, m in samples])
    linear = np.array([[m.twist.linear.x, m.twist.linear.y, m.twist.linear.z] for _, m in samples])
    return TwistSeries(time, angular, linear)


def plotted_topics(recorded: dict[str, str], prefix: str = "") -> dict[str, str]:
    """Recorded topic -> the plotted topic it is read as, from the recording's topic types.

    A plotted topic is read under its own name (in ``prefix``) when it has the expected type.
    When that name is absent, a type that only one plotted topic has (JointState,
    Float64MultiArray, Path, String) is looked up by type: the one recorded topic of that type
    not already read is used (the commands remapped to ``/forward_velocity_controller/commands``).
    Poses and twists, of which several are plotted, are read by name only.

    Args:
        recorded: every recorded topic name -> its type (``pkg/msg/Type``).
        prefix: the pipeline's namespace (``/left``) or "".
    """
    chosen = {
        prefix + name: name
        for name, type_name in PLOTTED_TOPIC_TYPES.items()
        if recorded.get(prefix + name) == type_name
    }
    named = {prefix + name for name in PLOTTED_TOPIC_TYPES}  # never read as another plotted topic
    type_counts: dict[str, int] = {}
    for type_name in PLOTTED_TOPIC_TYPES.values():
        type_counts[type_name] = type_counts.get(type_name, 0) + 1
    for name, type_name in PLOTTED_TOPIC_TYPES.items():
        if prefix + name in recorded or type_counts[type_name] != 1:
            continue
        candidates = [
            topic for topic, t in recorded.items() if t == type_name and topic not in chosen and topic not in named
        ]
        if len(candidates) == 1:
            chosen[candidates[0]] = name
    return chosen


def load_run(path: str | Path, namespace: str = "") -> RunData:
    """Read a recording (``.mcap`` file or bag directory) into :class:`RunData`.

    ``namespace`` selects the pipeline (``/left`` reads ``/left/joint_states``...). Topics are
    matched by name and type (:func:`plotted_topics`).
    """
    from manip_kin.pipeline.status import normalize_namespace
    from manip_kin.recording import RecordingError, read_info, read_messages

    prefix = normalize_namespace(namespace)
    recorded = {topic.name: topic.type for topic in read_info(path).topics}
    chosen = plotted_topics(recorded, prefix)

    by_topic: dict[str, list[tuple[int, object]]] = {}
    for topic, message, log_time_ns, _publish_ns in read_messages(path, topics=list(chosen)):
        by_topic.setdefault(chosen[topic], []).append((log_time_ns, message))
    if not by_topic:
        expected = ", ".join(prefix + name for name in PLOTTED_TOPIC_TYPES)
        raise RecordingError(
            f"{path}: the recording holds no messages on a plotted topic ({expected}); nothing to plot"
        )
    start_ns = min(samples[0][0] for samples in by_topic.values())

    def seconds(topic: str) -> list[tuple[float, object]]:
        return [((t - start_ns) * 1e-9, m) for t, m in by_topic.get(topic, [])]

    run = RunData()
    run.found_by_type = {name: topic for topic, name in chosen.items() if topic != prefix + name}
    joint_samples = [(t, m) for t, m in seconds("/joint_states") if len(m.position)]
    if joint_samples:
        run.joint_names = list(joint_samples[0][1].name)
        width = len(run.joint_names)
        joint_samples = [(t, m) for t, m in joint_samples if len(m.position) == width]
        run.joint_time = np.array([t for t, _ in joint_samples])
        run.joint_position = np.array([list(m.position) for _, m in joint_samples])
    command_samples = seconds("/joint_velocity_commands")
    if command_samples:
        width = len(command_samples[0][1].data)
        command_samples = [(t, m) for t, m in command_samples if len(m.data) == width]
        run.command_time = np.array([t for t, _ in command_samples])
        run.command = np.array([list(m.data) for _, m in command_samples])
    run.tool = _pose_series(seconds("/tool_pose"))
    run.ee = _pose_series(seconds("/ee_pose"))
    run.goal = _pose_series(seconds("/goal_pose"))
    run.tool_twist = _twist_series(seconds("/tool_twist"))
    run.ee_twist = _twist_series(seconds("/ee_twist"))
    for _, message in seconds("/planned_path"):
        points = [[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in message.poses]
        if points:
            run.planned_paths.append(np.array(points))
    descriptions = seconds("/robot_description")
    if descriptions:
        run.robot_description = descriptions[-1][1].data
    run.arm = load_arm_frames(path)
    return run


def tracking_errors(run: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Error of the tool against the latest goal at each tool sample.

    Returns:
        time [s] (K,), position error norm [m] (K,), orientation error angle [rad] (K,),
        for the tool samples that come after the first goal.
    """
    if not len(run.goal.time) or not len(run.tool.time):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    latest_goal = np.searchsorted(run.goal.time, run.tool.time, side="right") - 1
    valid = latest_goal >= 0
    goal_index = latest_goal[valid]
    position_error = np.linalg.norm(run.goal.position[goal_index] - run.tool.position[valid], axis=1)
    orientation_error = np.array(
        [
            np.linalg.norm(matrix_to_rotvec(quat_to_matrix(t).T @ quat_to_matrix(g)))
            for t, g in zip(run.tool.quaternion[valid], run.goal.quaternion[goal_index])
        ]
    )
    return run.tool.time[valid], position_error, orientation_error


def _model_from_description(run: RunData):
    if not run.robot_description:
        return None
    from manip_kin.core.urdf import load_urdf_string

    try:
        return load_urdf_string(run.robot_description, source="/robot_description")
    except ManipKinError:
        return None


def _legend(axis, **options) -> None:
    """A legend when ``axis`` holds a labelled artist (matplotlib warns about an empty one, as
    for a recording without ``/joint_velocity_commands``)."""
    if axis.get_legend_handles_labels()[1]:
        axis.legend(**options)


def plot_run(run: RunData, out_dir: str | Path, title: str = "") -> list[Path]:
    """Write every figure of :data:`FIGURES` for ``run`` into ``out_dir``; returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    prefix = f"{title}: " if title else ""
    written = []
    model = _model_from_description(run)

    def save(figure, name):
        figure.tight_layout()
        path = out_dir / name
        figure.savefig(path, dpi=110)
        plt.close(figure)
        written.append(path)

    # 1. tool position vs reference
    figure, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for i, axis_name in enumerate("xyz"):
        axes[i].plot(run.tool.time, run.tool.position[:, i], label=f"tool {axis_name}")
        if len(run.goal.time):
            axes[i].step(
                run.goal.time, run.goal.position[:, i], where="post", linestyle="--", label=f"reference {axis_name}"
            )
        axes[i].set_ylabel(f"{axis_name} [m]")
        _legend(axes[i], loc="best", fontsize="small")
        axes[i].grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(f"{prefix}tool position vs reference (base frame)")
    save(figure, "tool_position.png")

    # 2. error norms
    time, position_error, orientation_error = tracking_errors(run)
    figure, axis = plt.subplots(figsize=(9, 4.5))
    floor = 1e-12  # log scale cannot show an exact zero
    axis.semilogy(time, np.maximum(position_error, floor), label="position error [m]")
    axis.semilogy(time, np.maximum(orientation_error, floor), label="orientation error [rad]")
    axis.set_xlabel("time [s]")
    axis.set_ylabel("error norm")
    axis.set_title(f"{prefix}tool error against the current goal")
    axis.grid(True, which="both", alpha=0.3)
    _legend(axis)
    save(figure, "errors.png")

    # 3. velocities
    figure, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for series, label in ((run.tool_twist, "tool"), (run.ee_twist, "end effector")):
        axes[0].plot(series.time, np.linalg.norm(series.linear, axis=1) if len(series.time) else [], label=label)
        axes[1].plot(series.time, np.linalg.norm(series.angular, axis=1) if len(series.time) else [], label=label)
    axes[0].set_ylabel("linear speed [m/s]")
    axes[1].set_ylabel("angular speed [rad/s]")
    axes[1].set_xlabel("time [s]")
    axes[0].set_title(f"{prefix}tool and end-effector velocity w.r.t. base")
    for axis in axes:
        axis.grid(True, alpha=0.3)
        _legend(axis, loc="best", fontsize="small")
    save(figure, "velocities.png")

    # 4. joint positions with limits
    count = len(run.joint_names)
    columns = 2
    rows = max(1, (count + columns - 1) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(10, 2.2 * rows + 0.6), sharex=True, squeeze=False)
    limits = {}
    if model is not None:
        limits = {j.name: (j.lower, j.upper, j.is_revolute) for j in model.joints}
    for index, name in enumerate(run.joint_names):
        axis = axes[index // columns][index % columns]
        axis.plot(run.joint_time, run.joint_position[:, index], label=name)
        unit = "rad"
        if name in limits:
            lower, upper, revolute = limits[name]
            unit = "rad" if revolute else "m"
            for bound in (lower, upper):
                if np.isfinite(bound) and abs(bound) < 1e5:
                    axis.axhline(bound, color="red", linestyle=":", linewidth=1)
        axis.set_ylabel(f"{name} [{unit}]")
        axis.grid(True, alpha=0.3)
    for index in range(count, rows * columns):
        axes[index // columns][index % columns].axis("off")
    for axis in axes[-1]:
        axis.set_xlabel("time [s]")
    figure.suptitle(f"{prefix}joint positions (dotted red: position limits)")
    save(figure, "joint_positions.png")

    # 5. joint-rate commands
    figure, axis = plt.subplots(figsize=(9, 4.5))
    for index in range(run.command.shape[1] if run.command.ndim == 2 else 0):
        label = run.joint_names[index] if index < len(run.joint_names) else f"joint {index + 1}"
        axis.plot(run.command_time, run.command[:, index], label=label)
    axis.set_xlabel("time [s]")
    axis.set_ylabel("commanded rate [rad/s | m/s]")
    axis.set_title(f"{prefix}joint-rate commands (/joint_velocity_commands)")
    axis.grid(True, alpha=0.3)
    if not len(run.command_time):
        axis.text(0.5, 0.5, "no /joint_velocity_commands in this recording", transform=axis.transAxes, ha="center")
    _legend(axis, loc="best", fontsize="small", ncol=2)
    save(figure, "joint_rate_commands.png")

    # 6. 3D path and arm snapshots
    figure = plt.figure(figsize=(8, 7))
    axis = figure.add_subplot(projection="3d")
    drawn = []  # every plotted point, for equal axis scales
    if run.arm is not None:
        arm = run.arm
        instants = np.unique(np.linspace(0, len(arm.time) - 1, 5).astype(int))
        for k, sample in enumerate(instants):
            shade = 0.2 + 0.6 * k / max(1, len(instants) - 1)
            for e, (parent, child) in enumerate(arm.edges):
                segment = arm.positions[sample, [parent, child]]
                label = f"arm (/tf) at t = {arm.time[sample]:.1f} s" if e == 0 else None
                axis.plot(*segment.T, color=(shade, shade, shade), linewidth=1.5, label=label)
            axis.plot(*arm.positions[sample].T, linestyle="", marker="o", markersize=3, color=(shade, shade, shade))
            drawn.append(arm.positions[sample])
    elif model is not None and len(run.joint_time):
        from manip_kin.core.kinematics import frame_poses

        instants = np.unique(np.linspace(0, len(run.joint_time) - 1, 5).astype(int))
        for k, sample in enumerate(instants):
            q = run.joint_position[sample]
            if q.shape[0] != model.dof:
                break
            origins = frame_poses(model, q)[:, :3, 3]
            shade = 0.2 + 0.6 * k / max(1, len(instants) - 1)
            axis.plot(
                *origins.T,
                marker="o",
                markersize=3,
                color=(shade, shade, shade),
                linewidth=1.5,
                label=f"arm at t = {run.joint_time[sample]:.1f} s",
            )
            drawn.append(origins)
    if len(run.goal.time):
        axis.scatter(*run.goal.position.T, s=2, color="tab:green", alpha=0.2, label="goal poses")
    if len(run.tool.time):
        axis.plot(*run.tool.position.T, label="tool path", color="tab:blue", linewidth=2.5)
        drawn.append(run.tool.position)
    for k, line in enumerate(run.planned_paths):
        axis.plot(*line.T, linestyle="--", color="tab:orange", linewidth=2, label="planned line" if k == 0 else None)
    if drawn:
        # Equal scales on x, y and z, so a straight line and the arm's proportions look as they are.
        equal_3d_axes(axis, np.vstack(drawn))
    axis.set_title(f"{prefix}tool path, planned line and arm (base frame)")
    _legend(axis, loc="upper left", fontsize="small")
    save(figure, "path_3d.png")

    if run.arm is not None:
        written.append(draw_arm_picture(run.arm, out_dir / TF_FIGURE, title=f"{prefix}arm from /tf"))
    return written
