"""The package builds with colcon and its executables land where `ros2 run` looks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXECUTABLES = ["manip_kin", "robot_state", "cartesian_controller", "trajectory_generator", "recorder"]


def test_executables_land_in_lib_and_answer_help(colcon_install):
    lib, env = colcon_install.lib, colcon_install.env
    for name in EXECUTABLES:
        executable = lib / name
        assert executable.is_file(), f"{executable} missing; lib has {sorted(p.name for p in lib.iterdir())}"
        result = subprocess.run([str(executable), "--help"], env=env, capture_output=True, text=True, timeout=60)
        assert result.returncode == 0, result.stderr
        assert "usage" in result.stdout.lower() or "parameters" in result.stdout.lower()


def test_installed_share_has_package_xml_and_bundled_robots(colcon_install):
    share = colcon_install.share
    assert (share / "package.xml").is_file()
    assert (share / "config" / "robots" / "genova7.yaml").is_file()
    assert (colcon_install.prefix / "share" / "ament_index" / "resource_index" / "packages" / "manip_kin").is_file()


def test_installed_cli_finds_robots_through_the_ament_index(colcon_install):
    lib, env = colcon_install.lib, colcon_install.env
    code = (
        "from manip_kin.core.robots import config_dir; import manip_kin; print(config_dir()); print(manip_kin.__file__)"
    )
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60, cwd="/")
    assert result.returncode == 0, result.stderr
    config, module = result.stdout.split()
    assert str(colcon_install.prefix) in config and str(colcon_install.prefix) in module
    fk = subprocess.run(
        [str(lib / "manip_kin"), "fk", "--robot", "genova7", "--json"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert fk.returncode == 0 and '"frame": "tool"' in fk.stdout


def test_the_installed_package_builds_its_native_narrow_phase(colcon_install):
    # The C++ source is package data: the installed package compiles it where it runs.
    code = "from manip_kin.collision.narrow_phase import native_problem; print(repr(native_problem()))"
    result = subprocess.run(
        [sys.executable, "-c", code], env=colcon_install.env, capture_output=True, text=True, timeout=300, cwd="/"
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "''"
