"""MCAP records and chunks decoded within bounds: no length in a file is trusted.

A record is read only when its length fits in what is left of the file; a chunk is
decompressed to at most its declared uncompressed size, which must itself be at most
:data:`MAX_CHUNK_BYTES`, and its CRC is checked when it has one. So a length of 2⁶⁴−1, a
chunk declaring 1 TB or a 51 kB "zip bomb" that inflates to 1 GB is a
:class:`ChunkError` naming the offset, in bounded time and memory.

Readers (:mod:`.messages`, :mod:`.salvage`) work on a memory map of the file
(:func:`mapped`): slicing it reads only the pages that are used.
"""

from __future__ import annotations

import io
import mmap
import struct
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema

from manip_kin.recording.errors import CorruptRecordingError

#: Largest uncompressed chunk read [bytes]; the writer's chunks are 256 KiB (rosbag2's 768 KiB).
MAX_CHUNK_BYTES = 64 * 2**20
#: Largest ratio of a chunk's declared uncompressed size to its compressed size (above
#: :data:`MIN_CHUNK_BOUND`): recorded messages compress 3-50x, a "zip bomb" 1000x and more.
MAX_INFLATION = 1000
MIN_CHUNK_BOUND = 2**20
RECORD_HEADER_BYTES = 1 + 8  # opcode, length
_CHUNK_FIXED = struct.Struct("<QQQI")  # start, end, uncompressed size, crc
COMPRESSIONS = ("", "none", "zstd", "lz4")
MAGIC = b"\x89MCAP0\r\n"


class ChunkError(CorruptRecordingError):
    """A record or chunk that cannot be what it claims (length, size, compression, CRC)."""


class _ExactStream(ReadDataStream):
    """mcap's record reader over one record's bytes; a read past its end is an error."""

    def __init__(self, data: bytes | memoryview):
        super().__init__(io.BytesIO(data))

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise ChunkError(f"a field of {length} bytes runs past the end of its record")
        return data


@contextmanager
def mapped(path: Path) -> Iterator[mmap.mmap]:
    """The file memory-mapped: indexable, sliceable and a seekable stream (for mcap's
    readers, whose reads of a hostile length then return what is there instead of
    allocating it).

    Raises:
        ChunkError: for an empty file (nothing to map).
    """
    with open(path, "rb") as stream:
        if stream.seek(0, io.SEEK_END) == 0:
            raise ChunkError(f"{path} is empty (0 bytes)")
        with mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ) as memory:
            yield memory


def record_at(data, offset: int) -> tuple[int, memoryview | bytes, int]:
    """``(opcode, body, next offset)`` of the record at ``offset``.

    Raises:
        ChunkError: when the header or the body does not fit in ``data``.
    """
    if offset + RECORD_HEADER_BYTES > len(data):
        raise ChunkError(f"a record header at byte {offset} is cut off")
    opcode = data[offset]
    (length,) = struct.unpack_from("<Q", data, offset + 1)
    start = offset + RECORD_HEADER_BYTES
    if length > len(data) - start:
        raise ChunkError(f"the record at byte {offset} claims {length} bytes, {len(data) - start} are left")
    return opcode, data[start : start + length], start + length


def parse_chunk(body) -> Chunk:
    """A Chunk record's fields, every length checked against the body."""
    if len(body) < _CHUNK_FIXED.size + 4:
        raise ChunkError("a chunk record is shorter than its fixed fields")
    start, end, uncompressed_size, crc = _CHUNK_FIXED.unpack_from(body, 0)
    position = _CHUNK_FIXED.size
    (name_length,) = struct.unpack_from("<I", body, position)
    position += 4
    if name_length > 16 or position + name_length + 8 > len(body):
        raise ChunkError(f"a chunk's compression name claims {name_length} bytes")
    compression = bytes(body[position : position + name_length]).decode("ascii", "replace")
    position += name_length
    (data_length,) = struct.unpack_from("<Q", body, position)
    position += 8
    if data_length != len(body) - position:
        raise ChunkError(f"a chunk claims {data_length} data bytes, its record holds {len(body) - position}")
    if compression not in COMPRESSIONS:
        raise ChunkError(f"chunk compression {compression!r}; valid: {', '.join(c for c in COMPRESSIONS if c)}")
    check_declared_size(uncompressed_size, len(body) - position)
    return Chunk(
        compression=compression,
        data=bytes(body[position:]),
        message_end_time=end,
        message_start_time=start,
        uncompressed_crc=crc,
        uncompressed_size=uncompressed_size,
    )


def check_declared_size(declared: int, compressed: int) -> None:
    """Refuse a chunk whose declared uncompressed size is beyond the caps."""
    bound = min(MAX_CHUNK_BYTES, max(MIN_CHUNK_BOUND, MAX_INFLATION * compressed))
    if declared > bound:
        raise ChunkError(
            f"a chunk of {compressed} bytes declares {declared} uncompressed bytes; valid: at most {bound} "
            f"({MAX_INFLATION}x its size, {MAX_CHUNK_BYTES} in all)"
        )


def chunk_data(chunk: Chunk) -> bytes:
    """The uncompressed bytes of a chunk: at most its declared size, CRC checked when set.

    Raises:
        ChunkError: more or fewer bytes than declared, a decoder error, a CRC mismatch.
    """
    declared = chunk.uncompressed_size
    check_declared_size(declared, len(chunk.data))
    try:
        if chunk.compression == "zstd":
            # A bounded read: a frame header's own content size is not trusted either.
            parts, total = [], 0
            with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data)) as reader:
                while total <= declared and (part := reader.read(declared + 1 - total)):
                    parts.append(part)
                    total += len(part)
            data = b"".join(parts)
        elif chunk.compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=declared + 1)
        else:
            data = chunk.data
    except (zstandard.ZstdError, RuntimeError, ValueError, OSError) as error:
        raise ChunkError(f"a {chunk.compression} chunk does not decompress ({type(error).__name__})") from None
    if len(data) != declared:
        more = "more" if len(data) > declared else f"{len(data)}"
        raise ChunkError(f"a chunk declaring {declared} bytes inflates to {more} bytes")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ChunkError("a chunk's CRC does not match its data")
    return data


def chunk_records(chunk: Chunk) -> list[Schema | Channel | Message]:
    """The schema, channel and message records of a chunk (others skipped)."""
    data = chunk_data(chunk)
    records: list[Schema | Channel | Message] = []
    offset = 0
    while offset < len(data):
        opcode, body, offset = record_at(data, offset)
        if opcode not in PARSED_OPCODES:  # the only records a chunk may hold (MCAP spec)
            raise ChunkError(f"a chunk holds a record of opcode 0x{opcode:02x}; valid: schema, channel, message")
        records.append(parse_record(opcode, body))
    return records


PARSED_OPCODES = (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE)


def parse_record(opcode: int, body) -> Schema | Channel | Message:
    """A Schema, Channel or Message record from its body (mcap's parsers, exact lengths)."""
    stream = _ExactStream(body)
    try:
        if opcode == Opcode.SCHEMA:
            return Schema.read(stream)
        if opcode == Opcode.CHANNEL:
            return Channel.read(stream)
        if opcode == Opcode.MESSAGE:
            if len(body) < 22:
                raise ChunkError("a message record is shorter than its fixed fields")
            return Message.read(stream, len(body))
    except (struct.error, UnicodeDecodeError, ValueError, KeyError) as error:
        if isinstance(error, ChunkError):
            raise
        raise ChunkError(f"a record of opcode {opcode} does not parse ({type(error).__name__})") from None
    raise ChunkError(f"opcode {opcode} is not a schema, channel or message")


def top_level_records(opcode: int, body) -> list[Schema | Channel | Message]:
    """The schema, channel and message records a top-level record holds (a chunk's, or itself)."""
    if opcode == Opcode.CHUNK:
        return chunk_records(parse_chunk(body))
    if opcode in PARSED_OPCODES:
        return [parse_record(opcode, body)]
    if opcode not in KNOWN_OPCODES:
        raise ChunkError(f"opcode 0x{opcode:02x} is no MCAP record")
    return []


KNOWN_OPCODES = frozenset(int(opcode) for opcode in Opcode)


def walk(data) -> Iterator[tuple[int, int, memoryview | bytes, list[Schema | Channel | Message]]]:
    """``(offset, opcode, body, records)`` of every top-level record up to the footer, strictly.

    For a file without a summary section (a recording ended on a full disk): readers scan it.

    Raises:
        ChunkError: at the first record that is cut off or damaged.
    """
    offset = len(MAGIC)
    while offset < len(data):
        opcode, body, next_offset = record_at(data, offset)
        yield offset, opcode, body, top_level_records(opcode, body)
        if opcode == Opcode.FOOTER:
            return
        offset = next_offset
    raise ChunkError("the file ends before its footer")
