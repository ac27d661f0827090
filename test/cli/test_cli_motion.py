"""``manip_kin ik`` and ``manip_kin simulate`` as a user runs them (interfaces.md).

Answers are checked against forward kinematics computed here, not against other CLI output.
"""

from __future__ import annotations

import json
import math
import subprocess
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from kin_reference import euler_rpy

from manip_kin.cli import main
from manip_kin.control.resolved_rate import pose_error
from manip_kin.core.kinematics import KinematicsData, forward_kinematics
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform, matrix_to_quat

EXECUTABLE = Path(sysconfig.get_path("scripts")) / "manip_kin"
IK_KEYS = {"q", "success", "iterations", "position_error", "orientation_error", "reason"}
SIMULATE_KEYS = {"converged", "time_to_converge", "final_error", "q_final", "steps"}


def run_json(capsys, argv) -> tuple[int, dict, str]:
    code = main(argv)
    captured = capsys.readouterr()
    lines = captured.out.strip().splitlines()
    assert len(lines) == 1, captured.out  # --json: one object, nothing else on stdout
    return code, json.loads(lines[0]), captured.err


def numbers(values) -> list[str]:
    """Full-precision command-line numbers."""
    return [repr(float(v)) for v in values]


def tool_pose(model, q) -> np.ndarray:
    data = KinematicsData(model)
    forward_kinematics(model, data, np.asarray(q, dtype=float))
    return data.tool.copy()


# --- ik -----------------------------------------------------------------------------------


def test_ik_json_reaches_the_pose_with_rpy(capsys):
    model = load_robot("genova7")
    code, answer, _ = run_json(
        capsys,
        ["ik", "--robot", "genova7", "--xyz", "0.2", "-0.7", "0.3", "--rpy", "0", "1.57", "0", "--seed", "3", "--json"],
    )
    assert code == 0
    assert IK_KEYS <= set(answer)
    assert answer["success"] is True and answer["reason"] == "converged"
    assert answer["task"] == "full" and answer["frame"] == "tool"
    target = make_transform(euler_rpy(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])
    orientation, position = pose_error(tool_pose(model, answer["q"]), target)
    assert np.linalg.norm(position) < 1e-6 and np.linalg.norm(orientation) < 1e-6
    assert answer["position_error"] == pytest.approx(np.linalg.norm(position), abs=1e-9)
    assert model.within_limits(answer["q"], 0.0)


def test_ik_with_a_quaternion_and_an_initial_guess(capsys):
    model = load_robot("irb120")
    q_true = np.array([0.3, 0.4, -0.2, 0.5, 0.6, -0.7])
    target = tool_pose(model, q_true)
    quat = matrix_to_quat(target[:3, :3])
    argv = ["ik", "--robot", "irb120", "--xyz", *numbers(target[:3, 3]), "--quat", *numbers(quat)]
    argv += ["--q0", *numbers(q_true + 0.1), "--json"]
    code, answer, _ = run_json(capsys, argv)
    assert code == 0 and answer["success"]
    np.testing.assert_allclose(tool_pose(model, answer["q"]), target, atol=1e-5)
    assert answer["attempts"] == 1  # from a nearby guess no restart is needed


def test_ik_on_an_under_actuated_arm_says_which_task(capsys):
    model = load_robot("scara")
    code, answer, err = run_json(
        capsys,
        [
            "ik",
            "--robot",
            "scara",
            "--xyz",
            "0.7",
            "0.7",
            "0.2",
            "--rpy",
            "0",
            "0",
            repr(math.pi / 4),
            "--q0",
            "0",
            "0",
            "0",
            "0",
            "--json",
        ],
    )
    assert code == 0 and answer["success"]
    assert answer["task"] == "position_yaw"
    assert "position_yaw" in err and "--task" in err
    pose = tool_pose(model, answer["q"])
    np.testing.assert_allclose(pose[:3, 3], [0.7, 0.7, 0.2], atol=1e-6)
    assert math.atan2(pose[1, 0], pose[0, 0]) == pytest.approx(math.pi / 4, abs=1e-6)


def test_ik_task_flag_chooses_the_components(capsys):
    code, answer, err = run_json(
        capsys, ["ik", "--robot", "rpp", "--xyz", "0.5", "-0.1", "0.6", "--task", "position", "--json"]
    )
    assert code == 0 and answer["task"] == "position" and answer["success"]
    assert err == ""  # an explicit task needs no note
    position = tool_pose(load_robot("rpp"), answer["q"])[:3, 3]
    np.testing.assert_allclose(position, [0.5, -0.1, 0.6], atol=1e-6)


def test_ik_failure_exits_1_with_a_reason(capsys):
    code, answer, _ = run_json(
        capsys, ["ik", "--robot", "irb120", "--xyz", "2", "0", "0.5", "--restarts", "2", "--seed", "1", "--json"]
    )
    assert code == 1
    assert answer["success"] is False and answer["reason"].startswith("unreachable")


def test_ik_readable_summary(capsys):
    code = main(["ik", "--robot", "mocom7", "--xyz", "0.3", "0.2", "0.5", "--rpy", "0", "1.0", "0", "--seed", "2"])
    out = capsys.readouterr().out
    assert code == 0
    assert "converged" in out and "q = [" in out and "position error" in out


# --- simulate -----------------------------------------------------------------------------


def test_simulate_genova7_pose_goal_json(capsys):
    model = load_robot("genova7")
    argv = [
        "simulate",
        "--robot",
        "genova7",
        "--xyz",
        "0.2",
        "-0.7",
        "0.3",
        "--rpy",
        "0",
        "1.57",
        "0",
        "--gain-linear",
        "0.8",
    ]
    argv += ["--gain-angular", "0.8", "--dt", "0.001", "--duration", "18", "--tolerance", "1e-6", "--json"]
    code, answer, _ = run_json(capsys, argv)
    assert code == 0
    assert SIMULATE_KEYS <= set(answer)
    assert answer["converged"] is True
    # ln(e0 / tol) / K, the exponential decay of the larger initial error at K = 0.8 (1 % margin:
    # the discrete step is at most K dt / 2 = 0.04 % faster; a stall would cost seconds).
    target = make_transform(euler_rpy(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])
    initial = pose_error(tool_pose(model, model.initial_positions), target)
    law = math.log(max(np.linalg.norm(initial[0]), np.linalg.norm(initial[1])) / 1e-6) / 0.8
    assert abs(answer["time_to_converge"] - law) <= 0.01 * law, (answer["time_to_converge"], law)
    assert answer["final_error"]["position"] < 1e-6 and answer["final_error"]["orientation"] < 1e-6
    assert answer["steps"] == round(answer["time_to_converge"] / 0.001)
    assert answer["joints_held_at_limits"] == ["joint6"]
    orientation, position = pose_error(tool_pose(model, answer["q_final"]), target)
    assert np.linalg.norm(position) < 1e-6 and np.linalg.norm(orientation) < 1e-6


def test_simulate_without_limit_handling_does_not_converge(capsys):
    argv = [
        "simulate",
        "--robot",
        "genova7",
        "--xyz",
        "0.2",
        "-0.7",
        "0.3",
        "--rpy",
        "0",
        "1.57",
        "0",
        "--duration",
        "18",
    ]
    code, answer, _ = run_json(capsys, argv + ["--ignore-position-limits", "--json"])
    assert code == 1
    assert answer["converged"] is False and answer["time_to_converge"] is None
    assert answer["final_error"]["position"] > 1e-3
    assert "joint6" in answer["reason"]


def test_simulate_from_q0_with_quaternion(capsys):
    model = load_robot("mocom7")
    q0 = np.full(7, 1.3)
    goal = tool_pose(model, np.full(7, 1.4))
    argv = ["simulate", "--robot", "mocom7", "--q0", *numbers(q0), "--xyz", *numbers(goal[:3, 3])]
    argv += ["--quat", *numbers(matrix_to_quat(goal[:3, :3])), "--gain-linear", "2", "--gain-angular", "2", "--json"]
    code, answer, _ = run_json(capsys, argv)
    assert code == 0 and answer["converged"]
    # Both errors decay as exp(-2 t): the larger initial one sets the time.
    orientation, position = pose_error(tool_pose(model, q0), goal)
    expected = math.log(max(np.linalg.norm(orientation), np.linalg.norm(position)) / 1e-6) / 2.0
    assert answer["time_to_converge"] == pytest.approx(expected, abs=0.05)


def test_simulate_out_of_reach_readable(capsys):
    code = main(["simulate", "--robot", "irb120", "--xyz", "2", "0", "0.5", "--duration", "3"])
    out = capsys.readouterr().out
    assert code == 1
    assert "did NOT converge" in out and "out of reach" in out


def test_simulate_rpp_defaults_to_position(capsys):
    code, answer, err = run_json(
        capsys, ["simulate", "--robot", "rpp", "--xyz", "0.5", "-0.1", "0.6", "--duration", "30", "--json"]
    )
    assert code == 0 and answer["task"] == "position"
    assert "position" in err
    np.testing.assert_allclose(tool_pose(load_robot("rpp"), answer["q_final"])[:3, 3], [0.5, -0.1, 0.6], atol=1e-6)


# --- bad input: one line on stderr, exit 2 -------------------------------------------------


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["ik", "--robot", "nobot", "--xyz", "0", "0", "0"], "unknown robot"),
        (["ik", "--robot", "rpp", "--xyz", "0.5", "0", "0.6", "--q0", "1", "2"], "3 joints"),
        (["ik", "--robot", "rpp", "--xyz", "0.5", "0", "0.6", "--task", "elbow"], "task"),
        (["ik", "--robot", "genova7", "--xyz", "0.5", "0", "0.6", "--step", "2"], "step"),
        (["ik", "--robot", "genova7", "--xyz", "0.5", "0", "0.6", "--quat", "0", "0", "0", "2"], "quat"),
        (["simulate", "--robot", "genova7", "--xyz", "0.5", "0", "0.6", "--dt", "0"], "--dt"),
        (["simulate", "--robot", "genova7", "--xyz", "0.5", "0", "0.6", "--gain-linear", "-1"], "gain_linear"),
        (
            ["simulate", "--robot", "genova7", "--q0", "0", "0", "0", "0", "0", "0.5", "0", "--xyz", "0.5", "0", "0.6"],
            "outside",
        ),
        (["simulate", "--robot", "genova7", "--xyz", "0.5", "0"], "--xyz"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(capsys, argv, fragment):
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse usage errors
        code = exit_.code
    captured = capsys.readouterr()
    assert code == 2
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0], captured.err


# --- the installed executable ---------------------------------------------------------------


def test_executable_ik_and_simulate_json():
    ik = subprocess.run(
        [
            str(EXECUTABLE),
            "ik",
            "--robot",
            "genova7",
            "--xyz",
            "0.2",
            "-0.7",
            "0.3",
            "--rpy",
            "0",
            "1.57",
            "0",
            "--seed",
            "1",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ik.returncode == 0, ik.stderr
    answer = json.loads(ik.stdout)
    assert answer["success"] and len(answer["q"]) == 7
    # The answer puts the tool on the pose (FK here): IK's tolerances are 1e-6 m and rad.
    genova7 = load_robot("genova7")
    orientation, position = pose_error(
        tool_pose(genova7, answer["q"]), make_transform(euler_rpy(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])
    )
    assert np.linalg.norm(position) < 1e-5 and np.linalg.norm(orientation) < 1e-5
    assert genova7.within_limits(np.array(answer["q"]))
    sim = subprocess.run(
        [str(EXECUTABLE), "simulate", "--robot", "scara", "--xyz", "0.5", "0.5", "0.3", "--duration", "30", "--json"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert sim.returncode == 0, sim.stderr
    answer = json.loads(sim.stdout)
    assert answer["converged"] and answer["task"] == "position_yaw"
    # scara: position (and yaw) reached; the tool really is at the target (FK here).
    np.testing.assert_allclose(tool_pose(load_robot("scara"), answer["q_final"])[:3, 3], [0.5, 0.5, 0.3], atol=1e-5)
    assert "position_yaw" in sim.stderr
    bad = subprocess.run(
        [str(EXECUTABLE), "simulate", "--robot", "genova7", "--xyz", "0", "0", "0", "--dt", "-1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and bad.stdout == "" and len(bad.stderr.strip().splitlines()) == 1
