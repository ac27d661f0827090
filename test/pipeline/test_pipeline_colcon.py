"""`colcon build`, then the pipeline from install/manip_kin/lib/manip_kin, as `ros2 run` would run it."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from pipeline_checks import checked_pipeline

from manip_kin.pipeline import pipeline_processes

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def installed(colcon_install):
    """(lib dir of the executables, share dir, environment of setup.bash)."""
    return colcon_install.lib, colcon_install.share, colcon_install.env


def test_installed_pipeline_reaches_goal(installed, tmp_path):
    lib, share, env = installed
    params_file = share / "config" / "genova7_pipeline.yaml"
    assert params_file.is_file()
    processes = pipeline_processes("genova7", params_file=str(params_file))
    with checked_pipeline(processes, executable_dir=lib, env=env, log_dir=tmp_path) as pipeline:
        # The nodes run the installed code, not the source tree.
        for name in ("robot_state", "cartesian_controller"):
            command_line = Path(f"/proc/{pipeline.pid(name)}/cmdline").read_bytes().split(b"\0")
            assert str(lib).encode() in command_line[1], command_line
        result = subprocess.run(
            [
                str(lib / "manip_kin"),
                "goal",
                "--xyz",
                "0.2",
                "-0.7",
                "0.3",
                "--rpy",
                "0",
                "1.57",
                "0",
                "--wait",
                "--timeout",
                "30",
                "--json",
            ],
            env=pipeline.env,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert result.returncode == 0, result.stderr + pipeline.log_tail("cartesian_controller")
        payload = json.loads(result.stdout)
        assert payload["converged"] and payload["final_error"]["position"] <= 1e-4
        # The scenario gains came from the installed example params file.
        assert "gains 0.8/0.8 1/s" in pipeline.log_text("cartesian_controller")
