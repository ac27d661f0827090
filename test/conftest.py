"""Test session setup: DDS on loopback with a random free domain id.

This runs before any test module imports rclpy, so every node started in
pytest, and every subprocess a test starts, inherits the same isolated domain.
"""

import os
import re
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import settings

# manip_kin.pipeline does not import rclpy, so the environment is still set before rclpy loads.
from manip_kin.pipeline import pick_free_domain
from manip_kin.pipeline.domain import use_prompt_acknowledgements

REPO_ROOT = Path(__file__).resolve().parents[1]
TEST_ROOT = Path(__file__).resolve().parent

# Test modules import the shared helpers of test/support/ (node_harness, ...) and, in a few places,
# another wing's test module (test_closed_form's robots) by module name: every test folder is on
# sys.path whichever file runs first. Basenames are unique across folders (test_layout checks it).
for _folder in sorted({TEST_ROOT / "support", *(p.parent for p in TEST_ROOT.rglob("test_*.py"))}, reverse=True):
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(pick_free_domain())
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
os.environ.setdefault("PYTHONUNBUFFERED", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
# The test process is a client (it waits for acknowledgements); the nodes it starts are not.
use_prompt_acknowledgements()

# A run started in the background of a non-interactive shell (`make test &`, a CI script) has
# SIGINT ignored (POSIX), and so would every process a test starts: Ctrl-C of a CLI would do
# nothing (test_stop_signals' goal --wait ran on to convergence). Tests start processes as a
# terminal would, with SIGINT at Python's default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Hypothesis: derandomized (examples are a fixed function of the test), so a failure reproduces
# on any machine; print_blob lets one replay a failing example with @reproduce_failure.
# HYPOTHESIS_PROFILE=explore searches with fresh random examples (and prints the seed it used).
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("explore", deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


#: Folders whose tests run nodes in real time (their loops, DDS delivery, CLI processes) and
#: assert on what those did. On a loaded 2-core machine a test there can lose to the
#: scheduler (a loop held 200 ms, a reader matched late), so each gets one rerun, as ROS 2's
#: CI gives its tests (``colcon test --retest-until-pass``); a broken behaviour fails both
#: runs, and the summary line counts the reruns (``-r R`` lists them).
REAL_TIME_FOLDERS = ("cli", "pipeline", "recording", "ros")


#: Modules that run a pipeline of node processes (at SCHED_FIFO where permitted) and assert
#: on its timing or its path. Two of them at once on 2 cores starve each other's test client
#: (a move's 1000 joint_states arrived as 16 to 35; a ros2_control line left its segment by
#: 6 mm), so ``make test`` runs them one after another on one worker (``--dist loadgroup``);
#: every other module is a group of its own, as ``--dist loadfile`` would have it.
SERIAL_PIPELINES = ("pipeline/", "ros/nodes/test_ros2_control.py")


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the groups
def pytest_collection_modifyitems(items):
    for item in items:
        relative = Path(item.path).relative_to(TEST_ROOT).as_posix()
        if relative.split("/")[0] in REAL_TIME_FOLDERS:
            item.add_marker(pytest.mark.flaky(reruns=1))
        serial = any(relative.startswith(prefix) for prefix in SERIAL_PIPELINES)
        item.add_marker(pytest.mark.xdist_group("serial_pipelines" if serial else relative))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    """Stop the run when ``--dist loadgroup`` did not take. pytest-xdist groups tests by a suffix
    it writes into each node id, which pytest 9.2 no longer lets it write; the groups then fall
    apart silently: a module's tests run on both workers (each starting its own pipeline), two
    pipelines run at once, and a test that relies on its module's earlier tests fails."""
    if node.config.getvalue("dist") != "loadgroup":
        return
    ungrouped = [nodeid for nodeid in ids if "@" not in nodeid.rpartition("]")[2]]
    if ungrouped:
        pytest.exit(
            f"pytest-xdist did not group {len(ungrouped)} tests (first: {ungrouped[0]}) under "
            f"pytest {pytest.__version__}; requirements-dev.txt pins a pytest that keeps the groups",
            returncode=3,
        )


def pytest_terminal_summary(terminalreporter):
    """Why each rerun test failed first: its error lines, so a run (CI's too) shows what a
    rerun hid, not just that one happened."""
    reruns = terminalreporter.stats.get("rerun", [])
    if not reruns:
        return
    terminalreporter.section("why the reruns failed at first")
    for report in reruns:
        lines = report.longreprtext.strip().splitlines()
        errors = [line for line in lines if line.startswith("E ")][:6]
        where = [line for line in lines if re.match(r"^\S+\.py:\d+: ", line)][-1:]
        terminalreporter.write_line(f"{report.nodeid}")
        for line in errors + where:
            terminalreporter.write_line(f"    {line[:300]}")


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
        [
            str(colcon),
            "build",
            "--base-paths",
            str(REPO_ROOT),
            "--build-base",
            "build",
            "--install-base",
            "install",
            "--packages-select",
            "manip_kin",
            "--event-handlers",
            "console_direct-",
        ],
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


# The collision tests' robots (test_collision, test_qp_law): built once per module that uses them.
@pytest.fixture(scope="module")
def panda():
    """The Panda of example-robot-data with its collision meshes and SRDF: ``(model, collision model)``."""
    from collision_robots import panda_files

    from manip_kin.collision.collision_model import load_collision_model
    from manip_kin.core.urdf import load_urdf

    urdf, srdf, share = panda_files()
    model = load_urdf(urdf)
    return model, load_collision_model(model, srdf=srdf, mesh_search_path=share)


@pytest.fixture(scope="module")
def ball_arm():
    """The spheres-and-boxes test arm of collision_robots, pairs sampled: ``(model, collision model)``."""
    from collision_robots import BALL_ARM_URDF

    from manip_kin.collision.collision_model import load_collision_model
    from manip_kin.core.urdf import load_urdf_string

    model = load_urdf_string(BALL_ARM_URDF, tip_link="tip")
    return model, load_collision_model(model, BALL_ARM_URDF, samples=300)
