"""A recording whose disk fails (full, quota, I/O error): end what is on disk cleanly.

:class:`WholeWrites` is the stream the MCAP writer writes through: unbuffered, every write
whole or an :class:`OSError` (a short write on a full disk is never silently dropped); it
remembers where the last whole write (a record boundary) ended, and keeps a small reserve
of disk space. After a failure :func:`end_at_last_flush` frees the reserve, cuts the file at
that boundary (the half-written chunk goes) and ends it with a data-end record, a footer and
the closing magic: every chunk written before the failure stays readable (readers scan a
file without a summary section), and ``manip_kin info --salvage`` makes a complete copy.
"""

from __future__ import annotations

import contextlib
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


#: Bytes kept free on the recording's disk, in a hidden file next to it, for ending the file
#: after the disk filled up (a file system allocates whole blocks: the ending's 50 bytes may
#: need a new one).
RESERVE_BYTES = 64 * 1024


class WholeWrites:
    """An unbuffered binary file for the MCAP writer: whole writes or OSError; tracks the flushed end.

    It holds :data:`RESERVE_BYTES` in ``.<name>.reserve`` next to the file while it is open
    (removed by :meth:`close`, and first thing after a failure, to make room for the ending).
    """

    def __init__(self, path: Path):
        self._file = open(path, "wb", buffering=0)  # noqa: SIM115 - closed by close()
        self.flushed_end = 0  # bytes of the file that end with a complete record
        self._reserve: Path | None = path.parent / f".{path.name}.reserve"
        try:
            self._reserve.write_bytes(b"\0" * RESERVE_BYTES)
        except OSError:  # no room even for that: the ending may then not fit
            self.release_reserve()

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

    def release_reserve(self) -> None:
        """Give the reserved bytes back to the disk (idempotent, never raises)."""
        if self._reserve is not None:
            try:
                self._reserve.unlink(missing_ok=True)
            except OSError:
                pass
            self._reserve = None

    def close(self) -> None:
        self.release_reserve()
        self._file.close()

    @property
    def closed(self) -> bool:
        return self._file.closed


class DiskGuard:
    """The recording's file (a :class:`WholeWrites`) and what happens when its disk fails.

    Attributes:
        stream: what the MCAP writer writes to.
        failure: the one :class:`RecordingWriteError`, once the disk failed.
        kept_messages: messages complete in the file (all of them after a normal close).
    """

    def __init__(self, path: Path):
        self.path = path
        self.stream = WholeWrites(path)
        self.failure: RecordingWriteError | None = None
        self.kept_messages = 0

    @contextlib.contextmanager
    def guard(self, kept_if_written: int | None = None):
        """Turn an OSError of the disk into the one :class:`RecordingWriteError`, the file ended first.

        ``kept_if_written``: the messages the file holds when a write got out before the one
        that failed (a chunk, then its message index): that chunk is complete on disk.
        """
        before = self.stream.flushed_end
        try:
            yield
        except OSError as error:
            if kept_if_written is not None and self.stream.flushed_end != before:
                self.kept_messages = kept_if_written
            raise self.fail(error) from None

    def fail(self, error: OSError) -> RecordingWriteError:
        """End the file at the last complete record (once) and return the failure."""
        if self.failure is None:
            ended = end_at_last_flush(self.stream)
            kept = "ended after them" if ended else "cut after them (no room left to end it)"
            self.failure = RecordingWriteError(
                f"writing {self.path} failed: {error.strerror or error}; the {self.kept_messages} messages "
                f"flushed before are kept, the file {kept}; `manip_kin info --salvage OUT {self.path}` "
                "makes it a complete recording"
            )
        return self.failure


def end_at_last_flush(stream: WholeWrites) -> bool:
    """Cut the file at the last complete flush and try to end it; True when the ending fit.

    Never raises: it runs after the disk failed once already.
    """
    ended = False
    stream.release_reserve()
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
