"""A recorded run as plain arrays (:func:`load_run`: no plotting, testable): the poses, twists,
joint states and commands of the topics plotted, the planned path, the robot description, the
arm's frames from ``/tf``; and the tracking errors of the tool against its goal.

Times are seconds since the first message of the run (receive time).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.core.rotations import matrix_to_rotvec, quat_to_matrix
from manip_kin.errors import ManipKinError
from manip_kin.viz.arm_animation import ArmFrames, load_arm_frames

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


def model_from_description(run: RunData):
    if not run.robot_description:
        return None
    from manip_kin.core.urdf import load_urdf_string

    try:
        return load_urdf_string(run.robot_description, source="/robot_description")
    except ManipKinError:
        return None
