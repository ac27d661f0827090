"""Paths of the URDFs shipped by the ``example-robot-data`` PyPI package (tests and bench only).

The package installs its robots under ``site-packages/cmeel.prefix/share/example-robot-data/robots``.
"""

from __future__ import annotations

import site
import sysconfig
from pathlib import Path

_EXAMPLE_ROBOT_DATA_ROBOTS = Path("cmeel.prefix") / "share" / "example-robot-data" / "robots"

PANDA = "panda_description/urdf/panda.urdf"
UR5 = "ur_description/urdf/ur5_robot.urdf"


def _site_package_dirs() -> list[Path]:
    """Every site-packages directory of this interpreter, without duplicates, in search order."""
    candidates = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    try:
        candidates += site.getsitepackages()
    except AttributeError:  # some virtualenv versions ship a site.py without it
        pass
    if site.ENABLE_USER_SITE:
        candidates.append(site.getusersitepackages())
    unique: list[Path] = []
    for candidate in candidates:
        path = Path(candidate)
        if path not in unique:
            unique.append(path)
    return unique


def example_robot_data_urdf(relative_path: str | Path) -> Path:
    """Path of a URDF shipped by the ``example-robot-data`` PyPI package.

    Args:
        relative_path: path below the package's ``robots/`` directory, e.g.
            ``"panda_description/urdf/panda.urdf"`` or ``"ur_description/urdf/ur5_robot.urdf"``.

    Returns:
        The absolute path of the existing file.

    Raises:
        FileNotFoundError: the package is not installed, or it has no such file.
    """
    searched = [directory / _EXAMPLE_ROBOT_DATA_ROBOTS for directory in _site_package_dirs()]
    installed = [robots for robots in searched if robots.is_dir()]
    if not installed:
        raise FileNotFoundError(
            "example-robot-data is not installed (no "
            f"{_EXAMPLE_ROBOT_DATA_ROBOTS} under {', '.join(str(d) for d in _site_package_dirs())}); "
            "install it with `pip install example-robot-data`"
        )
    for robots in installed:
        candidate = robots / relative_path
        if candidate.is_file():
            return candidate.resolve()
    raise FileNotFoundError(
        f"example-robot-data has no {relative_path}; looked in {', '.join(str(r) for r in installed)}"
    )
