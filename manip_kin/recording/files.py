"""Find and check a recording's MCAP files (a single ``.mcap`` or a rosbag2 bag directory).

Shared by :mod:`.info`, :mod:`.messages` and :mod:`.salvage`: which files a recording is,
whether each is complete (has its footer), and the errors a damaged file can raise.
"""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import yaml
import zstandard
from mcap.exceptions import McapError

from manip_kin.recording.errors import CorruptRecordingError, RecordingError
from manip_kin.recording.metadata import METADATA_FILENAME

MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_AND_MAGIC = 1 + 8 + 8 + 8 + 4 + len(MCAP_MAGIC)  # opcode, length, 2 offsets, crc, magic
# Errors a damaged file can raise from the mcap library, zstd, lz4 or struct decoding.
DECODE_ERRORS = (
    McapError,
    EOFError,
    ValueError,
    struct.error,
    zlib.error,
    zstandard.ZstdError,
    RuntimeError,
    OSError,
    KeyError,
    IndexError,
    UnicodeDecodeError,
)


def salvage_hint(path: Path) -> str:
    return f"`manip_kin info --salvage OUT {path}` recovers its readable part"


def recording_files(path: str | Path) -> list[Path]:
    """The MCAP files of a recording: the file itself, or a bag directory's files.

    Raises:
        RecordingError: when the path does not exist or holds no ``.mcap`` file.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file or directory; expected a .mcap file or a bag directory")
    if path.is_file():
        return [path]
    metadata_path = path / METADATA_FILENAME
    if metadata_path.is_file():
        try:
            document = yaml.safe_load(metadata_path.read_text(encoding="utf-8"))
            names = document["rosbag2_bagfile_information"]["relative_file_paths"]
        except (yaml.YAMLError, KeyError, TypeError) as error:
            raise CorruptRecordingError(
                f"{metadata_path}: not a rosbag2 metadata file ({type(error).__name__}: {error})"
            ) from None
        files = [path / Path(name).name for name in names]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise RecordingError(f"{path}: metadata.yaml lists missing files: {', '.join(missing)}")
        if any(f.suffix != ".mcap" for f in files):
            raise RecordingError(f"{path}: only MCAP storage is supported, metadata lists {names}")
        return files
    files = sorted(path.glob("*.mcap"))
    if not files:
        raise RecordingError(f"{path}: a directory without metadata.yaml or .mcap files is not a recording")
    return files


def check_complete(path: Path) -> None:
    """Raise unless ``path`` starts and ends with the MCAP magic (has its footer).

    Raises:
        CorruptRecordingError: naming what is wrong (empty, not MCAP, truncated).
    """
    size = path.stat().st_size
    if size == 0:
        raise CorruptRecordingError(f"{path} is empty (0 bytes): nothing was ever flushed to it")
    with open(path, "rb") as stream:
        head = stream.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise CorruptRecordingError(
                f"{path} is not an MCAP file: it starts with {head[:8]!r}, an MCAP file with {MCAP_MAGIC!r}"
            )
        if size < len(MCAP_MAGIC) + _FOOTER_AND_MAGIC:
            raise CorruptRecordingError(f"{path} is truncated ({size} bytes, no footer); {salvage_hint(path)}")
        stream.seek(-len(MCAP_MAGIC), os.SEEK_END)
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise CorruptRecordingError(
                f"{path} is truncated: it has no footer (was the recorder killed?); {salvage_hint(path)}"
            )
