"""The pieces of CDR every message is made of: the encapsulation header, alignment (relative
to the payload, after the 4-byte header), stamps, NUL-terminated strings with a ``uint32``
length; as a ``struct`` layout built once for fixed-shape messages (:class:`CdrLayout`), a
writer for variable ones (:class:`CdrWriter`) and a reader (:class:`CdrReader`)."""

from __future__ import annotations

import struct

__all__ = ["CDR_LE", "CdrLayout", "CdrReader", "CdrWriter", "align", "stamp_parts"]

#: Encapsulation header: plain CDR, little endian (what rmw_fastrtps and rmw_cyclonedds write).
CDR_LE = b"\x00\x01\x00\x00"
_NS_PER_S = 1_000_000_000
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


def align(offset: int, size: int) -> int:
    """``offset`` rounded up to a multiple of ``size`` (a power of two: 1, 2, 4 or 8)."""
    return offset + (-offset) % size


def stamp_parts(stamp_ns: int) -> tuple[int, int]:
    """``builtin_interfaces/Time`` (sec, nanosec) of a time [ns]."""
    return divmod(int(stamp_ns), _NS_PER_S)


class CdrLayout:
    """Builds a ``struct`` format with CDR alignment (relative to the payload start)."""

    def __init__(self):
        self.parts = ["<4s"]  # the encapsulation header, not part of the aligned payload
        self.offset = 0

    def align(self, size: int) -> None:
        pad = (-self.offset) % size
        if pad:
            self.parts.append(f"{pad}x")
            self.offset += pad

    def add(self, code: str, size: int, count: int = 1) -> None:
        self.align(size)
        self.parts.append(f"{count}{code}" if count != 1 else code)
        self.offset += size * count

    def add_string(self, text: str) -> bytes:
        data = text.encode() + b"\x00"
        self.add("I", 4)
        self.parts.append(f"{len(data)}s")
        self.offset += len(data)
        return data

    def header(self, frame_id: str) -> bytes:
        """``std_msgs/Header``: stamp (sec, nanosec), then frame_id; returns the frame bytes."""
        self.add("i", 4)
        self.add("I", 4)
        return self.add_string(frame_id)

    def compile(self) -> struct.Struct:
        return struct.Struct("".join(self.parts))


class CdrWriter:
    """Little-endian CDR of a message of any shape, field by field."""

    def __init__(self):
        self._body = bytearray()  # the payload: positions count from here

    def pad(self, size: int) -> None:
        self._body.extend(b"\x00" * (align(len(self._body), size) - len(self._body)))

    def pack(self, packer: struct.Struct, *values, alignment: int) -> None:
        """``values`` by ``packer`` (little endian), aligned to ``alignment`` bytes."""
        self.pad(alignment)
        self._body.extend(packer.pack(*values))

    def count(self, length: int) -> None:
        """A sequence's length (``uint32``), before its elements."""
        self.pack(_U32, length, alignment=4)

    def stamp(self, stamp_ns: int) -> None:
        """A ``builtin_interfaces/Time`` (sec, nanosec) of a time [ns]."""
        self.pack(_STAMP, *stamp_parts(stamp_ns), alignment=4)

    def string(self, text: str) -> None:
        """A ``uint32`` length (the NUL counted), the UTF-8 bytes and a NUL."""
        self.strings((text,))

    def strings(self, texts) -> None:
        """:meth:`string` of each of ``texts`` in turn (one loop: a status has ~80 of them)."""
        body, pack = self._body, _U32.pack
        for text in texts:
            encoded = text.encode("utf-8")
            body += b"\x00" * (-len(body) % 4)
            body += pack(len(encoded) + 1)
            body += encoded
            body.append(0)

    def bytes(self) -> bytes:
        """The message: encapsulation header and payload."""
        return CDR_LE + bytes(self._body)


class CdrReader:
    """Reads a plain CDR message (little or big endian) field by field.

    Raises:
        ValueError: ``data`` is not plain CDR (on construction), or ends inside a field.
    """

    def __init__(self, data: bytes):
        if len(data) < 8 or data[0] != 0 or data[1] > 1:
            raise ValueError("not a plain CDR buffer")
        self._order = "<" if data[1] == 1 else ">"
        self._body = memoryview(data)[4:]
        self.position = 0

    def read(self, fmt: str, size: int, alignment: int) -> tuple:
        """The values of ``fmt`` (``struct`` codes without byte order; ``size`` bytes) at the
        next ``alignment``-aligned position."""
        self.position = align(self.position, alignment)
        try:
            values = struct.unpack_from(self._order + fmt, self._body, self.position)
        except struct.error as error:
            raise ValueError(f"CDR ends inside a field at byte {self.position}: {error}") from None
        self.position += size
        return values

    def string(self) -> str:
        (length,) = self.read("I", 4, 4)
        end = self.position + length
        if length < 1 or end > len(self._body):
            raise ValueError(f"a string of {length} bytes at byte {self.position} runs past the data")
        text = bytes(self._body[self.position : end - 1]).decode("utf-8")
        self.position = end
        return text
