"""The ``manip_kin`` command line tool.

Each sub-command lives in its own module exposing ``register(subparsers)``,
which adds an argparse parser whose ``run`` default is ``run(args) -> int``.
Errors are reported on one line on stderr: exit code 2 for bad input (an
:class:`~manip_kin.errors.InputError`), 1 for a valid request that failed.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from manip_kin.errors import EXIT_INTERRUPTED, ManipKinError, exit_code_for

# Order is the order of `manip_kin --help`.
COMMAND_MODULES = (
    "manip_kin.cli.model_commands",
    "manip_kin.cli.motion_commands",
    "manip_kin.cli.ros_commands",
    "manip_kin.cli.teleop_streaming",
    "manip_kin.cli.teleop_command",
    "manip_kin.cli.move_command",
    "manip_kin.cli.control_commands",
    "manip_kin.cli.collision_commands",
    "manip_kin.cli.recording_commands",
    "manip_kin.cli.plot_commands",
    "manip_kin.cli.demo_command",
)


class OneLineErrorParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr and exit code 2."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full ``manip_kin`` parser with every sub-command registered."""
    parser = OneLineErrorParser(
        prog="manip_kin",
        description=(
            "Kinematics and cartesian control of serial manipulators. "
            "Lengths in metres, angles in radians, times in seconds. "
            "`--robot` takes a bundled robot name (see `manip_kin robots`) or a "
            "robot YAML/URDF path."
        ),
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineErrorParser)
    subparsers.required = True
    for module_name in COMMAND_MODULES:
        importlib.import_module(module_name).register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``manip_kin`` executable."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    # `ros2 run` may append ROS arguments; they are not ours.
    if "--ros-args" in args_list:
        args_list = args_list[: args_list.index("--ros-args")]
    try:
        parser = build_parser()  # imports every command's module: a Ctrl-C may land here
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    args = parser.parse_args(args_list)
    try:
        return int(args.run(args) or 0)
    except ManipKinError as error:
        print(f"manip_kin {args.command}: error: {error}", file=sys.stderr)
        return exit_code_for(error)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
