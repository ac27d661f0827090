"""``manip_kin info`` and ``manip_kin replay``: inspect, salvage and republish recordings."""

from __future__ import annotations

import argparse
import json
import sys


def register(subparsers) -> None:
    """Add the recording sub-commands."""
    info = subparsers.add_parser(
        "info",
        help="what a recording holds (as `ros2 bag info`), or salvage a truncated one",
        description=(
            "Print duration, start/end, per-topic type and count, compression and size of a "
            "recording (.mcap file or rosbag2 bag directory). With --salvage OUT, copy the "
            "readable part of a truncated or damaged recording into a new, complete one."
        ),
    )
    info.add_argument("file", metavar="FILE", help="a .mcap file or a bag directory")
    info.add_argument(
        "--salvage",
        metavar="OUT",
        default=None,
        help="write the readable part of FILE to OUT (.mcap file or new bag directory) and report it",
    )
    info.add_argument(
        "--add-tf",
        metavar="OUT",
        default=None,
        help="write a copy of FILE to OUT with /tf and /tf_static computed from its joint_states and "
        "robot_description (for recordings made before the recorder wrote TF)",
    )
    info.add_argument(
        "--tf-rate", type=float, default=50.0, metavar="HZ", help="rate of the added /tf [Hz] (default 50)"
    )
    info.add_argument("--json", action="store_true", help="print one JSON object on stdout and nothing else there")
    info.set_defaults(run=run_info)

    replay = subparsers.add_parser(
        "replay",
        help="republish a recording with its recorded timing and QoS",
        description=(
            "Republish the messages of a recording in receive-time order, with the recorded "
            "spacing divided by --rate, on publishers offering the recorded QoS. A progress "
            "line goes to stderr. Ctrl-C stops. Topics whose type has no Python class here "
            "(tf2_msgs on a PyPI-only machine) are left out with a note, unless named in --topics."
        ),
    )
    replay.add_argument("file", metavar="FILE", help="a .mcap file or a bag directory")
    replay.add_argument(
        "--rate", type=float, default=1.0, metavar="R", help="speed factor, > 0 (default 1; 2 = twice as fast)"
    )
    replay.add_argument("--loop", action="store_true", help="start over at the end until interrupted")
    replay.add_argument(
        "--topics", nargs="+", metavar="TOPIC", default=None, help="only these recorded topics (default all)"
    )
    replay.add_argument(
        "--remap",
        nargs="+",
        action="extend",
        default=[],
        metavar="FROM:=TO",
        help="publish recorded topic FROM on TO (repeatable)",
    )
    replay.add_argument(
        "--start-offset", type=float, default=0.0, metavar="S", help="skip the first S seconds of the recording"
    )
    replay.add_argument(
        "--clock",
        action="store_true",
        help="publish the recording's time on /clock (rosgraph_msgs/Clock) for use_sim_time nodes",
    )
    replay.add_argument(
        "--wait-for-subscribers",
        type=float,
        default=1.0,
        metavar="S",
        help="wait up to S seconds for every topic to have a subscriber before starting (default 1)",
    )
    replay.add_argument(
        "--namespace",
        default=None,
        metavar="NS",
        help="publish the recorded manip_kin topics (joint_states, goal_pose, ...) in namespace NS, "
        "whatever namespace they were recorded in (e.g. /left/joint_states -> /right/joint_states); "
        "--remap wins for the topics it names",
    )
    replay.add_argument(
        "--add-tf",
        action="store_true",
        help="also publish /tf and /tf_static computed from the replayed joint_states and robot_description "
        "(for recordings without TF; needs tf2_msgs, else use `manip_kin info --add-tf OUT FILE`)",
    )
    replay.add_argument("--quiet", action="store_true", help="no progress line")
    replay.set_defaults(run=run_replay)


def _print_json(document: dict) -> None:
    json.dump(document, sys.stdout, indent=2)
    sys.stdout.write("\n")


def run_info(args: argparse.Namespace) -> int:
    """``manip_kin info``."""
    from manip_kin.recording.errors import RecordingError
    from manip_kin.recording.info import read_info
    from manip_kin.recording.salvage import salvage

    if args.add_tf is not None:
        from manip_kin.recording.tf_synthesis import add_tf

        if args.salvage is not None:
            raise RecordingError("--add-tf and --salvage are separate steps: salvage first, then add TF")
        summary, status = add_tf(args.file, args.add_tf, rate_hz=args.tf_rate)
        if args.json:
            _print_json({"output": str(summary.path), "topic_counts": summary.topic_counts, "tf": status})
        else:
            print(f"{summary.one_line()}; {status}")
        return 0
    if args.salvage is not None:
        report = salvage(args.file, args.salvage)
        if args.json:
            _print_json(report.to_json())
        else:
            print(report.one_line())
        return 0
    info = read_info(args.file)
    if args.json:
        _print_json(info.to_json())
    else:
        print(info.to_text())
    return 0


def run_replay(args: argparse.Namespace) -> int:
    """``manip_kin replay``."""
    from manip_kin.pipeline.domain import use_prompt_acknowledgements
    from manip_kin.recording.replay import ReplayOptions, parse_remaps, replay

    remaps = parse_remaps(args.remap)
    if args.namespace is not None:
        remaps = {**namespace_remaps(args.file, args.namespace, args.topics), **remaps}
    options = ReplayOptions(
        rate=args.rate,
        loop=args.loop,
        topics=args.topics,
        remaps=remaps,
        start_offset_s=args.start_offset,
        clock=args.clock,
        wait_for_subscribers_s=max(0.0, args.wait_for_subscribers),
        add_tf=args.add_tf,
    )
    use_prompt_acknowledgements()  # a player wants its last samples acknowledged before it exits
    report = replay(args.file, options, progress=None if args.quiet else sys.stderr)
    print(
        f"replayed {report.messages_published} messages on {len(report.topic_counts)} topics "
        f"in {report.wall_duration_s:.2f} s ({report.loops} pass{'es' if report.loops != 1 else ''})",
        file=sys.stderr,
    )
    return 0


def namespace_remaps(path: str, namespace: str, topics: list[str] | None = None) -> dict[str, str]:
    """Recorded topic → the same manip_kin topic in ``namespace``, for the manip_kin topics of ``path``.

    A manip_kin topic is one whose last name part is a pipeline topic (``joint_states``,
    ``goal_pose``...); global topics (``/diagnostics``, ``/tf``) and others keep their names.
    Only ``topics`` are considered when given.

    Raises:
        InvalidArgumentError: the considered topics come from pipelines in several namespaces
            (they would land on the same topics); name one pipeline's topics with ``--topics``.
    """
    from manip_kin.errors import InvalidArgumentError
    from manip_kin.pipeline.status import normalize_namespace
    from manip_kin.recording.info import read_info
    from manip_kin.ros.wire.topics import PIPELINE_TOPIC_TYPES

    prefix = normalize_namespace(namespace)
    relative = {name for name in PIPELINE_TOPIC_TYPES if not name.startswith("/")}
    remaps = {}
    sources = set()
    for topic in read_info(path).topics:
        recorded_namespace, _, name = topic.name.rpartition("/")
        if name in relative and (topics is None or topic.name in topics):
            remaps[topic.name] = f"{prefix}/{name}"
            sources.add(recorded_namespace or "/")
    if len(sources) > 1:
        raise InvalidArgumentError(
            f"--namespace: {path} holds pipelines in {', '.join(sorted(sources))}, which would land on the same "
            f"topics; valid: pick one pipeline's topics with --topics (e.g. --topics {sorted(remaps)[0]} ...)"
        )
    return remaps
