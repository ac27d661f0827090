"""Robot YAML loading, bundled robot lookup and the errors a user sees."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.loaders import load_robot_yaml, model_from_dict
from manip_kin.core.robots import config_dir, load_robot, resolve_robot_path
from manip_kin.errors import ModelFileError, UnknownRobotError


def test_bundled_robots_have_the_documented_joints_and_limits():
    genova = load_robot("genova7")
    assert genova.joint_names == [f"joint{i}" for i in range(1, 8)]
    assert genova.is_prismatic.tolist() == [False] * 5 + [True, False]
    assert (genova.lower[5], genova.upper[5], genova.velocity_limits[5]) == (0.0, 0.3, 0.5)
    np.testing.assert_allclose(
        genova.initial_positions, [math.pi / 2, -math.pi / 4, 0, -math.pi / 4, 0, 0.15, math.pi / 4]
    )
    irb = load_robot("irb120")
    np.testing.assert_allclose(np.degrees(irb.upper), [165, 110, 70, 160, 120, 400])
    np.testing.assert_allclose(np.degrees(irb.velocity_limits), [250, 250, 250, 320, 320, 420])
    assert load_robot("rpp").dof == 3 and load_robot("scara").dof == 4
    assert load_robot("genova7") is genova  # models are built once


def test_robot_found_by_path_and_units_scale(tmp_path):
    metres = tmp_path / "m.yaml"
    metres.write_text(
        "name: arm\njoints:\n  - {name: a, origin: {xyz: [0, 0, 0.5]}}\n  - {name: b, type: prismatic, origin: {xyz: [0.2, 0, 0]}, limits: {lower: 0, upper: 0.3, velocity: 0.1}}\n"
    )
    millimetres = tmp_path / "mm.yaml"
    millimetres.write_text(
        "name: arm\nunits: mm\njoints:\n  - {name: a, origin: {xyz: [0, 0, 500]}}\n  - {name: b, type: prismatic, origin: {xyz: [200, 0, 0]}, limits: {lower: 0, upper: 300, velocity: 100}}\n"
    )
    a, b = load_robot(str(metres)), load_robot(str(millimetres))
    assert resolve_robot_path(str(metres)) == metres.resolve()
    np.testing.assert_allclose(b.upper, a.upper)
    np.testing.assert_allclose(b.velocity_limits, a.velocity_limits)
    for q in ([0.3, 0.1], [-1.0, 0.25]):
        np.testing.assert_allclose(frame_pose(b, q), frame_pose(a, q), atol=1e-12)


def test_config_dir_is_found_from_the_checkout():
    assert (config_dir() / "robots" / "genova7.yaml").is_file()


def test_unknown_robot_lists_the_bundled_ones():
    with pytest.raises(UnknownRobotError) as error:
        load_robot("ur5e")
    assert "genova7" in str(error.value) and "ur5e" in str(error.value)


@pytest.mark.parametrize(
    "text, field, problem",
    [
        ("name: x\njoints: [\n", "line", "malformed YAML"),
        ("name: x\n", "<top level>", "exactly one describes the chain"),
        ("joints:\n  - {name: a, type: spherical}\n", "joints[a].type", "valid: revolute, prismatic"),
        ("joints:\n  - {name: a, origin: {xyz: [0, 0]}}\n", "joints[a].origin.xyz", "list of 3 numbers"),
        ("joints:\n  - {name: a, origin: {xyz: [0, 0, one]}}\n", "joints[a].origin.xyz[2]", "not a number"),
        (
            "joints:\n  - {name: a, origin: {rotation: [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}}\n",
            "joints[a].origin.rotation",
            "not a rotation",
        ),
        ("joints:\n  - {name: a, limits: {lower: 1, upper: 0}}\n", "joints[a].limits", "lower 1.0 > upper 0.0"),
        ("joints:\n  - {name: a, limits: {velocity: 0}}\n", "joints[a].limits.velocity", "positive"),
        ("units: km\njoints:\n  - {name: a}\n", "units", "valid: m, mm"),
        ("dh:\n  - {d: 0, theta: 0, a: 1}\n", "dh[0].alpha", "missing"),
        ("poe:\n  screws: [{screw: [0, 0, 2, 0, 0, 0]}]\n  home: {}\n", "poe.screws[joint1].screw", "valid: 1"),
        ("joints:\n  - {name: a}\ninitial_positions: [0, 1]\n", "initial_positions", "list of 1 numbers"),
        ("joints:\n  - {name: a}\ntol: {xyz: [0, 0, 1]}\n", "tol", "unknown key"),
    ],
)
def test_malformed_robot_yaml_names_the_file_and_the_field(tmp_path, text, field, problem):
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    with pytest.raises(ModelFileError) as error:
        load_robot_yaml(path)
    message = str(error.value)
    assert str(path) in message and field in message and problem in message, message


def test_scalar_expressions_in_yaml():
    model = model_from_dict(
        {"joints": [{"name": "a", "limits": {"lower": "-3*pi/4", "upper": "90 deg", "velocity": "pi"}}]}, "inline"
    )
    assert model.lower[0] == pytest.approx(-3 * math.pi / 4)
    assert model.upper[0] == pytest.approx(math.pi / 2)
    assert model.velocity_limits[0] == pytest.approx(math.pi)
