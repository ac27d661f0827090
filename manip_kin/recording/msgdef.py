"""ROS 2 message definitions: find them, encode them as rosbag2 does, parse them.

A rosbag2 MCAP file stores, per message type, a schema of encoding ``ros2msg``:
the ``.msg`` text of the type followed by the text of every type it uses, each
once, each introduced by a line of 80 ``=`` and ``MSG: pkg/Type``. The order
is rosbag2 Jazzy's (``LocalMessageDefinitionSource::get_full_text``): depth
first, dependencies of one definition in sorted order, the names exactly as
they are written in the field declarations.

The same text, parsed back into field lists, gives the ROS Interface Hash
(REP-2011, ``RIHS01_<sha256>``) that rosidl computes from the type
description (:mod:`manip_kin.recording.type_hash`), and the layout needed to measure a CDR
buffer (:mod:`manip_kin.recording.cdr_measure`).
"""

from __future__ import annotations

import enum
import functools
import os
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from manip_kin.recording.errors import MessageDefinitionError

SEPARATOR_LINE = "=" * 80

# The primitive names rosbag2 skips when it looks for dependencies.
PRIMITIVE_TYPES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
    }
)
# ``wstring`` is primitive too, but rosbag2's list omits it; it only matters for parsing.
_ALL_PRIMITIVES = PRIMITIVE_TYPES | {"wstring"}

# rosbag2's dependency scan: the first word of every line (array suffix dropped).
_FIELD_TYPE_PATTERN = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_TYPE_NAME_PATTERN = re.compile(r"^([a-zA-Z0-9_]+)/(?:msg/)?([a-zA-Z0-9_]+)$")
_TYPE_TOKEN_PATTERN = re.compile(
    r"^(?P<base>[A-Za-z][A-Za-z0-9_]*(?:/[A-Za-z][A-Za-z0-9_]*){0,2})"
    r"(?:<=(?P<string_bound>\d+))?"
    r"(?:\[(?P<array>(?:<=)?\d*)\])?$"
)
_CONSTANT_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9_]*\s*=")
_FIELD_NAME_PATTERN = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)")


def normalize_type_name(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` → ``pkg/msg/Type``.

    Raises:
        MessageDefinitionError: for anything else (services, actions, typos).
    """
    match = _TYPE_NAME_PATTERN.match(type_name)
    if not match:
        raise MessageDefinitionError(f"message type {type_name!r} is not of the form 'pkg/msg/Type' or 'pkg/Type'")
    return f"{match.group(1)}/msg/{match.group(2)}"


def _split_type_name(type_name: str) -> tuple[str, str]:
    package, _, name = normalize_type_name(type_name).partition("/msg/")
    return package, name


def share_prefixes() -> list[Path]:
    """Install prefixes searched for ``share/<pkg>/msg/<Type>.msg``, in order.

    ``AMENT_PREFIX_PATH`` first (a ROS install, or the Makefile's venv), then the
    running interpreter's prefix, where the ``ros-*`` wheels put their share files.
    """
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for extra in (sys.prefix, sys.base_prefix):
        if Path(extra) not in prefixes:
            prefixes.append(Path(extra))
    return prefixes


def find_interface_file(type_name: str, suffix: str = ".msg") -> Path:
    """The installed ``share/<pkg>/msg/<Type><suffix>`` of a message type.

    Raises:
        MessageDefinitionError: when no prefix has it; names the prefixes searched.
    """
    package, name = _split_type_name(type_name)
    for prefix in share_prefixes():
        candidate = prefix / "share" / package / "msg" / f"{name}{suffix}"
        if candidate.is_file():
            return candidate
    searched = ", ".join(str(p) for p in share_prefixes())
    raise MessageDefinitionError(
        f"no share/{package}/msg/{name}{suffix} for message type {type_name!r} under {searched}; "
        f"install the package that defines it (e.g. ros-jazzy-{package.replace('_', '-')})"
    )


# Definitions of types manip_kin writes without an installed package: ``tf2_msgs`` is not
# on PyPI, yet every recording carries ``/tf``. The text is geometry2's ``TFMessage.msg``.
BUNDLED_MSG_TEXTS = {
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
}


@functools.cache
def read_msg_text(type_name: str) -> str:
    """The installed ``.msg`` text of a type, exactly as on disk (else a bundled one, see above)."""
    try:
        return find_interface_file(type_name, ".msg").read_text(encoding="utf-8")
    except MessageDefinitionError:
        bundled = BUNDLED_MSG_TEXTS.get(normalize_type_name(type_name))
        if bundled is None:
            raise
        return bundled


def msg_dependencies(text: str, package: str) -> list[str]:
    """Non-primitive field types of one ``.msg`` text, sorted, as rosbag2 finds them.

    Names keep the spelling of the declaration (``std_msgs/Header``); a bare
    ``Type`` is resolved in ``package``. Like rosbag2, this scans the first word of
    every line, so constants' primitive types are skipped and comments never match.
    """
    found: set[str] = set()
    for match in _FIELD_TYPE_PATTERN.finditer(text):
        word = match.group(1)
        if word in PRIMITIVE_TYPES:
            continue
        found.add(word if "/" in word else f"{package}/{word}")
    return sorted(found)


def full_definition_text(type_name: str) -> str:
    """The ``ros2msg`` schema text rosbag2 Jazzy writes for ``type_name``.

    Args:
        type_name: ``pkg/msg/Type`` (or ``pkg/Type``).

    Returns:
        The root ``.msg`` text, then for each dependency (depth first, sorted,
        each once): ``"\\n" + 80 "=" + "\\nMSG: pkg/Type\\n" + its text``.
    """
    seen: set[str] = set()

    def append_recursive(name: str, depth: int) -> str:
        if depth <= 0:
            raise MessageDefinitionError(f"message definition of {type_name!r} nests too deeply")
        package, _ = _split_type_name(name)
        text = read_msg_text(normalize_type_name(name))
        result = text
        for dependency in msg_dependencies(text, package):
            if dependency not in seen:
                seen.add(dependency)
                result += f"\n{SEPARATOR_LINE}\nMSG: {dependency}\n"
                result += append_recursive(dependency, depth - 1)
        return result

    return append_recursive(type_name, 50)


def split_definition_text(root_type: str, schema_text: str) -> dict[str, str]:
    """Split a ``ros2msg`` schema back into ``{pkg/msg/Type: msg text}``.

    Raises:
        MessageDefinitionError: when a section header is not ``MSG: pkg/Type``.
    """
    sections: dict[str, str] = {}
    current_name = normalize_type_name(root_type)
    current_lines: list[str] = []
    lines = schema_text.split("\n")
    index = 0
    while index < len(lines):
        line = lines[index]
        if line.rstrip("\r") == SEPARATOR_LINE:
            sections.setdefault(current_name, "\n".join(current_lines))
            header = lines[index + 1].strip() if index + 1 < len(lines) else ""
            if not header.startswith("MSG:"):
                raise MessageDefinitionError(
                    f"schema of {root_type!r}: expected 'MSG: pkg/Type' after the separator, got {header!r}"
                )
            current_name = normalize_type_name(header[len("MSG:") :].strip())
            current_lines = []
            index += 2
            continue
        current_lines.append(line)
        index += 1
    sections.setdefault(current_name, "\n".join(current_lines))
    return sections


class ArrayKind(enum.Enum):
    """How a field repeats its base type."""

    NONE = "none"
    FIXED = "fixed"  # T[N]: exactly N, no length prefix in CDR
    BOUNDED = "bounded"  # T[<=N]: a length prefix, at most N
    UNBOUNDED = "unbounded"  # T[]: a length prefix


@dataclass(frozen=True)
class FieldSpec:
    """One field of a message definition.

    Attributes:
        name: field name.
        base_type: a primitive (``float64``, ``string``, ...) or ``pkg/msg/Type``.
        string_bound: N of ``string<=N`` (0 when unbounded or not a string).
        array: array kind of the field.
        array_size: N of ``T[N]`` or ``T[<=N]`` (0 otherwise).
    """

    name: str
    base_type: str
    string_bound: int = 0
    array: ArrayKind = ArrayKind.NONE
    array_size: int = 0

    @property
    def is_nested(self) -> bool:
        """True when the base type is another message."""
        return "/" in self.base_type


# ROS 2 adds this member to a message without fields (C and DDS have no empty structs).
EMPTY_STRUCT_FIELD = FieldSpec("structure_needs_at_least_one_member", "uint8")


def _strip_comment(line: str) -> str:
    quote = ""
    for position, char in enumerate(line):
        if quote:
            if char == quote:
                quote = ""
        elif char in "\"'":
            quote = char
        elif char == "#":
            return line[:position]
    return line


def parse_msg_fields(text: str, package: str, type_name: str = "") -> tuple[FieldSpec, ...]:
    """Fields of one ``.msg`` text, in order, constants and comments dropped.

    Args:
        text: the ``.msg`` text.
        package: package of the message, for bare nested names (``Type``).
        type_name: for error messages only.

    Raises:
        MessageDefinitionError: on a line that is not ``TYPE name [default]``.
    """
    fields: list[FieldSpec] = []
    for line_number, raw_line in enumerate(text.split("\n"), start=1):
        line = _strip_comment(raw_line).strip()
        if not line:
            continue
        type_token, _, rest = line.partition(" ")
        rest = rest.strip()
        if not rest and "\t" in type_token:
            type_token, _, rest = type_token.partition("\t")
            rest = rest.strip()
        if _CONSTANT_PATTERN.match(rest):
            continue
        token = _TYPE_TOKEN_PATTERN.match(type_token)
        name = _FIELD_NAME_PATTERN.match(rest)
        if not token or not name:
            raise MessageDefinitionError(
                f"definition of {type_name or package!r}, line {line_number}: {raw_line!r} is "
                "not 'TYPE name', 'TYPE name default' or 'TYPE NAME=value'"
            )
        base = token.group("base")
        if base not in _ALL_PRIMITIVES:
            base = normalize_type_name(base if "/" in base else f"{package}/{base}")
        array_text = token.group("array")
        if array_text is None:
            array, size = ArrayKind.NONE, 0
        elif array_text == "":
            array, size = ArrayKind.UNBOUNDED, 0
        elif array_text.startswith("<="):
            array, size = ArrayKind.BOUNDED, int(array_text[2:])
        else:
            array, size = ArrayKind.FIXED, int(array_text)
        fields.append(
            FieldSpec(
                name=name.group(1),
                base_type=base,
                string_bound=int(token.group("string_bound") or 0),
                array=array,
                array_size=size,
            )
        )
    return tuple(fields) if fields else (EMPTY_STRUCT_FIELD,)


Definitions = Mapping[str, tuple[FieldSpec, ...]]


def definitions_from_schema(root_type: str, schema_text: str) -> dict[str, tuple[FieldSpec, ...]]:
    """Parse a ``ros2msg`` schema into ``{pkg/msg/Type: fields}`` for every type in it."""
    definitions = {}
    for name, text in split_definition_text(root_type, schema_text).items():
        package, _ = _split_type_name(name)
        definitions[name] = parse_msg_fields(text, package, name)
    return definitions


@functools.cache
def local_definitions(type_name: str) -> Mapping[str, tuple[FieldSpec, ...]]:
    """``{pkg/msg/Type: fields}`` of a type and everything it uses, from installed files."""
    root = normalize_type_name(type_name)
    return definitions_from_schema(root, full_definition_text(root))


def has_header_first(type_name: str, definitions: Definitions) -> bool:
    """True when the first field is a ``std_msgs/Header`` (so CDR starts with its stamp)."""
    fields = definitions[normalize_type_name(type_name)]
    first = fields[0]
    return first.base_type == "std_msgs/msg/Header" and first.array is ArrayKind.NONE
