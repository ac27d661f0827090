"""`manip_kin ik --all`, `fk --in` and `sweep`: JSON shapes, values against independent FK, bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from kin_reference import dh_fk, euler_rpy, fixed_then_z_fk, homogeneous, poe_fk, rodrigues
from opw_arm import JOINTS, opw_reference_pose, opw_urdf
from test_closed_form import RPP_DH, SCARA_HOME, SCARA_SCREWS, irb120_pose

from manip_kin.cli import main

SOLUTION_KEYS = {"q", "branch", "position_error", "orientation_error"}

# robots.md genova7 table: R_i rows and p_i; joint 6 prismatic.
GENOVA7 = [
    ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0, 0, 0.105]),
    ([[0, 1, 0], [0, 0, 1], [1, 0, 0]], [0, 0, 0.110]),
    ([[0, 0, 1], [0, -1, 0], [1, 0, 0]], [0.100, 0, 0]),
    ([[0, 0, 1], [0, -1, 0], [1, 0, 0]], [0, 0, 0.325]),
    ([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], [0.095, 0, 0]),
    ([[-1, 0, 0], [0, -1, 0], [0, 0, 1]], [0, 0, 0.095]),
    ([[0, -1, 0], [0, 0, -1], [1, 0, 0]], [0, 0, 0.355]),
]
GENOVA7_TYPES = ["revolute"] * 5 + ["prismatic", "revolute"]


def genova7_frames(q):
    return fixed_then_z_fk([homogeneous(np.array(r, float), p) for r, p in GENOVA7], GENOVA7_TYPES, q)


def run(capsys, *args):
    code = main(list(args))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def run_json(capsys, *args, expect=0):
    code, out, err = run(capsys, *args, "--json")
    assert code == expect, err
    assert out.count("\n") == 1  # one JSON object, nothing else on stdout
    return json.loads(out)


def rpy_matrix(roll, pitch, yaw):
    return rodrigues([0, 0, 1], yaw) @ rodrigues([0, 1, 0], pitch) @ rodrigues([1, 0, 0], roll)


def test_ik_all_irb120_lists_every_in_limit_solution(capsys):
    q = [0.3, 0.2, -0.4, 0.7, 0.9, -1.1]
    target = irb120_pose(q)
    rpy = [
        math.atan2(target[2, 1], target[2, 2]),
        -math.asin(target[2, 0]),
        math.atan2(target[1, 0], target[0, 0]),
    ]
    xyz = target[:3, 3]
    args = ["ik", "--robot", "irb120", "--xyz", *map(str, xyz), "--rpy", *map(str, rpy), "--all"]
    result = run_json(capsys, *args, "--wraps")
    assert result["solver"] == "closed_form:opw"
    assert result["count"] == len(result["solutions"]) >= 2
    goal = homogeneous(rpy_matrix(*rpy), xyz)
    limits = np.radians([165, 110, 110, 160, 120, 400])
    every_q = [s["q"] for s in result["solutions"]] + [w for s in result["solutions"] for w in s["wrap_q"]]
    assert len(every_q) == result["count"] + result["wrap_count"]
    for solution in result["solutions"]:
        assert set(solution) == SOLUTION_KEYS | {"wraps", "wrap_q"} and solution["wraps"] == len(solution["wrap_q"])
        assert solution["position_error"] < 1e-9 and solution["orientation_error"] < 1e-9
    for values in every_q:
        np.testing.assert_allclose(irb120_pose(values), goal, atol=1e-9)
        assert np.all(np.abs(values) <= limits + 1e-12) and values[2] <= math.radians(70) + 1e-12
    # q itself (joint 6 at -1.1 rad) is the solution, its in-limit turn (+2π; -2π is beyond -400°) its wrap
    (same,) = [s for s in result["solutions"] if np.allclose(s["q"][:5], q[:5], atol=1e-9)]
    np.testing.assert_allclose(same["q"][5], -1.1, atol=1e-9)
    np.testing.assert_allclose([w[5] for w in same["wrap_q"]], [-1.1 + 2 * math.pi], atol=1e-9)
    # Without --wraps: the same solutions, the wraps only counted.
    plain = run_json(capsys, *args)
    assert [s["q"] for s in plain["solutions"]] == [s["q"] for s in result["solutions"]]
    assert all("wrap_q" not in s for s in plain["solutions"]) and plain["wrap_count"] == result["wrap_count"]


def test_ik_all_rpp_and_scara_closed_forms(capsys):
    q_rpp = [0.5, 0.1, 0.3]
    xyz = dh_fk(RPP_DH, q_rpp)[:3, 3]
    result = run_json(capsys, "ik", "--robot", "rpp", "--xyz", *map(str, xyz), "--all")
    assert result["solver"] == "closed_form:rpp" and result["task"] == "position"
    assert [s["branch"] for s in result["solutions"]] == ["d3=larger"]
    np.testing.assert_allclose(result["solutions"][0]["q"], q_rpp, atol=1e-12)

    target = poe_fk(SCARA_SCREWS, SCARA_HOME, [0.4, 1.1, 0.2, -0.3])
    yaw = math.atan2(target[1, 0], target[0, 0])
    args = ["ik", "--robot", "scara", "--xyz", *map(str, target[:3, 3]), "--rpy", "0", "0", str(yaw), "--all"]
    result = run_json(capsys, *args)
    assert result["solver"] == "closed_form:scara"
    assert sorted(s["branch"] for s in result["solutions"]) == ["elbow=left", "elbow=right"]
    for solution in result["solutions"]:
        np.testing.assert_allclose(poe_fk(SCARA_SCREWS, SCARA_HOME, solution["q"]), target, atol=1e-9)


def test_ik_all_opw_urdf_file(capsys, tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(opw_urdf())
    q = [0.2, -0.4, 0.3, 1.0, -0.7, 2.0]
    target = opw_reference_pose(q)
    quat = _quaternion(target[:3, :3])
    args = ["ik", "--robot", str(path), "--xyz", *map(str, target[:3, 3]), "--quat", *map(str, quat), "--all"]
    result = run_json(capsys, *args)
    assert result["solver"] == "closed_form:opw" and result["frame"] == "ee"
    # the URDF's tip is tool0 here (the chain ends there): 8 branches, each with 1 turn of joint 6 (±2π limits)
    assert len(result["solutions"]) == 8 and [s["wraps"] for s in result["solutions"]] == [1] * 8
    for solution in result["solutions"]:
        np.testing.assert_allclose(opw_reference_pose(solution["q"]), target, atol=1e-9)


def _quaternion(rotation):
    w = math.sqrt(max(0.0, 1 + np.trace(rotation))) / 2
    if w > 1e-3:
        return [
            (rotation[2, 1] - rotation[1, 2]) / (4 * w),
            (rotation[0, 2] - rotation[2, 0]) / (4 * w),
            (rotation[1, 0] - rotation[0, 1]) / (4 * w),
            w,
        ]
    raise AssertionError("pick a q whose rotation is not a half turn")


def test_ik_all_numeric_for_genova7(capsys):
    args = ["ik", "--robot", "genova7", "--xyz", "0.2", "-0.7", "0.3", "--rpy", "0", "1.57", "0", "--all"]
    result = run_json(capsys, *args, "--seed", "2", "--restarts", "4", "--time-budget", "30")
    assert result["solver"] == "numeric" and result["count"] >= 1
    goal = homogeneous(rpy_matrix(0, 1.57, 0), [0.2, -0.7, 0.3])
    tool = homogeneous(rpy_matrix(math.pi / 6, 0, math.pi / 10), [0.3, 0.1, 0])
    for solution in result["solutions"]:
        assert set(solution) == SOLUTION_KEYS | {"wraps"}
        np.testing.assert_allclose(genova7_frames(solution["q"])[-1] @ tool, goal, atol=1e-5)


def test_ik_bad_input_and_unreachable(capsys):
    code, out, err = run(capsys, "ik", "--robot", "genova7", "--xyz", "0.2", "-0.7", "0.3", "--solver", "closed_form")
    assert code == 2 and out == "" and err.count("\n") == 1 and "no closed form" in err
    code, out, err = run(capsys, "ik", "--robot", "irb120", "--xyz", "0.3", "0", "0.5", "--q0", "0", "0", "--all")
    assert code == 2 and err.count("\n") == 1 and "--q0 has 2 values" in err
    result = run_json(capsys, "ik", "--robot", "irb120", "--xyz", "2", "0", "0.3", "--all", expect=1)
    assert result["solutions"] == [] and result["reason"].startswith("unreachable")
    with pytest.raises(SystemExit) as exit_info:
        main(["ik", "--robot", "irb120", "--xyz", "0.3", "0", "0.5", "--all", "--solver", "magic"])
    assert exit_info.value.code == 2


def test_ik_single_solution_uses_the_closed_form_and_reports_it(capsys):
    result = run_json(capsys, "ik", "--robot", "irb120", "--xyz", "0.5649", "0", "0.5509", "--rpy", "0", "0", "0")
    assert result["solver"] == "closed_form:opw" and result["success"] and result["iterations"] == 0
    np.testing.assert_allclose(irb120_pose(result["q"])[:3, 3], [0.5649, 0, 0.5509], atol=1e-9)
    args = ["ik", "--robot", "irb120", "--xyz", "0.5649", "0", "0.5509", "--solver", "numeric"]
    result = run_json(
        capsys, *args, "--method", "dls", "--damping", "0.001", "--step", "0.5", "--max-iterations", "200"
    )
    assert result["solver"] == "numeric" and result["success"] and result["iterations"] > 5


def test_fk_in_another_frame_matches_composed_fk(capsys):
    q = [0.4, -0.3, 0.2, 0.9, -0.5, 0.12, 0.3]
    frames = genova7_frames(q)
    result = run_json(capsys, "fk", "--robot", "genova7", "--q", *map(str, q), "--frame", "6", "--in", "2")
    assert set(result) == {"frame", "matrix", "xyz", "quat_xyzw", "rpy"} and result["frame"] == "6"
    expected = np.linalg.inv(frames[1]) @ frames[5]
    np.testing.assert_allclose(result["matrix"], expected, atol=1e-12)
    np.testing.assert_allclose(result["xyz"], expected[:3, 3], atol=1e-12)
    # the base in frame 7 is the inverse of frame 7 in base
    result = run_json(capsys, "fk", "--robot", "genova7", "--q", *map(str, q), "--frame", "base", "--in", "7")
    np.testing.assert_allclose(result["matrix"], np.linalg.inv(frames[6]), atol=1e-12)


def test_fk_in_link_names_of_a_urdf(capsys, tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(opw_urdf())
    q = [0.2, -0.4, 0.3, 1.0, -0.7, 2.0]
    # frame i of a URDF model is its joint i's child link, so tool0 in link2 is T2^-1 T_tool
    result = run_json(capsys, "fk", "--robot", str(path), "--q", *map(str, q), "--frame", "ee", "--in", "link2")
    link2 = np.eye(4)
    for (_, xyz, rpy, axis, _, _), value in list(zip(JOINTS, q))[:2]:
        link2 = link2 @ homogeneous(euler_rpy(*rpy), xyz) @ homogeneous(rodrigues(axis, value))
    np.testing.assert_allclose(result["matrix"], np.linalg.inv(link2) @ opw_reference_pose(q), atol=1e-12)
    code, _, err = run(capsys, "fk", "--robot", "genova7", "--frame", "6", "--in", "elbow")
    assert code == 2 and err.count("\n") == 1 and "valid frames" in err


def test_sweep_json_and_figure(capsys, tmp_path):
    start, goal = [1.3] * 7, [2.0] * 7
    args = ["sweep", "--robot", "genova7", "--q-start", *map(str, start[:5]), "0.1", "1.3"]
    args += ["--q-goal", *map(str, goal[:5]), "0.25", "2.0", "--steps", "20", "--out", str(tmp_path)]
    result = run_json(capsys, *args)
    q = np.array(result["q"])
    positions = np.array(result["positions"])
    assert q.shape == (21, 7) and positions.shape == (21, 7, 3)
    assert q[0, 5] == pytest.approx(0.1) and q[-1, 5] == pytest.approx(0.25)
    np.testing.assert_allclose(np.diff(q, axis=0), np.tile((q[-1] - q[0]) / 20, (20, 1)), atol=1e-12)
    for k in (0, 7, 20):
        expected = [frame[:3, 3] for frame in genova7_frames(q[k])]
        np.testing.assert_allclose(positions[k], expected, atol=1e-12)
    png = tmp_path / "sweep_genova7.png"
    assert result["png"] == str(png) and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--steps", "0"], "steps"),
        (["--steps", "3", "--q-goal", "0", "0", "0", "9", "0", "0", "0"], "outside the joint limits"),
        (["--steps", "3", "--q-goal", "0", "0"], "has 2 values"),
    ],
)
def test_sweep_bad_input(capsys, tmp_path, extra, message):
    args = ["sweep", "--robot", "mocom7", "--q-start", *["0"] * 7, "--out", str(tmp_path)]
    if "--q-goal" not in extra:
        args += ["--q-goal", *["1"] * 7]
    code, out, err = run(capsys, *args, *extra)
    assert code == 2 and out == "" and err.count("\n") == 1 and message in err


def test_wraps_fold_into_one_solution_and_distinct_solutions_stay(capsys):
    from manip_kin.core.robots import load_robot
    from manip_kin.ik.all_solutions import group_wraps
    from manip_kin.ik.closed_form import Solution

    model = load_robot("genova7")  # joint 6 prismatic: never wrapped
    q = np.array([0.1, -0.2, 0.3, -0.4, 0.5, 0.15, 0.7])
    turned = q + np.array([2 * math.pi, 0, 0, -2 * math.pi, 0, 0, 4 * math.pi])
    other = q.copy()
    other[5] += 2 * math.pi * 1e-3  # a prismatic joint differing is another solution
    near_pi = q.copy()
    near_pi[0] = math.pi - 1e-9
    across = near_pi.copy()
    across[0] = -math.pi + 1e-9  # the same angle, written across the ±π seam
    solutions = [Solution(turned, "b+", 0.0, 0.0), Solution(q, "b", 0.0, 0.0), Solution(other, "c", 0.0, 0.0)]
    solutions += [Solution(near_pi, "d", 0.0, 0.0), Solution(across, "d'", 0.0, 0.0)]
    groups = group_wraps(model, solutions)
    assert [g.solution.branch for g in groups] == ["b", "c", "d"]  # the fewest turns represents a group
    assert [[w.branch for w in g.wraps] for g in groups] == [["b+"], [], ["d'"]]
