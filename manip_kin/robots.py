"""Bundled robots and the one entry point that turns a name or a file into a model.

The bundled YAML files live in ``config/robots/``. They are found, in order: in the
ament index share directory (a colcon/ROS install), next to the package in a source
checkout (also what ``pip install -e`` gives), and under ``<prefix>/share/manip_kin``
(a plain ``pip install``).
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

from manip_kin.errors import UnknownRobotError
from manip_kin.model import RobotModel

PACKAGE = "manip_kin"


def _candidate_config_dirs() -> list[Path]:
    candidates = []
    if os.environ.get("AMENT_PREFIX_PATH"):
        try:
            from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

            try:
                candidates.append(Path(get_package_share_directory(PACKAGE)) / "config")
            except PackageNotFoundError:
                pass
        except ImportError:
            pass
    candidates.append(Path(__file__).resolve().parent.parent / "config")
    candidates.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    return candidates


@functools.lru_cache(maxsize=1)
def config_dir() -> Path:
    """The directory holding the bundled ``robots/`` and parameter files."""
    for candidate in _candidate_config_dirs():
        if (candidate / "robots").is_dir():
            return candidate
    searched = ", ".join(str(c) for c in _candidate_config_dirs())
    raise FileNotFoundError(f"manip_kin config directory not found; searched {searched}")


def bundled_robot_files() -> dict[str, Path]:
    """Bundled robot name -> YAML path, sorted by name."""
    robots_dir = config_dir() / "robots"
    return {path.stem: path for path in sorted(robots_dir.glob("*.yaml"))}


def bundled_robot_names() -> list[str]:
    """Names accepted by :func:`load_robot` without a path."""
    return list(bundled_robot_files())


@functools.lru_cache(maxsize=32)
def _load_cached(key: str, mtime: float) -> RobotModel:
    path = Path(key)
    if path.suffix.lower() in (".urdf", ".xml"):
        from manip_kin.urdf import load_urdf

        return load_urdf(path)
    from manip_kin.loaders import load_robot_yaml

    return load_robot_yaml(path)


def resolve_robot_path(robot: str | os.PathLike) -> Path:
    """The file behind a bundled robot name or a path; :class:`UnknownRobotError` otherwise."""
    text = str(robot).strip()
    bundled = bundled_robot_files()
    if text in bundled:
        return bundled[text]
    path = Path(text).expanduser()
    if path.is_file() and path.suffix.lower() in (".yaml", ".yml", ".urdf", ".xml"):
        return path.resolve()
    raise UnknownRobotError(text, bundled)


def load_robot(robot: str | os.PathLike) -> RobotModel:
    """Load a bundled robot by name, or a robot YAML or URDF file by path.

    Models are immutable, so repeated loads of an unchanged file return the same object.
    """
    path = resolve_robot_path(robot)
    return _load_cached(str(path), path.stat().st_mtime)
