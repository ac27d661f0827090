"""Test session setup: DDS on loopback with a random free domain id.

This runs before any test module imports rclpy, so every node started in
pytest, and every subprocess a test starts, inherits the same isolated domain.
"""

import os
import random
import shutil
import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def _domain_is_free(domain_id: int) -> bool:
    # Fast DDS binds the first participant's unicast discovery port to
    # 7410 + 250 * domain; if that is taken another participant uses the domain.
    port = 7410 + 250 * domain_id
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _pick_free_domain() -> int:
    candidates = list(range(1, 101))
    random.SystemRandom().shuffle(candidates)
    for domain_id in candidates:
        if _domain_is_free(domain_id):
            return domain_id
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..100")


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(_pick_free_domain())
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
os.environ.setdefault("PYTHONUNBUFFERED", "1")
os.environ.setdefault("MPLBACKEND", "Agg")


@dataclass(frozen=True)
class ColconInstall:
    """A colcon build of this package.

    Attributes:
        prefix: ``install/manip_kin``.
        lib: where ``ros2 run`` finds the executables (``install/manip_kin/lib/manip_kin``).
        share: ``install/manip_kin/share/manip_kin``.
        env: the environment ``install/setup.bash`` would give (PYTHONPATH, AMENT_PREFIX_PATH).
    """

    prefix: Path
    lib: Path
    share: Path
    env: dict


@pytest.fixture(scope="session")
def colcon_install(tmp_path_factory) -> ColconInstall:
    """``colcon build`` of this repository into a temporary workspace, once per test session."""
    colcon = Path(sys.executable).parent / "colcon"
    if not colcon.exists():
        colcon = shutil.which("colcon")
    if colcon is None:
        pytest.skip("colcon is not installed")
    workspace = tmp_path_factory.mktemp("colcon_ws")
    result = subprocess.run(
        [str(colcon), "build", "--base-paths", str(REPO_ROOT), "--build-base", "build", "--install-base", "install",
         "--packages-select", "manip_kin", "--event-handlers", "console_direct-"],
        cwd=workspace,
        env=dict(os.environ, COLCON_HOME=str(workspace / ".colcon")),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    prefix = workspace / "install" / "manip_kin"
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join([str(prefix), env.get("AMENT_PREFIX_PATH", sys.prefix)])
    return ColconInstall(prefix, prefix / "lib" / "manip_kin", prefix / "share" / "manip_kin", env)
