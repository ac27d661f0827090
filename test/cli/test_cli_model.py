"""`manip_kin robots|fk|jacobian`: JSON schema and values, and every bad-input case."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from manip_kin.cli import main
from manip_kin.core.kinematics import frame_pose, jacobian
from manip_kin.core.robots import load_robot

EXECUTABLE = Path(sys.executable).parent / "manip_kin"


def run_json(capsys, *args):
    assert main(list(args) + ["--json"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1  # one JSON object, nothing else on stdout
    return json.loads(out)


@pytest.mark.parametrize("robot", ["genova7", "mocom7", "irb120", "rpp", "scara"])
def test_fk_json_for_every_robot(capsys, robot):
    model = load_robot(robot)
    q = model.random_configuration(np.random.default_rng(0))
    result = run_json(capsys, "fk", "--robot", robot, "--q", *map(str, q))
    assert set(result) == {"frame", "matrix", "xyz", "quat_xyzw", "rpy"}
    assert result["frame"] == ("tool" if robot == "genova7" else "ee")
    matrix = np.array(result["matrix"])
    np.testing.assert_allclose(matrix, frame_pose(model, q), atol=1e-12)
    np.testing.assert_allclose(result["xyz"], matrix[:3, 3], atol=0)
    x, y, z, w = result["quat_xyzw"]
    # the quaternion encodes the same rotation: R e_z from the quaternion formula
    np.testing.assert_allclose(
        [2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)], matrix[:3, 2], atol=1e-12
    )


def test_fk_joint_frame_index_and_default_configuration(capsys):
    model = load_robot("genova7")
    result = run_json(capsys, "fk", "--robot", "genova7", "--frame", "3")
    assert result["frame"] == "3"
    np.testing.assert_allclose(result["matrix"], frame_pose(model, model.initial_positions, 3), atol=1e-12)


@pytest.mark.parametrize("kind", ["geometric", "space", "body", "analytical"])
def test_jacobian_json_blocks(capsys, kind):
    model = load_robot("irb120")
    q = [0.1, 0.2, -0.3, 0.4, 0.5, 0.6]
    result = run_json(capsys, "jacobian", "--robot", "irb120", "--q", *map(str, q), "--kind", kind)
    assert result["kind"] == kind and result["frame"] == "ee"
    expected = jacobian(model, q, "ee", kind)
    assert np.array(result["angular"]).shape == (3, 6)
    np.testing.assert_allclose(result["angular"], expected.angular, atol=1e-12)
    np.testing.assert_allclose(result["linear"], expected.linear, atol=1e-12)


def test_robots_lists_every_bundled_robot(capsys):
    result = run_json(capsys, "robots")
    assert {"genova7", "mocom7", "irb120", "rpp", "scara"} <= set(result["robots"])
    genova = result["robots"]["genova7"]
    assert genova["dof"] == 7 and genova["tool"] is True
    assert genova["joints"][5] == {
        "name": "joint6",
        "type": "prismatic",
        "lower": 0.0,
        "upper": 0.3,
        "velocity": 0.5,
        "unit": "m",
        "link": "link6",
    }


@pytest.mark.parametrize(
    "args, message",
    [
        (["fk", "--robot", "nope"], "unknown robot 'nope'"),
        (["fk", "--robot", "irb120", "--q", "1", "2"], "--q has 2 values, the robot has 6 joints"),
        (["fk", "--robot", "irb120", "--q", "0", "0", "nan", "0", "0", "0"], "NaN or infinity"),
        (
            ["fk", "--robot", "irb120", "--frame", "tool"],
            "unknown frame 'tool'; valid frames: base, 1, 2, 3, 4, 5, 6, ee",
        ),
        (["fk", "--robot", "irb120", "--q", "a"], "invalid float value: 'a'"),
        (["jacobian", "--robot", "irb120", "--kind", "hybrid"], "invalid choice: 'hybrid'"),
        (["fk"], "the following arguments are required: --robot"),
        (["teleport"], "invalid choice: 'teleport'"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(args, message):
    result = subprocess.run([str(EXECUTABLE), *args], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr
    assert "Traceback" not in result.stderr


def test_malformed_robot_file_names_file_and_field(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text("joints:\n  - {name: j1, origin: {xyz: [0, 0, high]}}\n")
    result = subprocess.run([str(EXECUTABLE), "fk", "--robot", str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert f"{path}: field 'joints[j1].origin.xyz[2]'" in result.stderr


def test_help_explains_units():
    result = subprocess.run([str(EXECUTABLE), "fk", "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0
    assert "--q" in result.stdout and "[rad] or [m]" in result.stdout


def test_json_output_never_holds_nan_or_infinity(capsys):
    from manip_kin.cli.common import print_json
    from manip_kin.errors import OperationError

    for value in (float("nan"), float("inf")):
        with pytest.raises(OperationError, match="NaN or infinity"):
            print_json({"xyz": [0.0, value, 0.0]})
    assert capsys.readouterr().out == ""  # nothing half-printed
