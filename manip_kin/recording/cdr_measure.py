"""Measure CDR buffers without decoding them: the real length, and a header stamp.

``rclpy.serialization.serialize_message`` sizes its buffer with the type
support's *estimate*, which can exceed the bytes actually written (an empty
``JointState`` is 36 bytes of CDR in a 44-byte buffer whose tail is
uninitialised memory). Readers that check the length, such as ``rosbags``
("CDR message size mismatch"), reject such buffers, so the writer trims each
one to the length computed here. Bytes received from DDS are already exact.

CDR (XCDR1, as ROS 2 uses): a 4-byte encapsulation header (``00 01`` little
endian, ``00 00`` big endian), then the fields in order, each primitive aligned
to its own size relative to the end of the header; strings and sequences are
a ``uint32`` count followed by the elements (strings count their NUL).
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from manip_kin.recording.msgdef import ArrayKind, Definitions, FieldSpec, normalize_type_name

ENCAPSULATION_SIZE = 4

_PRIMITIVE_SIZES = {
    "bool": 1,
    "byte": 1,
    "char": 1,
    "int8": 1,
    "uint8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "float32": 4,
    "int64": 8,
    "uint64": 8,
    "float64": 8,
}

# (buffer, position after the encapsulation header, little_endian) -> position after the value
Skipper = Callable[[bytes, int, bool], int]

_U32 = {True: struct.Struct("<I"), False: struct.Struct(">I")}
_STAMP = {True: struct.Struct("<iI"), False: struct.Struct(">iI")}


def _count(data: bytes, pos: int, little: bool) -> tuple[int, int]:
    """Read the uint32 count at ``pos`` (aligned to 4); return (count, position after it)."""
    pos = (pos + 3) & ~3
    (value,) = _U32[little].unpack_from(data, ENCAPSULATION_SIZE + pos)
    return value, pos + 4


def _skip_string(data: bytes, pos: int, little: bool) -> int:
    length, pos = _count(data, pos, little)
    return pos + length  # the count includes the terminating NUL


def _skip_wstring(data: bytes, pos: int, little: bool) -> int:
    # Fast-CDR 2 (Jazzy) writes a character count, then each character as a 4-byte wchar_t.
    length, pos = _count(data, pos, little)
    return pos + 4 * length


def _primitive_skipper(size: int) -> Skipper:
    mask = size - 1

    def skip(data: bytes, pos: int, little: bool) -> int:
        return ((pos + mask) & ~mask) + size

    return skip


class CdrLayout:
    """Compiled skip functions for every type of a definition set.

    Args:
        definitions: ``{pkg/msg/Type: fields}`` (see :func:`msgdef.local_definitions`).
    """

    def __init__(self, definitions: Definitions):
        self._definitions = definitions
        self._skippers: dict[str, Skipper] = {}

    def skipper(self, type_name: str) -> Skipper:
        """The function that skips one value of ``type_name`` in a CDR buffer."""
        name = normalize_type_name(type_name)
        if name not in self._skippers:
            # Placeholder first: a self-referencing type would otherwise recurse forever.
            self._skippers[name] = lambda data, pos, little: self._skippers[name](data, pos, little)
            fields = [self._field_skipper(f) for f in self._definitions[name]]

            def skip_struct(data: bytes, pos: int, little: bool, fields=fields) -> int:
                for skip_field in fields:
                    pos = skip_field(data, pos, little)
                return pos

            self._skippers[name] = skip_struct
        return self._skippers[name]

    def _element_skipper(self, field: FieldSpec) -> tuple[Skipper, int]:
        """Skip function of one element and its fixed size (0 when variable)."""
        if field.base_type in _PRIMITIVE_SIZES:
            size = _PRIMITIVE_SIZES[field.base_type]
            return _primitive_skipper(size), size
        if field.base_type == "string":
            return _skip_string, 0
        if field.base_type == "wstring":
            return _skip_wstring, 0
        return self.skipper(field.base_type), 0

    def _field_skipper(self, field: FieldSpec) -> Skipper:
        element, size = self._element_skipper(field)
        if field.array is ArrayKind.NONE:
            return element
        if field.array is ArrayKind.FIXED:
            count = field.array_size
            if size:
                mask = size - 1
                return lambda data, pos, little: ((pos + mask) & ~mask) + size * count

            def skip_fixed(data: bytes, pos: int, little: bool) -> int:
                for _ in range(count):
                    pos = element(data, pos, little)
                return pos

            return skip_fixed
        if size:
            mask = size - 1

            def skip_primitive_sequence(data: bytes, pos: int, little: bool) -> int:
                count, pos = _count(data, pos, little)
                # An empty sequence adds no alignment padding after its count.
                return ((pos + mask) & ~mask) + size * count if count else pos

            return skip_primitive_sequence

        def skip_sequence(data: bytes, pos: int, little: bool) -> int:
            count, pos = _count(data, pos, little)
            for _ in range(count):
                pos = element(data, pos, little)
            return pos

        return skip_sequence

    def message_length(self, type_name: str, data: bytes) -> int:
        """Bytes of ``data`` (encapsulation header included) that the message really uses.

        Returns ``len(data)`` for an encapsulation this module does not know
        (only plain CDR little/big endian is measured).

        Raises:
            struct.error: when ``data`` is shorter than its own counts say.
        """
        if len(data) < ENCAPSULATION_SIZE or data[0] != 0 or data[1] > 1:
            return len(data)
        little = data[1] == 1
        end = self.skipper(type_name)(data, 0, little)
        return ENCAPSULATION_SIZE + end


def header_stamp_ns(data: bytes) -> int | None:
    """Nanoseconds of the leading ``std_msgs/Header`` stamp of a CDR buffer, or None if unset.

    Only valid for types whose first field is a Header (see
    :func:`msgdef.has_header_first`): its ``int32 sec, uint32 nanosec`` then sit
    right after the encapsulation header. A zero or negative stamp counts as unset.
    """
    if len(data) < ENCAPSULATION_SIZE + 8 or data[0] != 0 or data[1] > 1:
        return None
    sec, nanosec = _STAMP[data[1] == 1].unpack_from(data, ENCAPSULATION_SIZE)
    if sec < 0 or (sec == 0 and nanosec == 0):
        return None
    return sec * 1_000_000_000 + nanosec
