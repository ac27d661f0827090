"""``cartesian_controller``'s interface: its name, states, parameters (with units and checks) and ``--help``.

Kept apart from the node so the table can be read (and documented) on its own.
"""

from __future__ import annotations

import math

from manip_kin.control.state_machines import ControllerState
from manip_kin.ros.nodes.collision_params import COLLISION_PARAMETERS
from manip_kin.ros.nodes.joint_limit_params import HELP_LINE
from manip_kin.ros.nodes.robot_model import model_parameters
from manip_kin.ros.runtime.param_struct import param_struct
from manip_kin.ros.runtime.params import REALTIME_PRIORITY, SCHEDULER_SLICE, ParamSpec, diagnostics_rate, loop_rate
from manip_kin.ros.runtime.usage import usage_text

NODE_NAME = "cartesian_controller"

#: Controller states reported as the DiagnosticStatus message and the ``state`` value.
STATES = tuple(state.value for state in ControllerState)

PARAMETERS = (
    *model_parameters(""),
    loop_rate("control and command rate"),
    # Gains: the sampled law e(k+1) = (1 - K dt) e(k) needs K dt < 2; 1000 1/s keeps that up to
    # 2 kHz and leaves every output finite (the rates are then bounded by the velocity limits).
    ParamSpec("gain_angular", "float", 0.8, "orientation gain K_o", "1/s", minimum=0.0, maximum=1e3, tunable=True),
    ParamSpec("gain_linear", "float", 0.8, "position gain K_p", "1/s", minimum=0.0, maximum=1e3, tunable=True),
    ParamSpec(
        "frame", "str", "", "controlled frame: tool, ee, a joint number or a link name ('' = tool if any, else ee)"
    ),
    ParamSpec(
        "task",
        "str",
        "",
        "controlled error components: full, position, position_yaw, orientation or e.g. 'rz,x,y,z' ('' = full for 6+ joints)",
    ),
    # lambda and epsilon are in the unit of the Jacobian's singular values (about the arm's
    # size in m): beyond 10 an arm of metres would barely move (and lambda^2 stays far from an
    # overflow); below 1e-6 the damping would act only within rounding noise of a singularity.
    ParamSpec(
        "damping_max",
        "float",
        0.04,
        "damping lambda at an exact singularity",
        minimum=0.0,
        maximum=10.0,
        tunable=True,
    ),
    ParamSpec(
        "singular_threshold",
        "float",
        0.02,
        "smallest singular value below which damping rises",
        minimum=1e-6,
        maximum=10.0,
        tunable=True,
    ),
    ParamSpec("respect_velocity_limits", "bool", True, "scale the joint rates into the velocity limits", tunable=True),
    ParamSpec(
        "respect_position_limits",
        "bool",
        True,
        "redistribute the task over joints not at a position limit",
        tunable=True,
    ),
    ParamSpec("base_frame", "str", "", "frame id goals must carry ('' = the robot's base frame, base_link)"),
    # Timeouts: 1 ms (one period at 1 kHz) to a minute; 0 would make every input stale.
    ParamSpec(
        "joint_state_timeout",
        "float",
        0.1,
        "no joint state for longer than this: publish zeros",
        "s",
        minimum=1e-3,
        maximum=60.0,
        tunable=True,
    ),
    # A day at most: longer is 'never', which is 0.
    ParamSpec(
        "goal_timeout",
        "float",
        0.0,
        "a goal older than this is dropped and zeros published (0 = goals never expire)",
        "s",
        minimum=0.0,
        maximum=86400.0,
        tunable=True,
    ),
    ParamSpec(
        "goal_twist_timeout",
        "float",
        0.02,
        "the feed-forward twist is used while younger than this (short: a stalled stream must not carry the arm on)",
        "s",
        minimum=1e-3,
        maximum=60.0,
        tunable=True,
    ),
    ParamSpec(
        "predict_state",
        "bool",
        True,
        "run the law on the joint state predicted (from its velocities and stamp) for the period the "
        "command will drive, compensating the state-command-robot delay; a streamed goal (goal_pose with "
        "goal_twist, joint_reference) is moved by its stamp to the same instant",
        tunable=True,
    ),
    # A delay of a second is no real-time command path; the prediction extrapolates over it.
    ParamSpec(
        "command_latency",
        "float",
        0.0003,
        "for predict_state: time from publishing a command until the robot holds it "
        "(add one robot period for a robot that stamps its state before applying that cycle's command)",
        "s",
        minimum=0.0,
        maximum=1.0,
        tunable=True,
    ),
    # Tolerances: from a nanometre/nanoradian (below float rounding of a pose) to a metre / half a turn.
    ParamSpec(
        "position_tolerance",
        "float",
        1e-4,
        "converged when the position error is below this",
        "m",
        minimum=1e-9,
        maximum=1.0,
        tunable=True,
    ),
    ParamSpec(
        "orientation_tolerance",
        "float",
        1e-3,
        "... and the orientation error below this",
        "rad",
        minimum=1e-9,
        maximum=math.pi,
        tunable=True,
    ),
    # As the cartesian gains: K dt < 2 for the sampled joint law up to 2 kHz.
    ParamSpec(
        "gain_joint",
        "float",
        20.0,
        "joint-space gain K on q_ref - q when following a joint reference (plus its velocity)",
        "1/s",
        minimum=0.0,
        maximum=1e3,
        tunable=True,
    ),
    ParamSpec(
        "joint_tolerance",
        "float",
        1e-3,
        "converged on a joint reference when every joint is within this of it",
        "rad | m",
        minimum=1e-9,
        maximum=1.0,
        tunable=True,
    ),
    # Below 1, so a zero quaternion (no rotation at all) can never pass; 1e-9 is above double rounding.
    ParamSpec(
        "quaternion_tolerance",
        "float",
        1e-2,
        "a goal quaternion whose length differs from 1 by more is rejected",
        minimum=1e-9,
        maximum=0.5,
        tunable=True,
    ),
    ParamSpec(
        "stop_time",
        "float",
        1.0,
        "longest a halt may take: on exit, ~/stop, ~/pause and faults the commands come to rest within the "
        "deceleration and jerk limits, and are zero after this at the latest",
        "s",
        minimum=0.01,
        maximum=60.0,
        tunable=True,
    ),
    ParamSpec(
        "progress_window",
        "float",
        0.5,
        "a resting goal whose error falls by less than 2 % in this long, with the arm singular or at joint "
        "limits, is unreachable (the commands come to rest)",
        "s",
        minimum=0.05,
        maximum=10.0,
        tunable=True,
    ),
    diagnostics_rate(10.0, "rate of /diagnostics (also sent at once on a state change)"),
    # MoveIt Servo's incoming_command_timeout is 0.1 s; a teleop stream comes at 50 Hz or more.
    ParamSpec(
        "command_timeout",
        "float",
        0.1,
        "a twist_command or joint_jog older than this halts the arm (smoothly, within the limits)",
        "s",
        minimum=1e-3,
        maximum=60.0,
        tunable=True,
    ),
    # Smallest singular values of the task Jacobian, as singular_threshold (manip_kin.control.servo).
    ParamSpec(
        "singularity_slowdown_start",
        "float",
        0.05,
        "twist commands that move towards a singularity slow down once the task Jacobian's smallest singular "
        "value is below this",
        minimum=1e-6,
        maximum=10.0,
        tunable=True,
    ),
    ParamSpec(
        "singularity_hard_stop",
        "float",
        0.01,
        "... and stop at this one (motion away from the singularity is never slowed); below the start",
        minimum=1e-7,
        maximum=10.0,
        tunable=True,
    ),
    *COLLISION_PARAMETERS,
    REALTIME_PRIORITY,
    SCHEDULER_SLICE,
)

#: The parameters as a typed struct (what the node reads; the joint_limits.* group is in its ``dynamic``).
ControllerParams = param_struct(
    "ControllerParams", PARAMETERS, "cartesian_controller's parameters, typed (docs/interfaces.md)."
)

USAGE = usage_text(
    NODE_NAME,
    "Resolved-rate cartesian controller: drives the controlled frame (tool if any, else end\n"
    "effector) to the latest goal_pose with joint-rate commands at rate_hz, adding the\n"
    "goal_twist feed-forward while it is fresh. A goal with a non-finite value, a quaternion far\n"
    "from unit length or a frame other than the base frame is rejected (previous goal kept).\n"
    "A joint_reference (positions + velocities by joint name) is followed in joint space\n"
    "instead (q_dot = q_dot_ref + gain_joint (q_ref - q), within the limits); the latest goal\n"
    "of either kind wins. Convergence counts only the task's components.\n"
    "Every command obeys joint_limits.<joint>.* (velocity, acceleration, jerk; ros2_control's\n"
    "layout): without a goal, without a fresh joint state, paused (~/pause), stopped (~/stop),\n"
    "at an unreachable goal and on exit, the commands come to rest within them (at most\n"
    "stop_time), and the last command before exit is an exact zero.\n"
    "With robot '' the model is the URDF on robot_description (robot_description_publisher picks\n"
    "one of several); a later, different one is logged, and the service\n"
    "~/reload_robot_description (std_srvs/Trigger) switches to it when its joints are the same.\n"
    "With collision_avoidance (a URDF robot) pose goals, twist commands, joint references and jogs\n"
    "run a QP law that keeps every checked pair collision_safety_distance apart; a pose goal or\n"
    "joint reference it holds off ends 'blocked'.\n"
    f"States on /diagnostics: {', '.join(STATES)}.",
    PARAMETERS,
    extra_help=HELP_LINE,
    services=[
        ("~/stop", "std_srvs/Trigger", "smooth halt within the limits; the goal is dropped"),
        ("~/pause", "std_srvs/SetBool", "true: hold still within the limits, the goal kept; false: resume"),
    ],
    subscribes=[
        ("goal_pose", "geometry_msgs/PoseStamped", "goal of the controlled frame, frame_id = base frame"),
        ("goal_twist", "geometry_msgs/TwistStamped", "feed-forward velocity of the goal, base frame"),
        ("joint_reference", "sensor_msgs/JointState", "joint positions + velocities to follow (trajectory_generator)"),
        (
            "twist_command",
            "geometry_msgs/TwistStamped",
            "velocity of the controlled frame, in frame_id (base, the frame, a link)",
        ),
        ("joint_jog", "sensor_msgs/JointState", "names + velocities of any joints to jog"),
        ("joint_states", "sensor_msgs/JointState", "matched to the model by joint name"),
        (
            "collision_objects",
            "visualization_msgs/MarkerArray",
            "obstacles in the base frame (CUBE, SPHERE, CYLINDER, MESH_RESOURCE; collision_avoidance)",
        ),
    ],
    publishes=[
        ("joint_velocity_commands", "std_msgs/Float64MultiArray", "joint rates [rad/s | m/s], model joint order"),
        (
            "/diagnostics",
            "diagnostic_msgs/DiagnosticArray",
            "state, errors [m, rad], manipulability, damping, limits, nearest pair, loop timing",
        ),
        ("markers", "visualization_msgs/MarkerArray", "the nearest pair's witness points (collision_avoidance)"),
    ],
    example=f"{NODE_NAME} --ros-args -p robot:=genova7 -p rate_hz:=1000 -p gain_linear:=1.5",
)
