"""The intermediate form of generated code: fragments of statements and the values they define.

An emitter (a chain's kinematics, ``J Jᵀ``, a Cholesky factor, the pose error, ...) returns a
:class:`Fragment`: its statements and its outputs. An output is a :data:`Value`: a float, a
constant known when the code is generated (a structural zero of the Jacobian, a unit entry),
or the name of a local, possibly negated (``"-v3"``: sign flips cost nothing). The next emitter
takes those values; nothing is parsed back from text, and constants are folded where they are
used (:func:`product`, :func:`total`).

Every local of a generated function comes from its one :class:`Names`, which also holds the
function's parameters and the globals it reads: two emitters cannot pick the same name.
"""

from __future__ import annotations

import builtins
import keyword
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

#: A constant (float), a local's name, or a negated name ``"-name"``.
Value = float | str

T = TypeVar("T")


class Names:
    """The names of one generated function: reserved ones (parameters, globals) and fresh locals.

    Python's builtins are reserved from the start (generated code calls ``abs`` and ``max``).

    Args:
        reserved: the function's parameters and the globals its code reads.

    Raises:
        ValueError: a reserved name is not an identifier, or is given twice.
    """

    def __init__(self, reserved: Iterable[str] = ()):
        self._taken: set[str] = set(vars(builtins))
        self._next: dict[str, int] = {}
        self.reserve(*reserved)

    def reserve(self, *names: str) -> None:
        """Take these exact names (a parameter, a global the code reads).

        Raises:
            ValueError: a name is not an identifier, or is already taken.
        """
        for name in names:
            if not name.isidentifier() or keyword.iskeyword(name):
                raise ValueError(f"{name!r} is not a Python name")
            if name in self._taken:
                raise ValueError(f"{name!r} is already taken")
            self._taken.add(name)

    def fresh(self, prefix: str) -> str:
        """A new local ``prefix`` + a number, different from every name taken so far."""
        if not (prefix + "0").isidentifier():
            raise ValueError(f"{prefix!r} cannot start a Python name")
        number = self._next.get(prefix, 0)
        while f"{prefix}{number}" in self._taken:
            number += 1
        self._next[prefix] = number + 1
        name = f"{prefix}{number}"
        self._taken.add(name)
        return name

    def __contains__(self, name: str) -> bool:
        return name in self._taken


@dataclass
class Fragment(Generic[T]):
    """Statements and the values they define.

    ``lines`` are indented relative to where the fragment is placed (:func:`indented`);
    ``outputs`` has the shape its emitter documents (a tuple of :data:`Value`, a factor, ...).
    """

    lines: list[str] = field(default_factory=list)
    outputs: T = None  # type: ignore[assignment]

    def constants(self) -> dict[int, float]:
        """Index -> value of the outputs known when the code was generated (a flat tuple's)."""
        return {index: value for index, value in enumerate(self.outputs) if isinstance(value, float)}


def indented(lines: Sequence[str], depth: int = 1) -> list[str]:
    """``lines`` placed ``depth`` levels (four spaces each) deeper."""
    pad = "    " * depth
    return [pad + line for line in lines]


def render(value: Value) -> str:
    """A value as an expression: a constant as its literal, a name as itself."""
    return repr(value) if isinstance(value, float) else value


def product(a: Value, b: Value) -> Value:
    """``a * b`` as a constant or an expression; names may carry a leading minus (folded)."""
    if isinstance(a, float) and isinstance(b, float):
        return a * b
    if isinstance(a, float) or isinstance(b, float):
        constant, name = (a, b) if isinstance(a, float) else (b, a)
        if constant == 0.0:
            return 0.0
        if name.startswith("-"):
            constant, name = -constant, name[1:]
        if constant == 1.0:
            return name
        if constant == -1.0:
            return f"-{name}"
        return f"{constant!r}*{name}"
    negative = a.startswith("-") != b.startswith("-")
    term = f"{a.lstrip('-')}*{b.lstrip('-')}"
    return f"-{term}" if negative else term


#: Terms per bracket in a generated sum: ``a + b + …`` nests one level of the syntax tree per
#: term, and Python's compiler recurses on it (a 3000-joint chain's ``J Jᵀ`` entries hit its
#: recursion limit). Longer sums are bracketed in groups; sums of up to this many terms (every
#: arm's) are left as they are, so their floating-point result does not change.
SUM_GROUP = 64


def total(terms: Sequence[Value]) -> str:
    """``Σ terms`` as an expression: constants added up, negative terms subtracted.

    More than :data:`SUM_GROUP` terms are summed in brackets of that many, so the expression's
    nesting stays shallow however many joints the chain has.
    """
    constant = sum(t for t in terms if isinstance(t, float))
    parts = [t for t in terms if not isinstance(t, float)]
    if constant != 0.0 or not parts:
        parts.append(repr(constant))
    while len(parts) > SUM_GROUP:
        parts = [f"({_joined(parts[i : i + SUM_GROUP])})" for i in range(0, len(parts), SUM_GROUP)]
    return _joined(parts)


def _joined(parts: Sequence[str]) -> str:
    expression = parts[0]
    for part in parts[1:]:
        expression += f" - {part[1:]}" if part.startswith("-") else f" + {part}"
    return expression
