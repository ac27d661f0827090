"""What a pipeline runs: node processes (:class:`NodeProcess`: an executable, a node name, a
namespace, parameters) and the three pipeline nodes of a robot (:func:`pipeline_processes`);
started and stopped by :class:`~manip_kin.pipeline.supervisor.Pipeline`."""

from __future__ import annotations

import os
import shutil
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.pipeline.errors import PipelineError
from manip_kin.pipeline.status import normalize_namespace, status_name

#: Node executables of the pipeline, in start order.
PIPELINE_NODES = ("robot_state", "cartesian_controller", "trajectory_generator")


def find_executable(name: str, executable_dir: str | os.PathLike | None = None) -> str:
    """Path of a node executable: in ``executable_dir`` if given, else next to this Python, else on PATH."""
    if executable_dir is not None:
        candidate = Path(executable_dir) / name
        if candidate.is_file():
            return str(candidate)
        raise PipelineError(f"executable {name!r} not found in {executable_dir}")
    beside = Path(sys.executable).parent / name
    if beside.is_file():
        return str(beside)
    found = shutil.which(name)
    if found is None:
        raise PipelineError(f"executable {name!r} not found next to {sys.executable} nor on PATH")
    return found


def _parameter_text(value) -> str:
    """A parameter value as ``-p name:=value`` text (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) and all(isinstance(v, str) for v in value):
            return "[" + ", ".join(f"'{v}'" for v in value) + "]"
        return "[" + ", ".join(repr(float(v)) for v in value) + "]"
    if isinstance(value, float):
        return repr(value)
    return str(value)


# --- processes -------------------------------------------------------------------------------


@dataclass(frozen=True)
class NodeProcess:
    """One node executable to run.

    Attributes:
        executable: console script name (``robot_state``...).
        node_name: the node's name in the graph.
        parameters: ``-p name:=value`` pairs.
        params_file: optional ``--params-file``.
        remaps: ``-r from:=to`` pairs.
        ready_status: name of the node whose ``/diagnostics`` status means the node runs
            ("" = wait only for the node name in the graph); looked up in ``namespace``.
        namespace: ``-r __ns:=NS`` (``""``: the root namespace, or the :class:`Pipeline`'s).
        prefix: a command the executable runs under, as its first words (e.g. ``("ip",
            "netns", "exec", "robot")``: the node in another network namespace); it must
            exec the executable (keep its pid, pass signals on). Empty: run it directly.
    """

    executable: str
    node_name: str = ""
    parameters: Mapping[str, object] = field(default_factory=dict)
    params_file: str | None = None
    remaps: Mapping[str, str] = field(default_factory=dict)
    ready_status: str = ""
    namespace: str = ""
    prefix: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        """The node name (the executable name when not set)."""
        return self.node_name or self.executable

    @property
    def status_name(self) -> str:
        """The ``/diagnostics`` status name that means "running" ("" when none)."""
        return status_name(self.ready_status, self.namespace) if self.ready_status else ""

    def arguments(self) -> list[str]:
        """The ``--ros-args`` part of the command line."""
        args = ["--ros-args"]
        if self.node_name:
            args += ["-r", f"__node:={self.node_name}"]
        namespace = normalize_namespace(self.namespace)
        if namespace:
            args += ["-r", f"__ns:={namespace}"]
        for source, target in self.remaps.items():
            args += ["-r", f"{source}:={target}"]
        if self.params_file:
            args += ["--params-file", str(self.params_file)]
        for key, value in self.parameters.items():
            args += ["-p", f"{key}:={_parameter_text(value)}"]
        return args


#: The generator's settings of the irb120 line scenario (0.4 m/s, robots.md): a trapezoid that
#: reaches the line speed in 0.8 s (0.16 m) at 0.5 m/s², so the cruise is the scenario's
#: constant speed and the ends are not a velocity step. At 1 m/s² joint3 decelerates at
#: 18 rad/s² into the line's end, and that acceleration's step back to 0 there, rounded off
#: at its jerk limit, left the line by 0.42 mm (0.067 mm at 0.5 m/s²; offline, 1 kHz).
IRB120_LINE_GENERATOR = {
    "time_scaling": "trapezoidal",
    "max_linear_velocity": 0.4,
    "max_linear_acceleration": 0.5,
    "max_angular_velocity": 1.0,
}


def pipeline_processes(
    robot: str = "genova7",
    rate_hz: float = 500.0,
    initial_positions: Sequence[float] | None = None,
    controller: Mapping[str, object] | None = None,
    generator: Mapping[str, object] | None = None,
    robot_state: Mapping[str, object] | None = None,
    params_file: str | None = None,
    realtime_priority: int = 0,
    model_from_description: bool = False,
) -> list[NodeProcess]:
    """The three pipeline nodes for ``robot`` at ``rate_hz``, with extra parameters per node.

    Args:
        robot: bundled robot name or robot file of robot_state. The controller and the
            generator get it too, unless ``model_from_description``.
        rate_hz: loop rate of the three nodes [Hz].
        initial_positions: start configuration of robot_state (default: the robot's).
        controller: extra cartesian_controller parameters (gains, tolerances...).
        generator: extra trajectory_generator parameters (time_scaling, limits...).
        robot_state: extra robot_state parameters.
        params_file: a ``--params-file`` given to every node. ROS resolves a key found in the
            file's node-name section before ``-p`` values (which act like ``/**`` entries), so
            the file wins for the keys it sets per node.
        realtime_priority: SCHED_FIFO priority of every node's loop thread and the threads it
            waits on (0 = normal scheduling); keeps the loops on time on a busy machine where
            permitted.
        model_from_description: the controller and the generator read the model from
            robot_state's ``robot_description`` instead of a ``robot`` parameter.
    """
    common: dict[str, object] = {"rate_hz": float(rate_hz)}
    if not model_from_description:
        common["robot"] = robot
    if realtime_priority:
        common["realtime_priority"] = int(realtime_priority)
    state = dict(common, robot=robot, **(robot_state or {}))
    if initial_positions is not None:
        state["initial_positions"] = [float(v) for v in initial_positions]
    return [
        NodeProcess("robot_state", "robot_state", state, params_file, ready_status="robot_state"),
        NodeProcess(
            "cartesian_controller",
            "cartesian_controller",
            dict(common, **(controller or {})),
            params_file,
            ready_status="cartesian_controller",
        ),
        NodeProcess(
            "trajectory_generator",
            "trajectory_generator",
            dict(common, **(generator or {})),
            params_file,
            ready_status="trajectory_generator",
        ),
    ]
