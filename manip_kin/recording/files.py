"""Find and check a recording's MCAP files (a single ``.mcap`` or a rosbag2 bag directory).

Shared by :mod:`.info`, :mod:`.messages` and :mod:`.salvage`: which files a recording is,
whether each is complete (has its footer), and the errors a damaged file can raise.
"""

from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import zstandard
from mcap.exceptions import McapError

from manip_kin.errors import bounded_repr
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
    OverflowError,  # a length of 2**64 - 1 used as a size
    MemoryError,
)
#: Largest bag ``metadata.yaml`` read [bytes].
MAX_METADATA_BYTES = 4 * 2**20


def salvage_hint(path: Path) -> str:
    return f"`manip_kin info --salvage OUT {path}` recovers its readable part"


def recording_files(path: str | Path) -> list[Path]:
    """The MCAP files of a recording: the file itself, or a bag directory's files.

    A bag's files must lie in the bag directory: ``metadata.yaml`` names plain file names,
    and a ``.mcap`` that is a symlink leading outside the directory is refused (its bytes
    are never read, so none of them reach a message).

    Raises:
        RecordingError: when the path does not exist or holds no ``.mcap`` file.
        CorruptRecordingError: a ``metadata.yaml`` that is not rosbag2 metadata.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file or directory; expected a .mcap file or a bag directory")
    if path.is_file():
        return [path]
    metadata_path = path / METADATA_FILENAME
    if metadata_path.is_file():
        # Older rosbag2 wrote "<bag>/<file>": only the file name counts, so no entry leaves the bag.
        files = [path / Path(name).name for name in _metadata_file_names(metadata_path)]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise RecordingError(f"{path}: metadata.yaml lists missing files: {', '.join(missing)}")
        if any(f.suffix != ".mcap" for f in files):
            raise RecordingError(f"{path}: only MCAP storage is supported, metadata lists {[f.name for f in files]}")
    else:
        files = sorted(path.glob("*.mcap"))
        if not files:
            raise RecordingError(f"{path}: a directory without metadata.yaml or .mcap files is not a recording")
    inside = path.resolve()
    for file_path in files:
        if inside not in file_path.resolve().parents:
            raise RecordingError(
                f"{file_path} leads outside the bag directory {path} (a symlink?); valid: files inside the bag"
            )
    return files


def _metadata_file_names(metadata_path: Path) -> list[str]:
    """``relative_file_paths`` of a bag's metadata, checked: a list of plain file names."""
    from manip_kin.core.robot_files import parse_yaml
    from manip_kin.errors import ModelFileError

    def refuse(problem: str) -> CorruptRecordingError:
        return CorruptRecordingError(f"{metadata_path}: not rosbag2 metadata: {problem}")

    try:
        with open(metadata_path, "rb") as stream:
            data = stream.read(MAX_METADATA_BYTES + 1)
        document = parse_yaml(data, str(metadata_path), max_bytes=MAX_METADATA_BYTES)
    except OSError as error:
        raise refuse(f"cannot read it ({error.strerror})") from None
    except ModelFileError as error:
        raise refuse(f"{error.field}: {error.problem}") from None
    information = document.get("rosbag2_bagfile_information") if isinstance(document, dict) else None
    if not isinstance(information, dict):
        raise refuse("valid: a mapping with a 'rosbag2_bagfile_information' mapping")
    names = information.get("relative_file_paths")
    if not isinstance(names, list) or not all(isinstance(name, str) for name in names):
        raise refuse(f"relative_file_paths is {bounded_repr(names)}; valid: a list of file names")
    return names


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
