"""``robot_state``'s interface: its name, parameters (with units and checks, and as a typed struct)
and ``--help``.

Kept apart from the node so the table can be read (and documented) on its own.
"""

from __future__ import annotations

from manip_kin.core.robots import bundled_robot_names
from manip_kin.ros.nodes.physics_params import PHYSICS_PARAMETERS
from manip_kin.ros.nodes.robot_model import model_parameters
from manip_kin.ros.runtime.param_struct import param_struct
from manip_kin.ros.runtime.params import REALTIME_PRIORITY, SCHEDULER_SLICE, ParamSpec, diagnostics_rate, loop_rate
from manip_kin.ros.runtime.usage import usage_text
from manip_kin.ros.wire.scene_messages import TOPIC as COLLISION_OBJECTS

NODE_NAME = "robot_state"

PARAMETERS = (
    *model_parameters("genova7"),
    ParamSpec(
        "initial_positions",
        "float_list",
        None,
        "joint positions at start, model joint order",
        "rad | m",
        minimum=-1e4,  # far beyond any joint's range (the limits are checked too); keeps FK finite
        maximum=1e4,
        default_text="the robot's scenario start, else zeros clipped into the limits",
    ),
    loop_rate("integration and publishing rate"),
    # 1 ms (a period at 1 kHz) to a minute.
    ParamSpec(
        "command_timeout",
        "float",
        0.1,
        "a command older than this counts as zero velocity",
        "s",
        minimum=1e-3,
        maximum=60.0,
        tunable=True,
    ),
    ParamSpec(
        "base_frame",
        "str",
        None,
        "frame id of the published poses and twists",
        default_text="the robot's base frame (base_link)",
    ),
    diagnostics_rate(2.0, "rate of the loop statistics on /diagnostics (0: off)", off=True),
    ParamSpec("frame_prefix", "str", "", "prepended to every TF frame id (as robot_state_publisher's)"),
    # Visuals: a viewer needs /tf at 0.1 Hz at least and gets nothing from more than one
    # per cycle of a 1 kHz loop; markers (10 Hz by default) likewise; a trail of two minutes
    # at its 20 ms spacing is 6000 points.
    ParamSpec("tf_rate_hz", "float", 50.0, "rate of /tf (where tf2_msgs is installed)", "Hz", minimum=0.1, maximum=1e3),
    ParamSpec(
        "markers_rate_hz",
        "float",
        10.0,
        "rate of the markers topic (0: off)",
        "Hz",
        minimum=0.1,
        maximum=1e3,
        zero_is_off=True,
    ),
    ParamSpec("trail_duration", "float", 5.0, "length of the tool trail marker", "s", minimum=0.02, maximum=120.0),
    *PHYSICS_PARAMETERS,
    REALTIME_PRIORITY,
    SCHEDULER_SLICE,
)

#: The parameters as a typed struct (what the node reads).
RobotStateParams = param_struct("RobotStateParams", PARAMETERS, "robot_state's parameters, typed (docs/interfaces.md).")

USAGE = usage_text(
    NODE_NAME,
    "Simulated arm: integrates the latest joint velocity command at rate_hz within the joint\n"
    "position and velocity limits (a command above a velocity limit is scaled down as a whole,\n"
    "keeping its direction) and publishes the joint state, the end-effector and tool poses and\n"
    "twists every cycle. A command older than command_timeout counts as zero; a command with the\n"
    "wrong length or a non-finite value is rejected with a log line. With plant:=mujoco the arm\n"
    "is MuJoCo physics stepped at physics_rate_hz: gravity, a PI velocity servo per joint with\n"
    "the URDF's effort limits, joint damping/armature/friction, and contact with the obstacles on\n"
    "collision_objects (contact force on /diagnostics); joint_states then carries effort.",
    PARAMETERS,
    subscribes=[
        ("joint_velocity_commands", "std_msgs/Float64MultiArray", "joint rates [rad/s | m/s], model joint order"),
        (COLLISION_OBJECTS, "visualization_msgs/MarkerArray", "obstacles in the base frame (plant mujoco)"),
    ],
    publishes=[
        ("joint_states", "sensor_msgs/JointState", "name, position, velocity (plant mujoco: effort), stamped"),
        ("ee_pose", "geometry_msgs/PoseStamped", "end effector in the base frame"),
        ("tool_pose", "geometry_msgs/PoseStamped", "tool (end effector if no tool) in the base frame"),
        ("ee_twist", "geometry_msgs/TwistStamped", "end-effector velocity w.r.t. base, in base"),
        ("tool_twist", "geometry_msgs/TwistStamped", "tool velocity w.r.t. base, in base"),
        ("robot_description", "std_msgs/String", "the URDF file as given (YAML robots: generated), transient local"),
        ("/tf, /tf_static", "tf2_msgs/TFMessage", "link transforms, where tf2_msgs is installed"),
        ("markers", "visualization_msgs/MarkerArray", "goal axes, planned path, tool trail, joint limits"),
        ("/diagnostics", "diagnostic_msgs/DiagnosticArray", "loop rate and timing, command state, contact force"),
    ],
    example=f"{NODE_NAME} --ros-args -p robot:=genova7 -p rate_hz:=1000  (robots: {', '.join(bundled_robot_names())})",
)
