"""The executables' entry points: a Ctrl-C while Python still imports ends quietly.

A console script imports its module before it calls ``main``, about half a second of numpy,
rclpy and the message types. A Ctrl-C then printed a KeyboardInterrupt traceback. Nothing has
started yet, so there is nothing to stop: the executable exits 130, as a shell reports a
SIGINT. Once ``main`` runs, its own handling applies (``run_node``'s clean stop, the CLI's 130).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from manip_kin.errors import EXIT_INTERRUPTED


def _entry(module: str) -> Callable[[], int]:
    def run() -> int:
        try:
            main = importlib.import_module(module).main
        except KeyboardInterrupt:
            return EXIT_INTERRUPTED
        return main()

    run.__doc__ = f"``{module}.main``, imported first (a Ctrl-C meanwhile: exit {EXIT_INTERRUPTED})."
    run.module = module  # type: ignore[attr-defined]
    return run


manip_kin = _entry("manip_kin.cli")
robot_state = _entry("manip_kin.ros.nodes.robot_state")
cartesian_controller = _entry("manip_kin.ros.nodes.cartesian_controller")
trajectory_generator = _entry("manip_kin.ros.nodes.trajectory_generator")
recorder = _entry("manip_kin.ros.nodes.recorder")
live_view = _entry("manip_kin.ros.nodes.live_view")
