"""Where a recording goes: a single ``.mcap`` file or a rosbag2 bag directory ``NAME/NAME_0.mcap``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from manip_kin.recording.errors import RecordingError


@dataclass(frozen=True)
class OutputLayout:
    """Where a recording goes.

    Attributes:
        mcap_path: the MCAP file written.
        bag_directory: the bag directory, or None for a single ``.mcap`` file.
    """

    mcap_path: Path
    bag_directory: Path | None


def resolve_output(output: str | Path, overwrite: bool = True) -> OutputLayout:
    """Turn an ``output`` argument into file paths (and create parent directories).

    Args:
        output: ``something.mcap`` for a single file, anything else for a bag directory.
        overwrite: replace an existing ``.mcap`` file; a non-empty bag directory is
            never reused (as rosbag2 refuses it), since it may hold another recording.

    Raises:
        RecordingError: when the path cannot be used.
    """
    path = Path(output).expanduser()
    if path.suffix == ".mcap":
        if path.is_dir():
            raise RecordingError(f"output {str(path)!r} is a directory; a .mcap output must be a file")
        if path.exists() and not overwrite:
            raise RecordingError(f"output {str(path)!r} exists; choose another path or delete it")
        path.parent.mkdir(parents=True, exist_ok=True)
        return OutputLayout(path, None)
    if path.exists() and (not path.is_dir() or any(path.iterdir())):
        raise RecordingError(
            f"output {str(path)!r} exists and is not an empty directory; give a new bag "
            "directory name or a path ending in .mcap"
        )
    path.mkdir(parents=True, exist_ok=True)
    return OutputLayout(path / f"{path.name}_0.mcap", path)
