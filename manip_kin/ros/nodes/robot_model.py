"""Where a node's robot model comes from: the ``robot`` parameter, or the URDF on ``robot_description``.

Every node declares the same chain parameters (:func:`model_parameters`): ``robot`` (a
bundled name or a robot YAML/URDF file), ``base_link``, ``tip_link`` and ``tool_link`` (the
chain of a URDF) and ``velocity_limits`` (one per joint, for URDFs that give none). With
``robot`` empty, :func:`load_node_model` waits for the URDF on the node's
``robot_description`` topic (transient local, as robot_state_publisher and robot_state
publish it) and logs that it waits, so a controller drops into a running ROS system with
the same model as everything else; several different descriptions there are refused until
``robot_description_publisher`` names one, and later ones are logged
(:mod:`manip_kin.ros.nodes.robot_description`).
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node

from manip_kin.core.model import RobotModel
from manip_kin.core.robots import load_robot, with_velocity_limits
from manip_kin.ros.nodes.robot_description import PARAMETER, DescriptionWatch
from manip_kin.ros.runtime.param_struct import ParamStruct
from manip_kin.ros.runtime.params import ParamSpec


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
        *(
            ()
            if robot_default
            else (
                ParamSpec(
                    PARAMETER,
                    "str",
                    "",
                    "node (/ns/name or name) whose robot_description to use when several publish different "
                    "ones ('' = the one description there is)",
                ),
            )
        ),
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


def load_node_model(
    node: Node, params: ParamStruct, switch: Callable[[RobotModel], str | None] | None = None
) -> RobotModel:
    """The model the parameters name, or the one on ``robot_description`` when ``robot`` is empty.

    Args:
        node: the node.
        params: its checked parameters (:func:`model_parameters`).
        switch: for a model from ``robot_description``: ``switch(model) -> None | reason``, the
            node's way to use another model when ``~/reload_robot_description`` is called; the
            node then follows the topic (see :class:`~manip_kin.ros.nodes.robot_description.DescriptionWatch`).
            None: the description is read once.

    Raises:
        ManipKinError: unknown robot, malformed file or description, links that make no chain,
            bad ``velocity_limits``, several different descriptions (the node exits with code 2
            and this message).
        ExternalShutdownException: Ctrl-C or SIGTERM while waiting for the description.
    """
    from manip_kin.core.urdf import joints_without_velocity_limit

    if params.robot:
        model = _with_limits(load_robot(params.robot, **_links(params)), params)
        origin = f"robot {params.robot!r}"
    else:
        # robot_description_publisher is declared where robot is empty by default.
        watch = DescriptionWatch(node, getattr(params, PARAMETER, ""))
        description = watch.wait()
        load = _description_loader(params, watch.topic)
        model = load(description.text)
        node.robot_description_text = description.text  # for what else the URDF holds (collision geometry)
        origin = f"the URDF on {watch.topic} from {description.publisher}"
        if switch is None:
            watch.close()
        else:
            watch.follow(description, load, switch, model)
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


def _links(params: ParamStruct) -> dict:
    return {
        "base_link": params.base_link or None,
        "tip_link": params.tip_link or None,
        "tool_link": params.tool_link or None,
    }


def _with_limits(model: RobotModel, params: ParamStruct) -> RobotModel:
    return with_velocity_limits(model, params.velocity_limits) if params.velocity_limits else model


def _description_loader(params: ParamStruct, topic: str) -> Callable[[str], RobotModel]:
    """URDF text -> the model of the node's chain parameters."""
    from manip_kin.core.urdf import load_urdf_string

    links = _links(params)
    return lambda text: _with_limits(load_urdf_string(text, source=topic, **links), params)
