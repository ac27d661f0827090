"""RIHS01: the ROS Interface Hash (REP-2011, ``RIHS01_<sha256>``) of a message type, as rosidl
computes it from the type description (type_description_interfaces/TypeDescription), from the
field lists of :mod:`manip_kin.recording.msgdef`; or the one rosidl generated for an installed type.
"""

from __future__ import annotations

import functools
import hashlib
import json

from manip_kin.recording.errors import MessageDefinitionError
from manip_kin.recording.msgdef import (
    ArrayKind,
    Definitions,
    FieldSpec,
    definitions_from_schema,
    find_interface_file,
    local_definitions,
    normalize_type_name,
)

# .msg primitive → FieldType id (via the IDL type rosidl_adapter maps it to: char → uint8,
# byte → octet, float64 → double, ...). Ids from type_description_interfaces/msg/FieldType.msg.
_FIELD_TYPE_IDS = {
    "int8": 2,
    "uint8": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "char": 3,
    "bool": 15,
    "byte": 16,
    "string": 17,
    "wstring": 18,
}
_NESTED_TYPE_ID = 1
_BOUNDED_STRING_IDS = {"string": 21, "wstring": 22}
_ARRAY_ID_OFFSET = {ArrayKind.NONE: 0, ArrayKind.FIXED: 48, ArrayKind.BOUNDED: 96, ArrayKind.UNBOUNDED: 144}


def _field_description(field: FieldSpec) -> dict:
    if field.is_nested:
        base_id = _NESTED_TYPE_ID
    elif field.string_bound and field.base_type in _BOUNDED_STRING_IDS:
        base_id = _BOUNDED_STRING_IDS[field.base_type]
    else:
        base_id = _FIELD_TYPE_IDS[field.base_type]
    return {
        "name": field.name,
        "type": {
            "type_id": base_id + _ARRAY_ID_OFFSET[field.array],
            "capacity": field.array_size,
            "string_capacity": field.string_bound,
            "nested_type_name": field.base_type if field.is_nested else "",
        },
    }


def type_description(type_name: str, definitions: Definitions) -> dict:
    """The hashable TypeDescription of ``type_name`` (default values left out, as rosidl hashes).

    Raises:
        MessageDefinitionError: when a referenced type is missing from ``definitions``.
    """
    root = normalize_type_name(type_name)

    def individual(name: str) -> dict:
        if name not in definitions:
            raise MessageDefinitionError(f"definition of {root!r} uses {name!r}, which the schema does not contain")
        return {"type_name": name, "fields": [_field_description(f) for f in definitions[name]]}

    referenced: set[str] = set()
    pending = [f.base_type for f in definitions.get(root, ()) if f.is_nested]
    while pending:
        name = pending.pop()
        if name not in referenced:
            referenced.add(name)
            pending.extend(f.base_type for f in definitions.get(name, ()) if f.is_nested)
    return {
        "type_description": individual(root),
        "referenced_type_descriptions": [individual(n) for n in sorted(referenced)],
    }


def rihs01_hash(type_name: str, definitions: Definitions) -> str:
    """``RIHS01_<sha256 hex>`` of the type description, as rosidl computes it (REP-2011)."""
    text = json.dumps(
        type_description(type_name, definitions),
        ensure_ascii=True,
        allow_nan=False,
        indent=None,
        separators=(", ", ": "),  # rosidl's separators; part of the hashed bytes
        sort_keys=False,
    )
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def rihs01_from_schema(type_name: str, schema_text: str) -> str:
    """RIHS01 hash computed from a ``ros2msg`` schema text alone."""
    return rihs01_hash(type_name, definitions_from_schema(type_name, schema_text))


@functools.cache
def rosidl_type_hash(type_name: str) -> str | None:
    """The hash rosidl generated for an installed type (``share/<pkg>/msg/<Type>.json``), or None."""
    root = normalize_type_name(type_name)
    try:
        path = find_interface_file(root, ".json")
        document = json.loads(path.read_text(encoding="utf-8"))
    except (MessageDefinitionError, OSError, ValueError):
        return None
    for entry in document.get("type_hashes", []):
        if entry.get("type_name") == root:
            return str(entry.get("hash_string"))
    return None


def type_hash(type_name: str) -> str:
    """RIHS01 hash of an installed type: rosidl's, else computed from its ``.msg`` files."""
    return rosidl_type_hash(type_name) or rihs01_hash(type_name, local_definitions(type_name))
