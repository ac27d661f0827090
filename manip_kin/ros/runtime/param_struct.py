"""Typed parameter structs generated from a node's :class:`~manip_kin.ros.runtime.params.ParamSpec`
table, as ``generate_parameter_library`` generates them in ROS 2 C++.

:func:`param_struct` makes one frozen dataclass type per table, a field per parameter, named as
the parameter and typed from its kind (``float``, ``int``, ``bool``, ``str``, a tuple of floats or
strings for the list kinds; ``| None`` where the parameter has no default), with a docstring that
lists every field with its unit and what it does. A node reads ``params.max_linear_velocity``, not
``values["max_linear_velocity"]``: a misspelt name is an AttributeError where it is written, and
the table is the one place a parameter is named and typed.

Groups declared once the model is known (``joint_limits.<joint>.<field>``: dotted, one per joint,
not known when the type is made) are not fields: they are in :attr:`ParamStruct.dynamic`, a
read-only mapping by full name. A struct never changes; a live parameter change makes a new one
(:meth:`ParamStruct.replace`, see :class:`~manip_kin.ros.runtime.declared_params.LiveParameters`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import ClassVar

from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.runtime.params import ParamSpec, quoted

#: The Python type of each parameter kind (lists are tuples: a struct is immutable).
KIND_TYPES: dict[str, type] = {
    "float": float,
    "int": int,
    "bool": bool,
    "str": str,
    "float_list": tuple,
    "str_list": tuple,
}
_ITEM_TYPES = {"float_list": float, "str_list": str}
#: The annotation of each kind's field (``| None`` added where a parameter has no default).
FIELD_TYPES: dict[str, object] = {
    "float": float,
    "int": int,
    "bool": bool,
    "str": str,
    "float_list": tuple[float, ...],
    "str_list": tuple[str, ...],
}


#: The field of the groups declared at run time (see the module docstring).
DYNAMIC = "dynamic"


class ParamStruct:
    """The base of the generated structs: construction checks every field's type; see :func:`param_struct`."""

    #: The table the type was generated from.
    SPECS: ClassVar[tuple[ParamSpec, ...]] = ()

    def __post_init__(self):
        for spec in self.SPECS:
            value = getattr(self, spec.name)
            typed = typed_value(spec, value, type(self).__name__)
            if typed is not value:
                object.__setattr__(self, spec.name, typed)
        object.__setattr__(self, DYNAMIC, MappingProxyType(dict(getattr(self, DYNAMIC))))

    @classmethod
    def from_values(cls, values: Mapping[str, object]):
        """The struct of ``values`` by parameter name: one per field; the others go to :attr:`dynamic`.

        Raises:
            InvalidArgumentError: a field missing from ``values``, or a value of the wrong type.
        """
        names = {spec.name for spec in cls.SPECS}
        missing = sorted(names - set(values))
        if missing:
            raise InvalidArgumentError(f"{cls.__name__}: no value for {', '.join(missing)}")
        fields = {name: values[name] for name in names}
        return cls(**fields, **{DYNAMIC: {k: v for k, v in values.items() if k not in names}})

    def replace(self, updates: Mapping[str, object]):
        """A new struct with ``updates`` (by parameter name; a dotted one goes to :attr:`dynamic`)."""
        names = {spec.name for spec in self.SPECS}
        dynamic = {**getattr(self, DYNAMIC), **{k: v for k, v in updates.items() if k not in names}}
        return dataclasses.replace(self, **{k: v for k, v in updates.items() if k in names}, **{DYNAMIC: dynamic})


def typed_value(spec: ParamSpec, value, struct: str = ""):
    """``value`` when it has ``spec``'s type (a list of a list kind as a tuple); InvalidArgumentError
    naming the parameter otherwise. A bool is no number; None only where there is no default."""
    kind = spec.kind
    if value is None and spec.default is None:
        return None
    expected = KIND_TYPES[kind]
    if kind in _ITEM_TYPES and isinstance(value, (list, tuple)):
        item = _ITEM_TYPES[kind]
        if all(isinstance(v, item) and not isinstance(v, bool) for v in value):
            return tuple(value)
    elif isinstance(value, expected) and (kind == "bool" or not isinstance(value, bool)):
        return value
    owner = f"{struct}." if struct else "parameter "
    raise InvalidArgumentError(
        f"{owner}{spec.name} = {quoted(value)} ({type(value).__name__}) has the wrong type; "
        f"valid: {_type_text(spec).replace(' | None', ' or None')}"
    )


def param_struct(name: str, specs: Sequence[ParamSpec], summary: str = "") -> type[ParamStruct]:
    """A frozen dataclass type named ``name`` with one typed field per parameter of ``specs``.

    Args:
        name: the type's name (``ControllerParams``).
        specs: the node's parameter table; every name must be an identifier (a dotted group
            declared at run time goes to :attr:`ParamStruct.dynamic` instead).
        summary: the first line of the docstring.

    Raises:
        ValueError: a name that is no identifier, or twice in ``specs``, or ``dynamic``.
    """
    names = [spec.name for spec in specs]
    bad = sorted({n for n in names if not n.isidentifier() or names.count(n) > 1 or n == DYNAMIC})
    if bad:
        raise ValueError(f"{name}: parameter names that cannot be fields: {', '.join(bad)}")
    fields = [(spec.name, field_type(spec)) for spec in specs]
    fields.append((DYNAMIC, Mapping[str, object], dataclasses.field(default_factory=dict, hash=False)))
    struct = dataclasses.make_dataclass(
        name, fields, bases=(ParamStruct,), frozen=True, namespace={"SPECS": tuple(specs)}
    )
    struct.__doc__ = _docstring(summary or f"The parameters of a node, typed ({len(specs)}).", specs)
    return struct


def field_type(spec: ParamSpec):
    """The annotation of ``spec``'s field: the kind's type, ``| None`` without a default."""
    kind_type = FIELD_TYPES[spec.kind]
    return kind_type | None if spec.default is None else kind_type


def _type_text(spec: ParamSpec) -> str:
    text = getattr(FIELD_TYPES[spec.kind], "__name__", None) if spec.kind not in _ITEM_TYPES else None
    text = text or f"tuple[{_ITEM_TYPES[spec.kind].__name__}, ...]"
    return text + (" | None" if spec.default is None else "")


def _docstring(summary: str, specs: Sequence[ParamSpec]) -> str:
    lines = [summary, "", "Generated from the ParamSpec table by param_struct.", "", "Attributes:"]
    for spec in specs:
        unit = f" [{spec.unit}]" if spec.unit else ""
        live = " Settable at run time." if spec.tunable else ""
        lines.append(f"    {spec.name} ({_type_text(spec)}){unit}: {spec.description}.{live}")
    lines.append(f"    {DYNAMIC} (Mapping[str, object]): the parameters declared at run time, by full name.")
    return "\n".join(lines)
