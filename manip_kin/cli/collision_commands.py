"""``manip_kin check`` (distances of a configuration) and ``manip_kin obstacle`` (scene obstacles).

``check`` loads the robot's URDF ``<collision>`` geometry and prints the closest link pairs
at ``--q`` (self-collision only: obstacles live in a running pipeline). Exit codes: 0 no
pair in contact, 1 the configuration collides, 2 bad input.

``obstacle add|delete|clear`` publishes one ``visualization_msgs/MarkerArray`` on
``collision_objects`` (in ``--namespace``) once a subscriber (a controller, the physics plant,
a recorder) is matched, and waits until it acknowledged the message, so it is delivered when
the command returns. ``--frame`` defaults to the base frame the controller reports. When the
namespace's cartesian_controller listens (it has ``collision_avoidance``), its status says
whether it took the array: exit 0 taken, 2 refused (with its reason), 1 no word of it.
"""

from __future__ import annotations

import argparse
import math
import sys

from manip_kin.cli.common import (
    add_joint_argument,
    add_json_argument,
    add_namespace_argument,
    add_robot_argument,
    joints_from_args,
    namespace_from_args,
    print_json,
    robot_from_args,
)
from manip_kin.errors import InvalidArgumentError


def register(subparsers) -> None:
    """Add ``check`` and ``obstacle``."""
    check = subparsers.add_parser(
        "check",
        help="distances of the closest link pairs at a configuration, and whether it collides",
        description="Load the robot's URDF <collision> geometry (meshes as convex hulls) and print the closest "
        "checked link pairs at --q with their distances [m] (negative: penetration depth). Pairs not checked: "
        "adjacent links and an SRDF's disable_collisions (--srdf), or, without an SRDF, those found by sampling "
        "random configurations as MoveIt's setup assistant does. Exit 0: no contact; 1: the configuration "
        "collides. Example: manip_kin check --robot panda.urdf --q 0 -0.785 0 -2.356 0 1.571 0.785 --srdf panda.srdf",
    )
    add_robot_argument(check)
    add_joint_argument(check)
    check.add_argument("--srdf", metavar="FILE", default=None, help="SRDF whose disable_collisions are not checked")
    check.add_argument(
        "--mesh-search-path",
        metavar="DIRS",
        default="",
        help="':'-separated directories holding packages, for package://P/... meshes (<dir>/P/...); "
        "the ament index is searched after them",
    )
    check.add_argument("--count", type=int, default=5, metavar="K", help="closest pairs to print (default 5)")
    check.add_argument(
        "--samples",
        type=int,
        default=1000,
        metavar="N",
        help="random configurations sampled to choose the pairs when no --srdf is given (default 1000)",
    )
    add_json_argument(check)
    check.set_defaults(run=run_check)

    obstacle = subparsers.add_parser(
        "obstacle",
        help="add, delete or clear scene obstacles on collision_objects",
        description="Publish boxes, spheres and cylinders (visualization_msgs/MarkerArray in the base frame) on "
        "collision_objects for the controller's collision avoidance. A marker's --ns and --id name an obstacle; "
        "add replaces one with the same name. Sizes follow the markers: a box's full extents, a sphere's "
        "diameter, a cylinder's diameter and height (along its z). A collision-aware controller's verdict is the "
        "command's: exit 0 taken (or no such controller listens), 2 refused (its reason printed), bad input or "
        "no subscriber, 1 no word from the controller within --timeout. Example: "
        "manip_kin obstacle add --id 1 --shape box --size 0.2 0.2 0.4 --xyz 0.5 0 0.2",
    )
    actions = obstacle.add_subparsers(dest="action", metavar="ACTION", parser_class=type(obstacle))
    actions.required = True
    add = actions.add_parser("add", help="put or replace one obstacle")
    _add_key_arguments(add)
    add.add_argument("--shape", choices=("box", "sphere", "cylinder"), required=True, help="obstacle shape")
    add.add_argument(
        "--size",
        nargs="+",
        type=float,
        required=True,
        metavar="M",
        help="box: X Y Z full extents; sphere: DIAMETER; cylinder: DIAMETER HEIGHT [m]",
    )
    add.add_argument("--xyz", nargs=3, type=float, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"), help="centre [m]")
    add.add_argument(
        "--rpy", nargs=3, type=float, default=(0.0, 0.0, 0.0), metavar=("R", "P", "Y"), help="orientation [rad]"
    )
    delete = actions.add_parser("delete", help="remove one obstacle")
    _add_key_arguments(delete)
    clear = actions.add_parser("clear", help="remove every obstacle")
    for parser in (add, delete, clear):
        parser.add_argument(
            "--frame",
            default=None,
            help="frame_id of the obstacle: the robot's base frame (default: the one the controller "
            "reports, else base_link)",
        )
        parser.add_argument("--timeout", type=float, default=10.0, metavar="S", help="seconds to wait for a subscriber")
        add_namespace_argument(parser)
        add_json_argument(parser)
        parser.set_defaults(run=run_obstacle)


def _add_key_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ns", default="manip_kin", help="marker namespace of the obstacle (default manip_kin)")
    parser.add_argument("--id", type=int, required=True, help="marker id of the obstacle")


# --- check ---------------------------------------------------------------------------------------


def run_check(args: argparse.Namespace) -> int:
    """``manip_kin check``."""
    from manip_kin.collision.collision_model import load_collision_model
    from manip_kin.collision.distances import CollisionChecker

    if args.count < 1:
        raise InvalidArgumentError(f"--count {args.count}; valid: at least 1")
    if args.samples < 1:
        raise InvalidArgumentError(f"--samples {args.samples}; valid: at least 1")
    model = robot_from_args(args)
    q = joints_from_args(model, args.q)
    collision_model = load_collision_model(
        model, srdf=args.srdf, mesh_search_path=args.mesh_search_path, samples=args.samples
    )
    pairs = CollisionChecker(model, collision_model, native=False).link_distances(q)  # one query
    collides = bool(pairs) and pairs[0].distance <= 0.0
    shown = pairs[: args.count]
    if args.json:
        print_json(
            {
                "collides": collides,
                "q": q.tolist(),
                "pairs": [
                    {
                        "first": pair.first,
                        "second": pair.second,
                        "distance": pair.distance,
                        "point_first": pair.point_first.tolist(),
                        "point_second": pair.point_second.tolist(),
                    }
                    for pair in shown
                ],
                "checked_pairs": len(collision_model.pairs.checked),
                "disabled_pairs": len(collision_model.pairs.disabled),
            }
        )
    else:
        verdict = "COLLIDES" if collides else "free"
        print(
            f"{model.name}: {verdict} ({len(collision_model.pairs.checked)} link pairs checked, "
            f"{len(collision_model.pairs.disabled)} disabled)"
        )
        for pair in shown:
            print(f"  {pair.distance:+.4f} m  {pair.first} - {pair.second}")
    return 1 if collides else 0


# --- obstacle ------------------------------------------------------------------------------------


def _obstacle_scale(shape: str, size: list[float]) -> tuple[float, float, float]:
    """The marker scale of ``--size`` for a shape."""
    expected = {"box": 3, "sphere": 1, "cylinder": 2}[shape]
    if len(size) != expected or not all(math.isfinite(v) and v > 0 for v in size):
        valid = {"box": "X Y Z", "sphere": "DIAMETER", "cylinder": "DIAMETER HEIGHT"}[shape]
        raise InvalidArgumentError(f"--size {' '.join(f'{v:g}' for v in size)} for a {shape}; valid: {valid}, > 0 [m]")
    if shape == "box":
        return (size[0], size[1], size[2])
    if shape == "sphere":
        return (size[0], size[0], size[0])
    return (size[0], size[0], size[1])


def build_marker_array(args: argparse.Namespace, frame: str, stamp):
    """The ``MarkerArray`` of an ``obstacle`` command in ``frame`` (checked like the controller will)."""
    from visualization_msgs.msg import Marker, MarkerArray

    from manip_kin.core.rotations import make_transform, rpy_to_matrix
    from manip_kin.core.scene import MARKER_OF_SHAPE, MarkerAction, ShapeKind, make_obstacle
    from manip_kin.ros.wire.messages import fill_pose

    marker = Marker()
    marker.header.frame_id = frame
    marker.header.stamp = stamp
    if args.action == "clear":
        marker.action = int(MarkerAction.DELETEALL)
        return MarkerArray(markers=[marker])
    marker.ns, marker.id = args.ns, int(args.id)
    if args.action == "delete":
        marker.action = int(MarkerAction.DELETE)
        return MarkerArray(markers=[marker])
    scale = _obstacle_scale(args.shape, args.size)
    pose = make_transform(rpy_to_matrix(*args.rpy), args.xyz)
    make_obstacle((args.ns, args.id), args.shape, scale, pose)  # the controller's checks, here first
    marker.action = int(MarkerAction.ADD)
    marker.type = int(MARKER_OF_SHAPE[ShapeKind(args.shape)])
    fill_pose(marker.pose, pose)
    marker.scale.x, marker.scale.y, marker.scale.z = scale
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = 0.8, 0.3, 0.2, 0.6
    return MarkerArray(markers=[marker])


def _controller_listens(client, topic: str, timeout: float) -> bool:
    """True when this namespace's cartesian_controller subscribes ``topic`` (it has
    ``collision_avoidance``, and reports what it took of the scene). A subscription's node is
    learnt after the subscription itself (Fast DDS: "_NODE_NAME_UNKNOWN_" until then): waited
    for, up to ``timeout``."""
    from manip_kin.pipeline.status import status_name

    controller = client.status_name("cartesian_controller")

    def names():
        infos = client.node.get_subscriptions_info_by_topic(topic)
        known = [status_name(info.node_name, info.node_namespace) for info in infos]
        return None if any("_NODE_NAME_UNKNOWN_" in name for name in known) else known

    return controller in (client.spin_until(names, timeout) or ())


def _verdict(client, stamp: str, timeout: float):
    """The controller's status that took the array stamped ``stamp`` (None: none within ``timeout``)."""

    def taken():
        status = client.latest_status("cartesian_controller")
        return (
            status is not None
            and stamp in (status.values.get("obstacles_stamp"), status.values.get("rejected_obstacles_stamp"))
            and status
        )

    return client.spin_until(taken, timeout)


def run_obstacle(args: argparse.Namespace) -> int:
    """``manip_kin obstacle add|delete|clear``."""
    from visualization_msgs.msg import MarkerArray

    from manip_kin.pipeline import PipelineClient, PipelineError
    from manip_kin.ros.wire.messages import stamp_key
    from manip_kin.ros.wire.scene_messages import TOPIC

    if not args.timeout > 0:
        raise InvalidArgumentError(f"--timeout {args.timeout}; valid: seconds > 0")
    namespace = namespace_from_args(args)
    if args.action == "add":
        _obstacle_scale(args.shape, args.size)  # bad input fails before any ROS start-up
    what = "every obstacle" if args.action == "clear" else f"obstacle {args.ns}/{args.id}"
    with PipelineClient(watch_state=False, namespace=namespace) as client:
        topic = client.topic(TOPIC)
        try:
            client.wait_subscribers(MarkerArray, TOPIC, args.timeout, latched=True)
            listens = _controller_listens(client, topic, args.timeout)
            frame = args.frame
            if frame is None:
                reported = client.wait_status("cartesian_controller", args.timeout) if listens else None
                frame = (reported.values.get("base_frame") if reported else None) or "base_link"
            stamp = client.node.get_clock().now().to_msg()
            subscribers = client.publish_delivered(TOPIC, build_marker_array(args, frame, stamp), args.timeout)
        except PipelineError as error:
            print(f"manip_kin obstacle: error: {error}", file=sys.stderr)
            return 2
        verdict = _verdict(client, stamp_key(stamp), args.timeout) if listens else None
    report = {"topic": topic, "action": args.action, "ns": getattr(args, "ns", ""), "frame": frame}
    report["subscribers"] = subscribers
    if not listens:
        report["controller"], outcome = "not listening", "no controller with collision_avoidance listens"
    elif verdict is None:
        report["controller"] = "no report"
        outcome = f"the controller reported nothing of it within {args.timeout:g} s"
    elif verdict.values.get("rejected_obstacles_stamp") == stamp_key(stamp):
        report["controller"], report["reason"] = "refused", verdict.values.get("last_obstacle_rejection", "")
        outcome = f"refused by the controller: {report['reason']}"
    else:
        report["controller"] = "taken"
        outcome = f"taken by the controller ({verdict.values.get('obstacles', '?')} obstacles)"
    if args.json:
        print_json(report)
    if report["controller"] in ("refused", "no report"):
        print(f"manip_kin obstacle: error: {what} delivered on {topic}, {outcome}", file=sys.stderr)
        return 2 if report["controller"] == "refused" else 1
    if not args.json:
        print(f"{args.action} {what}: delivered on {topic} to {subscribers} subscriber(s), {outcome}")
    return 0
