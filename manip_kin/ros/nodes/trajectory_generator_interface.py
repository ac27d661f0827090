"""``trajectory_generator``'s interface: its name, states, parameters (with units and checks) and ``--help``.

Kept apart from the node so the table can be read (and documented) on its own.
"""

from __future__ import annotations

from manip_kin.control.generator_supervisor import GeneratorState
from manip_kin.motion.joint_trajectory import JOINT_TIME_SCALINGS
from manip_kin.motion.lines import TIME_SCALINGS
from manip_kin.ros.nodes.collision_params import PATH_CHECK_PARAMETERS
from manip_kin.ros.nodes.joint_limit_params import HELP_LINE
from manip_kin.ros.nodes.robot_model import model_parameters
from manip_kin.ros.runtime.param_struct import param_struct
from manip_kin.ros.runtime.params import REALTIME_PRIORITY, SCHEDULER_SLICE, ParamSpec, diagnostics_rate, loop_rate
from manip_kin.ros.runtime.usage import usage_text

NODE_NAME = "trajectory_generator"

#: States reported on /diagnostics.
STATES = tuple(state.value for state in GeneratorState)

PARAMETERS = (
    *model_parameters(""),
    loop_rate("rate of goal_pose and goal_twist while a line runs"),
    ParamSpec(
        "time_scaling", "str", "trapezoidal", "progress along the line over time", choices=TIME_SCALINGS, tunable=True
    ),
    ParamSpec(
        "joint_time_scaling",
        "str",
        "cubic",
        "interpolation between the points of a joint trajectory",
        choices=JOINT_TIME_SCALINGS,
        tunable=True,
    ),
    ParamSpec(
        "task",
        "str",
        "",
        "pose components a line must reach, as the controller's task: full, position, position_yaw, ... "
        "('' = full for 6+ joints)",
    ),
    # Motion limits: from 0.1 mm/s (a 2 m line then takes 6 h) to 10 m/s and 100 m/s^2 (beyond any
    # arm; the speeds are also capped at twice what this arm can do, see trajectory_generator_params.check_limits); the
    # angular ones from 1e-4 rad/s to 100 rad/s and 1000 rad/s^2; jerks from 0.01 to 1e4 m/s^3 and
    # 1e5 rad/s^3. The lower bounds keep durations finite.
    ParamSpec(
        "max_linear_velocity",
        "float",
        0.25,
        "speed limit of the position (the constant speed of 'constant')",
        "m/s",
        minimum=1e-4,
        maximum=10.0,
        tunable=True,
    ),
    ParamSpec(
        "max_linear_acceleration",
        "float",
        0.5,
        "acceleration limit of the position (not used by 'constant')",
        "m/s^2",
        minimum=1e-3,
        maximum=100.0,
        tunable=True,
    ),
    ParamSpec(
        "max_angular_velocity",
        "float",
        0.5,
        "angular speed limit of the orientation",
        "rad/s",
        minimum=1e-4,
        maximum=100.0,
        tunable=True,
    ),
    ParamSpec(
        "max_angular_acceleration",
        "float",
        1.0,
        "angular acceleration limit (not used by 'constant')",
        "rad/s^2",
        minimum=1e-3,
        maximum=1e3,
        tunable=True,
    ),
    ParamSpec(
        "max_linear_jerk",
        "float",
        5.0,
        "jerk limit of the position ('jerk_limited' only)",
        "m/s^3",
        minimum=1e-2,
        maximum=1e4,
        tunable=True,
    ),
    ParamSpec(
        "max_angular_jerk",
        "float",
        10.0,
        "angular jerk limit ('jerk_limited' only)",
        "rad/s^3",
        minimum=1e-2,
        maximum=1e5,
        tunable=True,
    ),
    ParamSpec("check_reach", "bool", True, "reject a line the arm cannot follow within its joint limits", tunable=True),
    ParamSpec(
        "base_frame", "str", "", "frame id of targets and published goals ('' = the robot's base frame, base_link)"
    ),
    # 1 ms (a period at 1 kHz) to a minute.
    ParamSpec(
        "joint_state_timeout",
        "float",
        0.5,
        "a target is rejected when the newest joint_states is older than this (by its stamp)",
        "s",
        minimum=1e-3,
        maximum=60.0,
        tunable=True,
    ),
    # Below 1, so a zero quaternion can never pass; 1e-9 is above double rounding.
    ParamSpec(
        "quaternion_tolerance",
        "float",
        1e-2,
        "a target quaternion whose length differs from 1 by more is rejected",
        minimum=1e-9,
        maximum=0.5,
        tunable=True,
    ),
    # A path needs its two ends; 10000 poses (about 1 MB) is far more than a viewer shows, and
    # the path is sampled in the loop when a motion starts.
    ParamSpec("path_points", "int", 50, "poses in planned_path", minimum=2, maximum=10000, tunable=True),
    diagnostics_rate(5.0, "rate of /diagnostics (also sent at once on a state change)"),
    *PATH_CHECK_PARAMETERS,
    REALTIME_PRIORITY,
    SCHEDULER_SLICE,
)

#: The parameters as a typed struct (what the node reads; the joint_limits.* group is in its ``dynamic``).
GeneratorParams = param_struct(
    "GeneratorParams", PARAMETERS, "trajectory_generator's parameters, typed (docs/interfaces.md)."
)

USAGE = usage_text(
    NODE_NAME,
    "Straight-line goals: on a line_target pose, plans a line from the current tool pose (FK\n"
    "of the newest joint_states; the end effector if the robot has no tool; position along\n"
    "the segment, orientation by slerp) timed by time_scaling within the velocity and\n"
    "acceleration limits (and the jerk limits with jerk_limited), checks the arm can\n"
    "follow it from that configuration, and streams goal_pose and goal_twist at rate_hz\n"
    "until the end, then publishes the final pose once and holds. A joint_trajectory (as ros2_control's\n"
    "JointTrajectoryController takes it) is interpolated with joint_time_scaling from the\n"
    "current joint_states and streamed as joint_reference, within joint_limits.<joint>.*\n"
    "(velocity, acceleration, jerk); a single point at time_from_start 0 is timed as fast as\n"
    "those limits allow. The latest goal of either kind pre-empts the running motion.\n"
    "Unreachable or malformed goals are rejected with a log line; with collision_check (a URDF\n"
    "robot) so is a motion through the arm itself or collision_objects, saying where and which pair.\n"
    "With robot '' the model is the URDF on robot_description (robot_description_publisher picks\n"
    "one of several); a later, different one is logged, and the service\n"
    "~/reload_robot_description (std_srvs/Trigger) switches to it when its joints are the same.",
    PARAMETERS,
    extra_help=HELP_LINE,
    services=[("~/stop", "std_srvs/Trigger", "stop streaming; the last goal sent is held")],
    subscribes=[
        ("line_target", "geometry_msgs/PoseStamped", "end pose of the line, frame_id = base frame"),
        ("joint_trajectory", "trajectory_msgs/JointTrajectory", "joint names, points with time_from_start"),
        ("joint_states", "sensor_msgs/JointState", "current configuration: start of a line or trajectory, reach check"),
        ("collision_objects", "visualization_msgs/MarkerArray", "obstacles in the base frame (collision_check)"),
    ],
    publishes=[
        ("goal_pose", "geometry_msgs/PoseStamped", "the line's pose at each cycle"),
        ("goal_twist", "geometry_msgs/TwistStamped", "the line's velocity (feed-forward)"),
        ("joint_reference", "sensor_msgs/JointState", "a joint trajectory's positions and velocities"),
        ("planned_path", "nav_msgs/Path", "the planned tool path, transient local"),
        ("/diagnostics", "diagnostic_msgs/DiagnosticArray", "state, progress, target and final goal stamps"),
    ],
    example=f"{NODE_NAME} --ros-args -p robot:=irb120 -p time_scaling:=constant -p max_linear_velocity:=0.4",
)
