"""Bundled robots and the one entry point that turns a name or a file into a model.

The bundled YAML files live in ``config/robots/``. They are found, in order: in the
ament index share directory (a colcon/ROS install), next to the package in a source
checkout (also what ``pip install -e`` gives), and under ``<prefix>/share/manip_kin``
(a plain ``pip install``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import sys
from pathlib import Path

from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError, UnknownRobotError

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
    candidates.append(Path(__file__).resolve().parents[2] / "config")  # the source tree: manip_kin/core/ -> repo
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
def _load_cached(key: str, mtime: float, links: tuple[str | None, str | None, str | None]) -> RobotModel:
    # The type is the content's (robot_file_kind), not the name's: a symlink named .urdf may
    # point at a file without that suffix.
    from manip_kin.core.robot_files import read_robot_file, robot_file_kind

    shown = key
    data = read_robot_file(key)
    if robot_file_kind(data) == "urdf":
        from manip_kin.core.urdf import load_urdf_string

        base_link, tip_link, tool_link = links
        return load_urdf_string(data, source=shown, base_link=base_link, tip_link=tip_link, tool_link=tool_link)
    if any(links):
        given = ", ".join(f"{name}={value!r}" for name, value in zip(LINK_PARAMETERS, links) if value)
        raise InvalidArgumentError(
            f"{given} given for robot {shown!r}, which is not a URDF; valid: link names select the chain "
            "of a URDF file only (a robot YAML lists its own joints)"
        )
    from manip_kin.core.loaders import model_from_dict
    from manip_kin.core.robot_files import parse_yaml

    return model_from_dict(parse_yaml(data, shown), shown, Path(key).parent)


def resolve_robot_path(robot: str | os.PathLike) -> Path:
    """The file behind a bundled robot name or a path (any regular file: its content says
    whether it is a URDF or a robot YAML); :class:`UnknownRobotError` otherwise."""
    text = str(robot).strip()
    bundled = bundled_robot_files()
    if text in bundled:
        return bundled[text]
    path = Path(text).expanduser()
    if path.is_file():
        return path.resolve()
    raise UnknownRobotError(text, bundled)


def load_robot(
    robot: str | os.PathLike,
    base_link: str | None = None,
    tip_link: str | None = None,
    tool_link: str | None = None,
) -> RobotModel:
    """Load a bundled robot by name, or a robot YAML or URDF file by path.

    Args:
        robot: bundled name or file path.
        base_link, tip_link, tool_link: the chain of a URDF (see :mod:`manip_kin.core.urdf`);
            None or "" = the default. A robot YAML names its own chain, so they must be
            unset for one.

    Models are immutable, so repeated loads of an unchanged file return the same object.

    Raises:
        UnknownRobotError: neither a bundled name nor a robot file.
        InvalidArgumentError: links given for a robot YAML.
        ModelFileError: a malformed file, or links that do not make a chain.
    """
    path = resolve_robot_path(robot)
    links = (base_link or None, tip_link or None, tool_link or None)
    return _load_cached(str(path), path.stat().st_mtime, links)


#: The chain-selecting parameter names, in (base, tip, tool) order.
LINK_PARAMETERS = ("base_link", "tip_link", "tool_link")


def with_velocity_limits(model: RobotModel, limits) -> RobotModel:
    """``model`` with every joint's velocity limit replaced by ``limits`` [rad/s | m/s], shape (n,).

    For a URDF that gives no limits (velocity missing or 0), or to run slower than it says.

    Raises:
        InvalidArgumentError: not one positive number per joint.
    """
    values = [float(v) for v in limits]
    if len(values) != model.dof:
        raise InvalidArgumentError(
            f"velocity_limits has {len(values)} values; valid: one per joint, {model.dof} for {model.name} "
            f"({', '.join(model.joint_names)})"
        )
    bad = [
        f"{name}={value:g}"
        for name, value in zip(model.joint_names, values)
        if not (value > 0 and not math.isnan(value))
    ]
    if bad:
        raise InvalidArgumentError(f"velocity_limits {', '.join(bad)}; valid: speeds > 0 [rad/s | m/s]")
    joints = tuple(dataclasses.replace(joint, velocity_limit=value) for joint, value in zip(model.joints, values))
    return dataclasses.replace(model, joints=joints)
