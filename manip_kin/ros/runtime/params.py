"""Node parameters: one table per node gives the declaration, the checks and the ``--help`` text.

This module is the table's row, :class:`ParamSpec`, and the rows every loop node shares;
declaring them on a node and live changes: :mod:`manip_kin.ros.runtime.declared_params`; the
``--help`` text: :mod:`manip_kin.ros.runtime.usage`.

Parameters are declared with a :class:`~rcl_interfaces.msg.ParameterDescriptor`
(description with units) and ``dynamic_typing`` so that ``-p rate_hz:=1000`` (an integer
on the command line) and ``-p initial_positions:=[0, 0, 0]`` work where a float is meant;
the value is then coerced and checked here, and a bad one stops the node with a one-line
error (exit 2 through ``run_node``).

Live tuning: a ``tunable`` parameter (gains, damping, tolerances, timeouts, limits) can be
set on the running node through the standard parameter services (``ros2 param set``,
``rclpy.parameter_client.AsyncParameterClient``): the new value is checked with the same
:meth:`ParamSpec.coerce` as at start and handed to the node, which rebuilds its core object
with it (:class:`~manip_kin.ros.runtime.declared_params.LiveParameters`); an invalid value is
refused with the reason in the ``SetParametersResult``. The other parameters are structural
(robot, links, rates, frames) and read-only: setting one is refused, and their description says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rcl_interfaces.msg import ParameterDescriptor

from manip_kin.errors import InvalidArgumentError

KINDS = ("float", "int", "bool", "str", "float_list", "str_list")

#: Longest string parameter [characters]: a path (PATH_MAX) or a link name fits.
MAX_TEXT_LENGTH = 4096

#: Most values in a ``float_list`` parameter: one per joint of any chain.
MAX_LIST_ITEMS = 10000

#: Characters of a refused value quoted in a message: a 100k-element list is not echoed.
QUOTE_LENGTH = 80


def quoted(value) -> str:
    """``repr(value)`` cut to :data:`QUOTE_LENGTH` characters, with the size of what was cut."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - an object whose repr fails is still refused by its type
        text = f"<{type(value).__name__}>"
    if len(text) <= QUOTE_LENGTH:
        return text
    size = f"{len(value)} items" if isinstance(value, (list, tuple)) else f"{len(text)} characters"
    return f"{text[: QUOTE_LENGTH - 3]}... ({size})"


def period_ns(rate_hz: float) -> int:
    """The period [ns] of a rate [Hz] from a checked parameter; 0 for a rate of 0 (off)."""
    return int(1e9 / rate_hz) if rate_hz > 0 else 0


def _is_number(value) -> bool:
    """An int or a float, not a bool and not a string (``"1.5"`` is text, not a number)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_text_list(value) -> bool:
    """A list or tuple of strings (a string alone is not a list of them)."""
    return isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)


@dataclass(frozen=True)
class ParamSpec:
    """One node parameter.

    Attributes:
        name: parameter name.
        kind: ``float``, ``int``, ``bool``, ``str``, ``float_list`` or ``str_list``.
        default: default value (None: no default, e.g. "the robot's start configuration").
        description: what it does, one sentence.
        unit: unit text such as ``Hz``, ``s``, ``1/s``, ``m`` ("" when none).
        minimum: smallest valid value for numbers (inclusive; per element of a
            ``float_list``), or None.
        maximum: largest valid value for numbers (inclusive; per element of a
            ``float_list``), or None.
        positive: True when the value must be > 0 (an exclusive minimum of 0).
        zero_is_off: 0 is valid too and turns the feature off; other values must be within
            ``minimum``..``maximum`` (a rate: 0 = off, a tiny one such as 1e-300 Hz is refused).
        choices: valid values for strings, or empty.
        default_text: how to show a None default (or a long list default) in ``--help``.
        tunable: settable on the running node (see
            :class:`~manip_kin.ros.runtime.declared_params.LiveParameters`); otherwise
            structural and read-only.

    Every number parameter of the nodes has both bounds, chosen so that no value within
    them can raise or produce a non-finite output in the loop (test/ros/nodes/test_parameter_ranges.py).
    """

    name: str
    kind: str
    default: object
    description: str
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    positive: bool = False
    zero_is_off: bool = False
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
        """Valid values in words, e.g. ``0 to 1000``, ``> 0 and <= 10``, ``0 (off) or 0.1 to 1000``."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        low, high = self.minimum, self.maximum
        if self.positive and (low is None or low <= 0):
            text = "> 0" if high is None else f"> 0 and <= {high:g}"
        elif low is not None and high is not None:
            text = f"{low:g} to {high:g}"
        elif low is not None:
            text = f">= {low:g}"
        elif high is not None:
            text = f"<= {high:g}"
        else:
            text = ""
        if self.kind == "float_list" and text:
            text = "each " + text
        return f"0 (off) or {text}" if self.zero_is_off else text

    def help_line(self) -> str:
        """One line for ``--help``: name, default, unit, valid values, description."""
        if self.default is None or self.default_text:
            default = self.default_text or "(none)"
        elif isinstance(self.default, str):
            default = repr(self.default)
        elif isinstance(self.default, bool):
            default = "true" if self.default else "false"
        else:
            default = str(self.default)
        unit = f" [{self.unit}]" if self.unit else ""
        choices = f" One of: {', '.join(self.choices)}." if self.choices else ""
        valid = f" Valid: {self.constraint_text()}." if self.kind in ("float", "int", "float_list") else ""
        valid = "" if valid == " Valid: ." else valid
        live = " Settable at run time." if self.tunable else ""
        return f"  {self.name} (default {default}){unit}: {self.description}.{choices}{valid}{live}"

    def coerce(self, value):
        """``value`` converted to this parameter's kind and checked; InvalidArgumentError otherwise.

        Strict types: a float parameter takes an int or a float (``-p rate_hz:=1000``), an
        int parameter an int (or an integral float); a bool or a string is never a number.
        """
        if value is None:
            return None
        if self.kind == "float" and _is_number(value):
            return self._checked(float(value))
        if self.kind == "int" and _is_number(value) and (isinstance(value, int) or value.is_integer()):
            return self._checked(int(value))
        if self.kind == "bool" and isinstance(value, bool):
            return value
        if self.kind == "str" and isinstance(value, str):
            if len(value) > MAX_TEXT_LENGTH:
                raise self._error(value, f"at most {MAX_TEXT_LENGTH} characters")
            if self.choices and value not in self.choices:
                raise self._error(value, ", ".join(self.choices))
            return value
        if self.kind == "float_list" and self._is_number_list(value):
            if len(value) > MAX_LIST_ITEMS:
                raise self._error(value, f"at most {MAX_LIST_ITEMS} numbers")
            result = [float(v) for v in value]
            for number in result:
                self._checked(number, value)
            return result
        if self.kind == "str_list" and _is_text_list(value):
            if len(value) > MAX_LIST_ITEMS:
                raise self._error(value, f"at most {MAX_LIST_ITEMS} strings")
            if any(len(text) > MAX_TEXT_LENGTH for text in value):
                raise self._error(value, f"strings of at most {MAX_TEXT_LENGTH} characters")
            return [str(text) for text in value]
        if self.kind not in KINDS:
            raise InvalidArgumentError(f"parameter {self.name}: unknown kind {self.kind!r}")
        kind = "text" if isinstance(value, str) else type(value).__name__
        raise InvalidArgumentError(
            f"parameter {self.name} = {quoted(value)} ({kind}) has the wrong type; valid: {self._kind_text()}"
        )

    @staticmethod
    def _is_number_list(value) -> bool:
        if isinstance(value, (str, bytes)):
            return False
        try:
            return all(_is_number(v) for v in value)
        except TypeError:  # not iterable
            return False

    def _checked(self, number, value=None):
        """``number`` when within the range; ``value`` is the whole list it is an element of."""
        shown = number if value is None else value
        if isinstance(number, float) and not math.isfinite(number):
            raise self._error(shown, "finite numbers" if value is not None else "a finite number")
        if self.zero_is_off and number == 0:
            return number
        low, high = self.minimum, self.maximum
        if (
            (self.positive and not number > 0)
            or (low is not None and number < low)
            or (high is not None and number > high)
        ):
            raise self._error(shown, f"{self.constraint_text()} {self.unit}".rstrip())
        return number

    def _error(self, value, valid: str) -> InvalidArgumentError:
        shown = f"{value:g}" if isinstance(value, float) else quoted(value)
        return InvalidArgumentError(f"parameter {self.name} = {shown}; valid: {valid}")

    def _kind_text(self) -> str:
        return {
            "float": "a number",
            "int": "an integer",
            "bool": "true or false",
            "str": "a string",
            "float_list": "a list of numbers such as [0.0, 1.5]",
            "str_list": "a list of strings such as [joint_states, /tf]",
        }[self.kind]


def loop_rate(description: str) -> ParamSpec:
    """``rate_hz`` of a loop node, 1 to 10000 Hz: below 1 Hz it is no control loop, and no loop
    here holds a period under 0.1 ms (the bounds also keep every period a finite number of ns)."""
    return ParamSpec("rate_hz", "float", 500.0, description, "Hz", minimum=1.0, maximum=1e4)


def diagnostics_rate(default: float, description: str, off: bool = False) -> ParamSpec:
    """``diagnostics_rate_hz``, 0.1 to 1000 Hz (``off``: 0 turns it off): a status every 10 s at
    the least, at most one per loop cycle of a 1 kHz loop; a tiny rate such as 1e-300 Hz (a
    period beyond any integer of ns) is refused."""
    return ParamSpec(
        "diagnostics_rate_hz",
        "float",
        default,
        description,
        "Hz",
        minimum=0.1,
        maximum=1e3,
        zero_is_off=off,
        tunable=True,
    )


#: The loop thread's scheduling, the same parameter on every loop node.
REALTIME_PRIORITY = ParamSpec(
    "realtime_priority",
    "int",
    0,
    "SCHED_FIFO priority 1..99 of the loop thread and, while it runs, of the threads it waits on: "
    "the executor's and the middleware's receive threads (0 = normal scheduling; needs root/CAP_SYS_NICE)",
    minimum=0,
    maximum=99,  # the range of SCHED_FIFO on Linux
)

#: Under normal scheduling, the loop thread's EEVDF slice (see scheduling.set_scheduler_slice).
SCHEDULER_SLICE = ParamSpec(
    "scheduler_slice",
    "float",
    0.0001,
    "time slice the loop thread asks the kernel for under normal scheduling: a short one lets it "
    "preempt other threads when its period comes (Linux 6.12+, no privilege; the kernel keeps it "
    "within 0.0001-0.1; 0 = the kernel's default)",
    "s",
    minimum=0.0,
    maximum=0.1,  # the kernel's own ceiling
)
