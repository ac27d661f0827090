"""Parameters on a running node: declared from a node's table at start, changed live.

A node gets its parameters as a typed struct generated from its table
(:mod:`manip_kin.ros.runtime.param_struct`): :func:`declare_parameters` at start, a new one on
every accepted live change.

Parameters are declared with their :meth:`~manip_kin.ros.runtime.params.ParamSpec.descriptor`
(description with units, ``dynamic_typing``) and the values checked by
:meth:`~manip_kin.ros.runtime.params.ParamSpec.coerce`; a bad one stops the node with a one-line
error (exit 2 through ``run_node``).

Live tuning: a ``tunable`` parameter can be set on the running node through the standard
parameter services (``ros2 param set``, ``rclpy.parameter_client.AsyncParameterClient``).
:class:`LiveParameters` checks the new value with the same ``coerce`` as at start and hands it to
the node, which rebuilds its core object with it; an invalid value is refused with the reason in
the ``SetParametersResult``. The other parameters are structural and read-only.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.runtime.param_struct import ParamStruct
from manip_kin.ros.runtime.params import ParamSpec, quoted

P = TypeVar("P", bound=ParamStruct)


def declare_parameters(node: Node, struct: type[P]) -> P:
    """Declare every parameter of ``struct``'s table on ``node``; the checked values as a ``struct``
    (see :func:`~manip_kin.ros.runtime.param_struct.param_struct`).

    Raises:
        InvalidArgumentError: a value of the wrong type or outside its range.
    """
    return struct.from_values(declared_values(node, struct.SPECS))


def declare_group(node: Node, params: P, specs: Sequence[ParamSpec]) -> P:
    """Declare a group of parameters known only at run time (``joint_limits.<joint>.<field>``,
    once the model is) on ``node``: ``params`` with their checked values in its ``dynamic``."""
    return params.replace(declared_values(node, specs))


def declared_values(node: Node, specs: Sequence[ParamSpec]) -> dict[str, object]:
    """Declare every parameter of ``specs`` on ``node`` and return the checked values by name.

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
    coerced and checked by its :class:`ParamSpec`; when all pass, ``apply(params)`` gets a new
    struct, the current one with the new values, and returns None (the node now uses it) or the
    reason it cannot (the request is refused, nothing changes; :attr:`params` stays). Parameters
    not in the struct's table or ``group`` (``use_sim_time``...) are left to rclpy.

    Args:
        node: the node.
        params: its parameters as declared (:func:`declare_parameters`, :func:`declare_group`).
        apply: ``apply(params) -> None | reason``; called in the executor thread.
        group: the specs of the parameters declared with :func:`declare_group`.
    """

    def __init__(self, node: Node, params: P, apply: Callable[[P], str | None], group: Sequence[ParamSpec] = ()):
        self._specs = {spec.name: spec for spec in (*params.SPECS, *group)}
        self.params = params
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
            if parameter.type_ == Parameter.Type.NOT_SET:
                return _refused(f"parameter {spec.name} cannot be unset; valid: {spec.constraint_text() or spec.kind}")
            try:
                updates[spec.name] = spec.coerce(parameter.value)
            except InvalidArgumentError as error:
                return _refused(str(error))
        if not updates:
            return SetParametersResult(successful=True)
        try:
            params = self.params.replace(updates)
            problem = self._apply(params)
        except Exception as error:  # noqa: BLE001 - an exception here would end the executor: refuse instead
            self._logger.error(f"setting {', '.join(updates)} failed: {type(error).__name__}: {error}"[:MAX_REASON])
            problem = f"the node could not use it: {type(error).__name__}: {error}"
        if problem:
            return _refused(problem)
        self.params = params
        self._logger.info(
            "parameters set: " + ", ".join(f"{name} = {quoted(value)}" for name, value in updates.items())
        )
        return SetParametersResult(successful=True)


#: Longest refusal reason [characters] (the reason of a SetParametersResult).
MAX_REASON = 400


def _refused(reason: str) -> SetParametersResult:
    if len(reason) > MAX_REASON:
        reason = reason[: MAX_REASON - 3] + "..."
    return SetParametersResult(successful=False, reason=reason)
