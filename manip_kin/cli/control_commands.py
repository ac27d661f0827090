"""``manip_kin stop``, ``manip_kin pause``, ``manip_kin resume``: halt or hold the running arm.

``stop`` calls ``trajectory_generator``'s ``~/stop`` (it stops streaming, if it runs) and then
``cartesian_controller``'s ``~/stop``: the commands come to rest within the joint limits and
the goal is dropped. ``pause`` and ``resume`` call the controller's ``~/pause``
(std_srvs/SetBool): hold still within the limits with the goal kept, then go on.

Exit codes: 0 done; 1 the controller did not answer; 2 bad input.
"""

from __future__ import annotations

import argparse
import sys

from manip_kin.cli.common import add_namespace_argument, namespace_from_args


def register(subparsers) -> None:
    """Add ``stop``, ``pause`` and ``resume``."""
    for name, text in (
        ("stop", "halt the arm smoothly within its limits and drop the goal (and stop a streaming line)"),
        ("pause", "hold the arm still within its limits, keeping the goal (resume goes on)"),
        ("resume", "go on with the goal held by pause"),
    ):
        parser = subparsers.add_parser(
            name, help=text, description=f"{text[0].upper()}{text[1:]}. Example: manip_kin {name} --namespace /left"
        )
        parser.add_argument("--timeout", type=float, default=5.0, metavar="S", help="seconds to wait for the service")
        add_namespace_argument(parser)
        parser.set_defaults(run=run_control)


def run_control(args: argparse.Namespace) -> int:
    """``manip_kin stop|pause|resume``."""
    from manip_kin.pipeline import PipelineClient, PipelineError

    namespace = namespace_from_args(args)
    with PipelineClient(watch_state=False, namespace=namespace) as client:
        try:
            if args.command == "stop":
                try:
                    client.call_trigger("trajectory_generator", "stop", timeout=min(args.timeout, 1.0))
                except PipelineError:
                    pass  # no generator running: nothing streams
                message = client.call_trigger("cartesian_controller", "stop", timeout=args.timeout)
            else:
                message = client.call_trigger("cartesian_controller", "pause", args.command == "pause", args.timeout)
        except PipelineError as error:
            print(f"manip_kin {args.command}: error: {error}", file=sys.stderr)
            return 1
    print(f"cartesian_controller: {message}")
    return 0
