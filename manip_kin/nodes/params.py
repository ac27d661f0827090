"""Node parameters: one table per node gives the declaration, the checks and the ``--help`` text.

Parameters are declared with a :class:`~rcl_interfaces.msg.ParameterDescriptor`
(description with units) and ``dynamic_typing`` so that ``-p rate_hz:=1000`` (an integer
on the command line) and ``-p initial_positions:=[0, 0, 0]`` work where a float is meant;
the value is then coerced and checked here, and a bad one stops the node with a one-line
error (exit 2 through ``run_node``).

Live tuning: a ``tunable`` parameter (gains, damping, tolerances, timeouts, limits) can be
set on the running node through the standard parameter services (``ros2 param set``,
``rclpy.parameter_client.AsyncParameterClient``). :class:`LiveParameters` checks the new
value with the same :meth:`ParamSpec.coerce` as at start and hands it to the node, which
rebuilds its core object with it; an invalid value is refused with the reason in the
``SetParametersResult``. The other parameters are structural (robot, links, rates, frames)
and read-only: setting one is refused, and their description says so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from manip_kin.errors import InvalidArgumentError

KINDS = ("float", "int", "bool", "str", "float_list")


@dataclass(frozen=True)
class ParamSpec:
    """One node parameter.

    Attributes:
        name: parameter name.
        kind: ``float``, ``int``, ``bool``, ``str`` or ``float_list``.
        default: default value (None: no default, e.g. "the robot's start configuration").
        description: what it does, one sentence.
        unit: unit text such as ``Hz``, ``s``, ``1/s``, ``m`` ("" when none).
        minimum: smallest valid value for numbers (inclusive), or None.
        positive: True when the value must be > 0.
        choices: valid values for strings, or empty.
        default_text: how to show a None default in ``--help``.
        tunable: settable on the running node (see :class:`LiveParameters`); otherwise
            structural and read-only.
    """

    name: str
    kind: str
    default: object
    description: str
    unit: str = ""
    minimum: float | None = None
    positive: bool = False
    choices: tuple[str, ...] = ()
    default_text: str = ""
    tunable: bool = False

    def descriptor(self) -> ParameterDescriptor:
        """The descriptor: description with unit, valid range, read-only unless tunable, dynamic typing."""
        text = self.description + (f" [{self.unit}]" if self.unit else "")
        if self.choices:
            text += f" (one of: {', '.join(self.choices)})"
        text += " (settable at run time)" if self.tunable else " (read-only: structural, set at start)"
        return ParameterDescriptor(
            name=self.name,
            description=text,
            additional_constraints=self.constraint_text(),
            read_only=not self.tunable,
            dynamic_typing=True,
        )

    def constraint_text(self) -> str:
        """Valid values in words."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.positive:
            return "> 0"
        if self.minimum is not None:
            return f">= {self.minimum:g}"
        return ""

    def help_line(self) -> str:
        """One line for ``--help``: name, default, unit, description."""
        if self.default is None:
            default = self.default_text or "(none)"
        elif isinstance(self.default, str):
            default = repr(self.default)
        elif isinstance(self.default, bool):
            default = "true" if self.default else "false"
        else:
            default = str(self.default)
        unit = f" [{self.unit}]" if self.unit else ""
        choices = f" One of: {', '.join(self.choices)}." if self.choices else ""
        live = " Settable at run time." if self.tunable else ""
        return f"  {self.name} (default {default}){unit}: {self.description}.{choices}{live}"

    def coerce(self, value):
        """``value`` converted to this parameter's kind and checked; InvalidArgumentError otherwise."""
        if value is None:
            return None
        try:
            if self.kind == "float":
                if isinstance(value, bool):
                    raise TypeError
                result = float(value)
                self._check_number(result)
                return result
            if self.kind == "int":
                if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
                    raise TypeError
                result = int(value)
                self._check_number(result)
                return result
            if self.kind == "bool":
                if not isinstance(value, bool):
                    raise TypeError
                return value
            if self.kind == "str":
                if not isinstance(value, str):
                    raise TypeError
                if self.choices and value not in self.choices:
                    raise InvalidArgumentError(f"parameter {self.name} = {value!r}; valid: {', '.join(self.choices)}")
                return value
            if self.kind == "float_list":
                if isinstance(value, (str, bytes)) or any(isinstance(v, bool) for v in value):
                    raise TypeError
                result = [float(v) for v in value]
                if not all(math.isfinite(v) for v in result):
                    raise InvalidArgumentError(f"parameter {self.name} contains NaN or infinity; valid: finite numbers")
                return result
        except (TypeError, ValueError) as error:
            if isinstance(error, InvalidArgumentError):
                raise
            raise InvalidArgumentError(
                f"parameter {self.name} = {value!r} has the wrong type; valid: {self._kind_text()}"
            ) from None
        raise InvalidArgumentError(f"parameter {self.name}: unknown kind {self.kind!r}")

    def _check_number(self, value: float) -> None:
        if not math.isfinite(value):
            raise InvalidArgumentError(f"parameter {self.name} = {value}; valid: a finite number")
        if self.positive and not value > 0:
            raise InvalidArgumentError(f"parameter {self.name} = {value:g}; valid: > 0 {self.unit}".rstrip())
        if self.minimum is not None and value < self.minimum:
            raise InvalidArgumentError(
                f"parameter {self.name} = {value:g}; valid: >= {self.minimum:g} {self.unit}".rstrip()
            )

    def _kind_text(self) -> str:
        return {
            "float": "a number",
            "int": "an integer",
            "bool": "true or false",
            "str": "a string",
            "float_list": "a list of numbers such as [0.0, 1.5]",
        }[self.kind]


#: The loop thread's scheduling, the same parameter on every loop node.
REALTIME_PRIORITY = ParamSpec(
    "realtime_priority",
    "int",
    0,
    "SCHED_FIFO priority 1..99 of the loop thread and, while it runs, of the threads it waits on: "
    "the executor's and the middleware's receive threads (0 = normal scheduling; needs root/CAP_SYS_NICE)",
    minimum=0,
)

#: Under normal scheduling, the loop thread's EEVDF slice (see rate_loop.set_scheduler_slice).
SCHEDULER_SLICE = ParamSpec(
    "scheduler_slice",
    "float",
    0.0001,
    "time slice the loop thread asks the kernel for under normal scheduling: a short one lets it "
    "preempt other threads when its period comes (Linux 6.12+, no privilege; the kernel keeps it "
    "within 0.0001-0.1; 0 = the kernel's default)",
    "s",
    minimum=0.0,
)


def declare_parameters(node: Node, specs: Sequence[ParamSpec]) -> dict[str, object]:
    """Declare every parameter on ``node`` and return the checked values by name.

    Raises:
        InvalidArgumentError: a value of the wrong type or outside its range.
    """
    values: dict[str, object] = {}
    for spec in specs:
        if spec.default is None:
            # No default: declared without a value; "not set" reads back as None.
            parameter = node.declare_parameter(spec.name, None, spec.descriptor())
        else:
            parameter = node.declare_parameter(spec.name, spec.default, spec.descriptor())
        value = parameter.value
        if parameter.type_ == Parameter.Type.NOT_SET:
            value = None
        values[spec.name] = spec.coerce(value)
    return values


class LiveParameters:
    """Run-time changes of a node's tunable parameters, checked as at start.

    Registered as the node's on-set-parameters callback: every value of a set request is
    coerced and checked by its :class:`ParamSpec`; when all pass, ``apply(updates)`` gets
    the checked values by name and returns None (the node now uses them) or the reason it
    cannot use them (the request is refused, nothing changes). Parameters not in ``specs``
    (``use_sim_time``...) are left to rclpy.

    Args:
        node: the node.
        specs: its parameter table.
        apply: ``apply({name: value}) -> None | reason``; called in the executor thread.
    """

    def __init__(self, node: Node, specs: Sequence[ParamSpec], apply: Callable[[dict[str, object]], str | None]):
        self._specs = {spec.name: spec for spec in specs}
        self._apply = apply
        self._logger = node.get_logger()
        node.add_on_set_parameters_callback(self._on_set)

    def _on_set(self, parameters: list[Parameter]) -> SetParametersResult:
        updates: dict[str, object] = {}
        for parameter in parameters:
            spec = self._specs.get(parameter.name)
            if spec is None:
                continue
            if not spec.tunable:
                return _refused(f"parameter {spec.name} is read-only: structural, set at start (restart the node)")
            value = None if parameter.type_ == Parameter.Type.NOT_SET else parameter.value
            try:
                updates[spec.name] = spec.coerce(value)
            except InvalidArgumentError as error:
                return _refused(str(error))
        if not updates:
            return SetParametersResult(successful=True)
        problem = self._apply(updates)
        if problem:
            return _refused(problem)
        self._logger.info("parameters set: " + ", ".join(f"{name} = {value!r}" for name, value in updates.items()))
        return SetParametersResult(successful=True)


def _refused(reason: str) -> SetParametersResult:
    return SetParametersResult(successful=False, reason=reason)


def usage_text(
    executable: str,
    summary: str,
    specs: Sequence[ParamSpec],
    subscribes: Sequence[tuple[str, str, str]],
    publishes: Sequence[tuple[str, str, str]],
    example: str,
    extra_help: str = "",
    services: Sequence[tuple[str, str, str]] = (),
) -> str:
    """The ``--help`` text of a node executable.

    Args:
        executable: executable name.
        summary: what the node does (a few lines).
        specs: its parameters.
        subscribes: ``(topic, type, note)`` per input topic.
        publishes: ``(topic, type, note)`` per output topic.
        example: example command line(s).
        extra_help: lines for parameters declared once the model is known (after the table).
        services: ``(name, type, note)`` per service.
    """
    lines = [f"usage: {executable} [--help] [--ros-args -p NAME:=VALUE ... | --params-file FILE | -r FROM:=TO ...]", ""]
    lines += [
        summary.strip(),
        "",
        "Parameters (--ros-args -p NAME:=VALUE or --params-file FILE with /**: ros__parameters;",
        "those marked 'Settable at run time' also with `ros2 param set` on the running node):",
    ]
    lines += [spec.help_line() for spec in specs]
    if extra_help:
        lines.append(extra_help)
    lines += ["", "Subscribes:"]
    lines += [f"  {topic} ({msg_type}){': ' + note if note else ''}" for topic, msg_type, note in subscribes]
    lines += ["", "Publishes:"]
    lines += [f"  {topic} ({msg_type}){': ' + note if note else ''}" for topic, msg_type, note in publishes]
    if services:
        lines += ["", "Services:"]
        lines += [f"  {name} ({srv_type}){': ' + note if note else ''}" for name, srv_type, note in services]
    lines += ["", "Example:", f"  {example}"]
    return "\n".join(lines)
