"""A recording whose disk fails (full, quota, I/O error): end what is on disk cleanly.

:class:`WholeWrites` is the stream the MCAP writer writes through: unbuffered, every write
whole or an :class:`OSError` (a short write on a full disk is never silently dropped), and
it remembers where the last whole write (a record boundary) ended. After a failure :func:`end_at_last_flush`
cuts the file there (the half-written chunk goes, which frees its bytes) and ends it with a
data-end record, a footer and the closing magic, when those ~50 bytes still fit: every chunk
flushed before the failure stays readable, and ``manip_kin info --salvage`` turns the file
into a complete one (it has no summary section).
"""

from __future__ import annotations

import errno
import os
import struct
from pathlib import Path

from manip_kin.errors import OperationError

_MAGIC = b"\x89MCAP0\r\n"
# DataEnd (crc 0), Footer (no summary: offsets 0, crc 0), magic.
ENDING = bytes([0x0F]) + struct.pack("<QI", 4, 0) + bytes([0x02]) + struct.pack("<QQQI", 20, 0, 0, 0) + _MAGIC


class RecordingWriteError(OperationError):
    """Writing a recording failed (disk full, I/O error): what was flushed before is kept."""


class WholeWrites:
    """An unbuffered binary file for the MCAP writer: whole writes or OSError; tracks the flushed end."""

    def __init__(self, path: Path):
        self._file = open(path, "wb", buffering=0)  # noqa: SIM115 - closed by close()
        self.flushed_end = 0  # bytes of the file that end with a complete record

    def write(self, data) -> int:
        view = memoryview(data)
        while view:
            written = self._file.write(view)
            if not written:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            view = view[written:]
        # The MCAP writer writes whole records in one call: the file now ends at a record boundary.
        self.flushed_end = self._file.tell()
        return len(data)

    def tell(self) -> int:
        return self._file.tell()

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        return self._file.seek(offset, whence)

    def flush(self) -> None:
        pass  # unbuffered: every write is already with the OS

    def fileno(self) -> int:
        return self._file.fileno()

    def close(self) -> None:
        self._file.close()

    @property
    def closed(self) -> bool:
        return self._file.closed


def end_at_last_flush(stream: WholeWrites) -> bool:
    """Cut the file at the last complete flush and try to end it; True when the ending fit.

    Never raises: it runs after the disk failed once already.
    """
    ended = False
    try:
        os.ftruncate(stream.fileno(), stream.flushed_end)
        stream.seek(stream.flushed_end)
        try:
            stream.write(ENDING)
            ended = True
        except OSError:
            os.ftruncate(stream.fileno(), stream.flushed_end)
    except OSError:
        pass
    try:
        stream.close()
    except OSError:
        pass
    return ended
