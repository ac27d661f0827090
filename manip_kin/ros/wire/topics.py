"""The pipeline's topic names and types (docs/interfaces.md), without importing rclpy.

Names are relative, so ``--ros-args -r __ns:=/left`` moves a whole pipeline into ``/left``;
``/diagnostics`` stays global, as in ROS.
"""

from __future__ import annotations

#: Topic name → ROS type name, every topic a manip_kin pipeline uses.
PIPELINE_TOPIC_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState",
    "joint_velocity_commands": "std_msgs/msg/Float64MultiArray",
    "goal_pose": "geometry_msgs/msg/PoseStamped",
    "goal_twist": "geometry_msgs/msg/TwistStamped",
    "line_target": "geometry_msgs/msg/PoseStamped",
    "joint_trajectory": "trajectory_msgs/msg/JointTrajectory",
    "joint_reference": "sensor_msgs/msg/JointState",
    "twist_command": "geometry_msgs/msg/TwistStamped",
    "joint_jog": "sensor_msgs/msg/JointState",
    "collision_objects": "visualization_msgs/msg/MarkerArray",
    "planned_path": "nav_msgs/msg/Path",
    "ee_pose": "geometry_msgs/msg/PoseStamped",
    "tool_pose": "geometry_msgs/msg/PoseStamped",
    "ee_twist": "geometry_msgs/msg/TwistStamped",
    "tool_twist": "geometry_msgs/msg/TwistStamped",
    "robot_description": "std_msgs/msg/String",
    "markers": "visualization_msgs/msg/MarkerArray",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}

#: History depth of the publishers that stream every cycle (reliable, keep last). A reliable
#: writer drops its oldest unacknowledged sample once its history is full, so with depth 10 a
#: subscriber (a recorder, a test) starved for 10 ms at 1 kHz lost messages for good; 1000
#: keeps one second for it. Subscribers that want only the newest keep their own shallow queue.
STREAM_DEPTH = 1000


def latest_state_qos(depth: int):
    """QoS of a loop's subscription to a stream it only needs the newest sample of.

    Best effort, volatile, keep last ``depth`` (like rclpy's ``qos_profile_sensor_data``):
    the controller's ``joint_states``, robot_state's ``joint_velocity_commands``, the
    generator's ``joint_states``, robot_state's ``goal_pose`` for its
    markers. A sample resent after a loss would be older than the next one, which comes a
    cycle later anyway; and a reliable reader costs its writer a heartbeat-timer restart
    and a wake-up of the middleware's event thread on every sample (measured at 1 kHz:
    about 2 context switches a message in the writer's process). Reliable publishers match
    best-effort subscribers, so real hardware drivers and recorders are unaffected.
    Goals and references a user sends once stay reliable.
    """
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.BEST_EFFORT)
