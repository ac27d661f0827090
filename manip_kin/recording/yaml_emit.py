"""A YAML emitter with yaml-cpp's block layout, for the text rosbag2 writes.

rosbag2 writes ``offered_qos_profiles`` and ``metadata.yaml`` with yaml-cpp:
two-space indentation, sequence items indented under their key (``key:\\n  - a``),
``~`` for null, ``""`` for an empty string, ``[]``/``{}`` for empty collections,
no trailing newline from ``YAML::Dump``. Matching it keeps files diffable
against a ``ros2 bag record`` of the same run; any YAML parser reads either.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence

_PLAIN_SAFE = re.compile(r"^[A-Za-z_/][A-Za-z0-9_./\-]*$")
_PLAIN_RESERVED = frozenset({"y", "n", "yes", "no", "on", "off", "true", "false", "null", "~"})


def scalar(value: object) -> str:
    """One scalar as yaml-cpp writes it (strings quoted only when they must be)."""
    if value is None:
        return "~"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    text = str(value)
    if _PLAIN_SAFE.match(text) and text.lower() not in _PLAIN_RESERVED:
        return text
    return json.dumps(text, ensure_ascii=False)  # a JSON string is a valid double-quoted YAML one


def _is_collection(value: object) -> bool:
    return isinstance(value, Mapping) or (isinstance(value, Sequence) and not isinstance(value, (str, bytes)))


def _emit(value: object, indent: int, lines: list[str], prefix: str) -> None:
    """Append ``value`` to ``lines``; ``prefix`` is what precedes it on its first line."""
    pad = " " * indent
    if isinstance(value, Mapping):
        if not value:
            lines.append(f"{prefix}{{}}")
            return
        first = True
        for key, item in value.items():
            lead = prefix if first else pad
            first = False
            if _is_collection(item) and item:
                lines.append(f"{lead}{scalar(key)}:")
                child_indent = indent + 2
                _emit(item, child_indent, lines, " " * child_indent)
            else:
                _emit(item, indent + 2, lines, f"{lead}{scalar(key)}: ")
        return
    if _is_collection(value):
        if not value:
            lines.append(f"{prefix}[]")
            return
        first = True
        for item in value:
            lead = prefix if first else pad
            first = False
            # The item's own lines continue two columns right of the dash.
            _emit(item, indent + 2, lines, f"{lead}- ")
        return
    lines.append(f"{prefix}{scalar(value)}")


def dump(value: object) -> str:
    """``YAML::Dump`` of ``value`` (dicts keep their order; no trailing newline)."""
    lines: list[str] = []
    _emit(value, 0, lines, "")
    return "\n".join(lines)
