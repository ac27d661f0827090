"""The package builds with colcon and its executables land where `ros2 run` looks."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXECUTABLES = ["manip_kin", "robot_state", "cartesian_controller", "trajectory_generator", "recorder"]


@pytest.fixture(scope="session")
def colcon_install(tmp_path_factory):
    """``colcon build`` of this package into a temp workspace; returns the install dir."""
    colcon = Path(sys.executable).parent / "colcon"
    if not colcon.exists():
        colcon = shutil.which("colcon")
    if colcon is None:
        pytest.skip("colcon is not installed")
    workspace = tmp_path_factory.mktemp("colcon_ws")
    (workspace / "src").mkdir()
    # A workspace holds the package source; symlink it rather than copying the venv along.
    (workspace / "src" / "manip_kin").symlink_to(REPO)
    env = dict(os.environ, COLCON_HOME=str(workspace / ".colcon"))
    result = subprocess.run(
        [str(colcon), "build", "--base-paths", "src", "--packages-select", "manip_kin", "--event-handlers", "console_direct-"],
        cwd=workspace,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return workspace / "install"


def install_env(install: Path) -> dict[str, str]:
    """The environment ``install/setup.bash`` would give (PYTHONPATH, AMENT_PREFIX_PATH)."""
    prefix = install / "manip_kin"
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join([str(prefix), env.get("AMENT_PREFIX_PATH", sys.prefix)])
    return env


def test_executables_land_in_lib_and_answer_help(colcon_install):
    lib = colcon_install / "manip_kin" / "lib" / "manip_kin"
    env = install_env(colcon_install)
    for name in EXECUTABLES:
        executable = lib / name
        assert executable.is_file(), f"{executable} missing; lib has {sorted(p.name for p in lib.iterdir())}"
        result = subprocess.run([str(executable), "--help"], env=env, capture_output=True, text=True, timeout=60)
        assert result.returncode == 0, result.stderr
        assert "usage" in result.stdout.lower() or "parameters" in result.stdout.lower()


def test_installed_share_has_package_xml_and_bundled_robots(colcon_install):
    share = colcon_install / "manip_kin" / "share" / "manip_kin"
    assert (share / "package.xml").is_file()
    assert (share / "config" / "robots" / "genova7.yaml").is_file()
    assert (colcon_install / "manip_kin" / "share" / "ament_index" / "resource_index" / "packages" / "manip_kin").is_file()


def test_installed_cli_finds_robots_through_the_ament_index(colcon_install):
    lib = colcon_install / "manip_kin" / "lib" / "manip_kin"
    env = install_env(colcon_install)
    code = "from manip_kin.robots import config_dir; import manip_kin; print(config_dir()); print(manip_kin.__file__)"
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60, cwd="/")
    assert result.returncode == 0, result.stderr
    config, module = result.stdout.split()
    assert str(colcon_install) in config and str(colcon_install) in module
    fk = subprocess.run([str(lib / "manip_kin"), "fk", "--robot", "genova7", "--json"], env=env, capture_output=True, text=True, timeout=60)
    assert fk.returncode == 0 and '"frame": "tool"' in fk.stdout
