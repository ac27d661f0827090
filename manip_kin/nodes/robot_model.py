"""Where a node's robot model comes from: the ``robot`` parameter, or the URDF on ``robot_description``.

Every node declares the same chain parameters (:func:`model_parameters`): ``robot`` (a
bundled name or a robot YAML/URDF file), ``base_link``, ``tip_link`` and ``tool_link`` (the
chain of a URDF) and ``velocity_limits`` (one per joint, for URDFs that give none). With
``robot`` empty, :func:`load_node_model` waits for the URDF on the node's
``robot_description`` topic (transient local, as robot_state_publisher and robot_state
publish it) and logs that it waits, so a controller drops into a running ROS system with
the same model as everything else.
"""

from __future__ import annotations

import time

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from manip_kin.model import RobotModel
from manip_kin.nodes.params import ParamSpec
from manip_kin.robots import load_robot, with_velocity_limits

#: Seconds between two "still waiting for robot_description" lines.
WAIT_LOG_PERIOD_S = 10.0


def model_parameters(robot_default: str) -> tuple[ParamSpec, ...]:
    """``robot``, ``base_link``, ``tip_link``, ``tool_link``, ``velocity_limits`` (structural: read-only).

    Args:
        robot_default: default of ``robot``; "" = read the URDF on ``robot_description``.
    """
    robot_text = "bundled robot name or path to a robot YAML/URDF file"
    if not robot_default:
        robot_text += " ('' = the URDF on the robot_description topic, waited for)"
    return (
        ParamSpec("robot", "str", robot_default, robot_text),
        ParamSpec("base_link", "str", "", "URDF: first link of the chain ('' = the root link)"),
        ParamSpec(
            "tip_link",
            "str",
            "",
            "URDF: last link of the chain, the end effector ('' = where the unbranched chain below the base ends; "
            "needed when the tree branches into several arms)",
        ),
        ParamSpec("tool_link", "str", "", "URDF: a link below the tip (fixed joints) used as the tool ('' = none)"),
        ParamSpec(
            "velocity_limits",
            "float_list",
            None,
            "joint velocity limits, model joint order, replacing the model's (for URDFs without limits)",
            "rad/s | m/s",
            minimum=1e-3,  # 1 mrad/s to 1000 rad/s: slower is no motion, faster no arm; the rates
            maximum=1e3,  # the limits bound (1/limit, 100 x limit) stay finite
            default_text="the model's; none where the URDF gives none",
        ),
    )


def load_node_model(node: Node, params: dict) -> RobotModel:
    """The model the parameters name, or the one on ``robot_description`` when ``robot`` is empty.

    Raises:
        ManipKinError: unknown robot, malformed file or description, links that make no chain,
            bad ``velocity_limits`` (the node exits with code 2 and this message).
        ExternalShutdownException: Ctrl-C or SIGTERM while waiting for the description.
    """
    from manip_kin.urdf import joints_without_velocity_limit, load_urdf_string

    links = {name: params[name] or None for name in ("base_link", "tip_link", "tool_link")}
    if params["robot"]:
        model = load_robot(params["robot"], **links)
        origin = f"robot {params['robot']!r}"
    else:
        text, topic = wait_for_description(node)
        model = load_urdf_string(text, source=topic, **links)
        origin = f"the URDF on {topic}"
    if params["velocity_limits"]:
        model = with_velocity_limits(model, params["velocity_limits"])
    node.get_logger().info(
        f"model {model.name!r} from {origin}: {model.dof} joints ({', '.join(model.joint_names)}), "
        f"base frame {model.base_frame!r}"
    )
    unlimited = joints_without_velocity_limit(model)
    if unlimited:
        node.get_logger().warning(
            f"no velocity limit for {', '.join(unlimited)} in {origin}: not speed-limited "
            "(set parameter velocity_limits, one value per joint, to limit them)"
        )
    return model


def wait_for_description(node: Node) -> tuple[str, str]:
    """Wait for the URDF on ``robot_description`` (transient local); returns ``(text, topic name)``.

    Spins ``node`` on a private executor until the text arrives (the node is not yet added
    to its main executor); logs the wait at start and every :data:`WAIT_LOG_PERIOD_S`.
    """
    from std_msgs.msg import String

    received: list[str] = []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    subscription = node.create_subscription(String, "robot_description", lambda msg: received.append(msg.data), latched)
    topic = subscription.topic_name
    node.get_logger().info(
        f"waiting for the robot model: a URDF on {topic} (transient local, as robot_state_publisher "
        "publishes it); set parameter robot to load a bundled robot or a file instead"
    )
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    started = time.monotonic()
    next_log = started + WAIT_LOG_PERIOD_S
    try:
        while not received:
            if not node.context.ok():
                raise ExternalShutdownException()
            executor.spin_once(timeout_sec=0.1)
            if time.monotonic() >= next_log:
                next_log += WAIT_LOG_PERIOD_S
                publishers = node.count_publishers(topic)
                node.get_logger().info(
                    f"still waiting for {topic} after {time.monotonic() - started:.0f} s ({publishers} publisher(s))"
                )
    finally:
        executor.remove_node(node)
        node.destroy_subscription(subscription)
    return received[-1], topic
