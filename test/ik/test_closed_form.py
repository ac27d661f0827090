"""Closed-form IK: FK round trips, branch counts, singular targets and detection from geometry.

Poses are checked with forward kinematics written independently of manip_kin
(kin_reference: DH product, product of exponentials, URDF transforms), never copied values.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from kin_reference import dh_fk, homogeneous, poe_fk, rodrigues
from opw_arm import JOINTS, opw_reference_pose, opw_urdf
from robot_data_files import example_robot_data_urdf

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.pose_rows import parse_task
from manip_kin.core.robots import load_robot
from manip_kin.core.urdf import load_urdf, load_urdf_string, model_to_urdf
from manip_kin.ik.all_solutions import all_ik_solutions
from manip_kin.ik.closed_form import closed_form_solutions, closed_form_solver
from manip_kin.ik.iterative import solve_ik

RPP_DH = [  # (d, θ, a, α, joint variable): robots.md, l0 = 0.4, l1 = 0.3, l2 = 0.2, l3 = 0.1
    (0.4, 0.0, 0.0, math.pi / 2, None),
    (0.0, 0.0, 0.3, 0.0, "theta"),
    (0.2, math.pi / 2, 0.0, math.pi / 2, "d"),
    (0.1, math.pi / 2, 0.0, 0.0, "d"),
]
SCARA_SCREWS = [[0, 0, 1, 0, 0, 0], [0, 0, 1, 0, -0.5, 0], [0, 0, 0, 0, 0, 1], [0, 0, 1, 0, -1.0, 0]]
SCARA_HOME = homogeneous(translation=(1.0, 0.0, 0.0))


def irb120_pose(q) -> np.ndarray:
    """robots.md irb120 table: joint origins and axes, URDF style."""
    origins = [[0, 0, 0.145], [0, 0, 0.145], [0, 0, 0.270], [0.134, 0, 0.070], [0.168, 0, 0], [0.072, 0, 0]]
    axes = [[0, 0, 1], [0, 1, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]]
    pose = np.eye(4)
    for origin, axis, value in zip(origins, axes, q):
        pose = pose @ homogeneous(translation=origin) @ homogeneous(rodrigues(axis, value))
    return pose


def opw_model():
    return load_urdf_string(opw_urdf(), tip_link="link6", tool_link="tool0")


# name -> (model factory, independent FK, task, branches of a generic target)
ARMS = {
    "rpp": (lambda: load_robot("rpp"), lambda q: dh_fk(RPP_DH, q), "position", 2),
    "scara": (lambda: load_robot("scara"), lambda q: poe_fk(SCARA_SCREWS, SCARA_HOME, q), "position_yaw", 2),
    "irb120": (lambda: load_robot("irb120"), irb120_pose, "full", 8),
    "opw_urdf": (opw_model, opw_reference_pose, "full", 8),
}


def same_modulo_turns(model, a, b, tolerance=1e-6) -> bool:
    """Revolute joints equal modulo 2π, prismatic ones equal."""
    difference = np.asarray(a, float) - np.asarray(b, float)
    revolute = ~model.is_prismatic
    difference[revolute] = np.remainder(difference[revolute] + math.pi, 2 * math.pi) - math.pi
    return bool(np.max(np.abs(difference)) < tolerance)


def check_pose(reference_fk, q, target, task_rows, tolerance=1e-9):
    """The independent FK of q reproduces the target on the task's components."""
    reached = reference_fk(q)
    assert np.all(np.isfinite(q))
    np.testing.assert_allclose(reached[:3, 3], target[:3, 3], atol=tolerance)
    if 0 in task_rows:  # full orientation
        np.testing.assert_allclose(reached[:3, :3], target[:3, :3], atol=tolerance)
    elif 2 in task_rows:  # yaw only: the x axes agree in the horizontal plane
        heading = math.atan2(reached[1, 0], reached[0, 0]) - math.atan2(target[1, 0], target[0, 0])
        assert abs(math.remainder(heading, 2 * math.pi)) < tolerance


def fractions(size):
    return st.lists(st.floats(0.0, 1.0), min_size=size, max_size=size)


@pytest.mark.parametrize("arm", list(ARMS))
@settings(max_examples=40, derandomize=True, deadline=None)
@given(data=st.data())
def test_fk_of_random_q_is_among_the_solutions(arm, data):
    factory, reference_fk, task_name, _ = ARMS[arm]
    model = factory()
    u = np.array(data.draw(fractions(model.dof)))
    q = model.lower + u * (model.upper - model.lower)
    target = reference_fk(q)
    task = parse_task(task_name)
    # q is also the hint: it fixes the joints a singular target leaves free (a folded SCARA's q1)
    found = closed_form_solutions(model, target, model.frame_index(model.default_frame), task, hint=q)
    assert found is not None and found.solver == f"closed_form:{'opw' if arm in ('irb120', 'opw_urdf') else arm}"
    assert any(same_modulo_turns(model, solution.q, q) for solution in found.solutions), (q, found)
    for solution in found.solutions:
        assert model.within_limits(solution.q, 0.0)
        check_pose(reference_fk, solution.q, target, task.rows)
        assert solution.position_error < 1e-9 and solution.orientation_error < 1e-9
    # Every in-limit wrap is listed: the copies of q itself are exactly the in-limit turns of each joint.
    copies = [s.q for s in found.solutions if same_modulo_turns(model, s.q, q)]
    expected = 1
    for j in np.flatnonzero(~model.is_prismatic):
        turns = np.arange(-3, 4)
        shifted = q[j] + 2 * math.pi * turns
        expected *= int(np.sum((shifted >= model.lower[j] - 1e-9) & (shifted <= model.upper[j] + 1e-9)))
    assert len(copies) == expected


@pytest.mark.parametrize("arm", list(ARMS))
def test_branch_counts_for_generic_targets(arm):
    factory, reference_fk, task_name, branches = ARMS[arm]
    model = factory()
    rng = np.random.default_rng(5)
    task = parse_task(task_name)
    counted = 0
    for _ in range(30):
        q = model.random_configuration(rng, margin=0.05)
        found = closed_form_solutions(model, reference_fk(q), model.frame_index(model.default_frame), task)
        if arm == "opw_urdf" and found.branches < 8:
            continue  # the back shoulder of an arm with a1 > 0 can be out of reach
        assert found.branches == branches
        labels = {s.branch.split(" j")[0].split(" d")[0] for s in found.solutions}
        assert len(labels) <= branches
        counted += 1
    assert counted >= 20


def test_irb120_all_eight_branches_without_limits_are_distinct_and_exact():
    model = load_robot("irb120")
    solver = closed_form_solver(model, model.frame_index("ee"))
    q = np.array([0.3, 0.2, -0.4, 0.7, 0.9, -1.1])
    target = irb120_pose(q)
    raw = solver.solve(target, np.zeros(6))
    labels = [branch for _, branch in raw]
    assert len(raw) == 8 and len(set(labels)) == 8
    assert {label.split()[0] for label in labels} == {"shoulder=front", "shoulder=back"}
    for solution, _ in raw:
        np.testing.assert_allclose(irb120_pose(solution), target, atol=1e-12)
    # the zero configuration is the front shoulder with the elbow up (elbow above the shoulder-wrist line)
    zero = solver.solve(irb120_pose(np.zeros(6)), np.zeros(6))
    assert any(np.allclose(s, 0.0, atol=1e-12) and b.startswith("shoulder=front elbow=up") for s, b in zero)


def test_irb120_wrist_singularity_returns_finite_solutions_with_the_hint():
    model = load_robot("irb120")
    q = np.array([0.4, 0.3, -0.2, 0.9, 0.0, 0.5])  # q5 = 0: axes 4 and 6 aligned
    target = irb120_pose(q)
    hint = np.array([0.0, 0.0, 0.0, 1.2, 0.0, 0.0])
    found = closed_form_solutions(model, target, model.frame_index("ee"), parse_task("full"), hint)
    assert found.solutions
    for solution in found.solutions:
        check_pose(irb120_pose, solution.q, target, (0, 1, 2, 3, 4, 5))
    # only q4 + q6 is fixed: the solver keeps q4 at the hint and finds q6 = 1.4 - 1.2
    matching = [s.q for s in found.solutions if abs(s.q[4]) < 1e-9 and abs(s.q[0] - 0.4) < 1e-9]
    assert any(abs(m[3] - 1.2) < 1e-9 and abs(math.remainder(m[5] - 0.2, 2 * math.pi)) < 1e-9 for m in matching)


def test_irb120_shoulder_singularity_wrist_centre_over_the_base():
    model = load_robot("irb120")
    # Orientation I puts the wrist centre 0.072 m behind the flange: on joint 1's axis.
    target = homogeneous(np.eye(3), [0.072, 0.0, 0.6])
    hint = np.array([0.7, 0, 0, 0, 0, 0])
    found = closed_form_solutions(model, target, model.frame_index("ee"), parse_task("full"), hint)
    assert found.solutions
    for solution in found.solutions:
        check_pose(irb120_pose, solution.q, target, (0, 1, 2, 3, 4, 5))
    assert any(abs(s.q[0] - 0.7) < 1e-12 for s in found.solutions)  # q1 free: kept at the hint


def test_stretched_and_unreachable_targets():
    scara = load_robot("scara")
    # stretched arm: both elbows coincide, one solution
    target = poe_fk(SCARA_SCREWS, SCARA_HOME, [0.3, 0.0, 0.1, 0.2])
    found = closed_form_solutions(scara, target, scara.frame_index("ee"), parse_task("position_yaw"))
    assert len(found.solutions) == 1 and found.branches == 1
    check_pose(lambda q: poe_fk(SCARA_SCREWS, SCARA_HOME, q), found.solutions[0].q, target, (2, 3, 4, 5))
    # beyond the reach: no solution, no NaN
    far = homogeneous(np.eye(3), [1.2, 0.3, 0.1])
    found = closed_form_solutions(scara, far, scara.frame_index("ee"), parse_task("position_yaw"))
    assert found.solutions == [] and found.branches == 0
    irb120 = load_robot("irb120")
    result = all_ik_solutions(irb120, homogeneous(np.eye(3), [2.0, 0.0, 0.3]))
    assert result.solutions == [] and result.reason.startswith("unreachable")


def test_rpp_both_branches_of_d3():
    model = load_robot("rpp")
    solver = closed_form_solver(model, model.frame_index("ee"))
    q = np.array([0.5, 0.1, 0.3])
    raw = solver.solve(dh_fk(RPP_DH, q), np.zeros(3))
    assert sorted(branch for _, branch in raw) == ["d3=larger", "d3=smaller"]
    for solution, _ in raw:
        np.testing.assert_allclose(dh_fk(RPP_DH, solution)[:3, 3], dh_fk(RPP_DH, q)[:3, 3], atol=1e-12)
    d3 = sorted(solution[2] for solution, _ in raw)
    assert d3[0] < 0 <= d3[1]  # the other root reaches through the axis: below d3's lower limit 0
    listed = closed_form_solutions(model, dh_fk(RPP_DH, q), 3, parse_task("position")).solutions
    assert [s.branch for s in listed] == ["d3=larger"]


def test_detection_comes_from_geometry_not_names():
    # the irb120 written to URDF under another name is still detected
    irb120 = load_robot("irb120")
    text = model_to_urdf(irb120).replace('name="irb120"', 'name="some_arm"')
    renamed = load_urdf_string(text, tip_link="ee")
    assert renamed.name != "irb120"
    assert closed_form_solver(renamed, renamed.frame_index("ee")).structure == "opw"
    # the OPW arm with joint 5 moved 2 cm off the wrist centre is not
    moved = opw_urdf().replace(
        f'<origin xyz="{JOINTS[4][1][0]!r} 0.0 0.0"', f'<origin xyz="{JOINTS[4][1][0]!r} 0.0 0.02"'
    )
    assert moved != opw_urdf()
    broken = load_urdf_string(moved, tip_link="link6", tool_link="tool0")
    assert closed_form_solver(broken, broken.frame_index("tool")) is None
    # arms of other structures have none
    for name in ("genova7", "mocom7"):
        model = load_robot(name)
        assert closed_form_solver(model, model.frame_index(model.default_frame)) is None
    ur5 = load_urdf(example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf"))
    assert closed_form_solver(ur5, ur5.frame_index("ee")) is None  # UR: no spherical wrist
    # a frame before the last link has no closed form
    assert closed_form_solver(irb120, 3) is None


def test_kinova_jaco_from_example_robot_data_is_opw_type():
    model = load_urdf(example_robot_data_urdf("kinova_description/robots/kinova.urdf"))
    assert closed_form_solver(model, model.frame_index("ee")).structure == "opw"
    rng = np.random.default_rng(11)
    for _ in range(10):
        q = model.random_configuration(rng)
        target = frame_pose(model, q, "ee")
        found = closed_form_solutions(model, target, model.frame_index("ee"), parse_task("full"), hint=q)
        assert any(same_modulo_turns(model, s.q, q, 1e-6) for s in found.solutions)


def test_solve_ik_uses_the_nearest_closed_form_solution():
    model = load_robot("irb120")
    q = np.array([0.3, 0.2, -0.4, 0.7, 0.9, -1.1])
    target = irb120_pose(q)
    near = q + 0.05
    result = solve_ik(model, target, near)
    assert result.success and result.solver == "closed_form:opw" and result.iterations == 0
    np.testing.assert_allclose(result.q, q, atol=1e-9)
    numeric = solve_ik(model, target, near, closed_form=False)
    assert numeric.success and numeric.solver == "numeric" and numeric.iterations > 0
    genova = load_robot("genova7")
    assert solve_ik(genova, frame_pose(genova, genova.initial_positions), seed=0).solver == "numeric"


def test_solve_ik_refines_a_closed_form_that_misses_tight_tolerances():
    # A tolerance below what double precision gives makes the closed form "miss": the
    # iteration then starts from it (and cannot do better either, so it reports why).
    model = load_robot("irb120")
    target = irb120_pose([0.3, 0.2, -0.4, 0.7, 0.9, -1.1])
    result = solve_ik(model, target, tolerance_position=1e-30, tolerance_orientation=1e-30, restarts=0)
    assert result.solver == "closed_form:opw+numeric"
    assert result.position_error < 1e-12


def test_numeric_all_lists_distinct_verified_solutions_for_a_redundant_arm():
    model = load_robot("genova7")
    target = frame_pose(model, model.initial_positions)
    result = all_ik_solutions(model, target, seed=3, restarts=8, time_budget=30.0)
    assert result.solver == "numeric" and result.attempts == 9
    assert len(result.solutions) >= 2
    for i, solution in enumerate(result.solutions):
        assert model.within_limits(solution.q, 0.0)
        np.testing.assert_allclose(frame_pose(model, solution.q), target, atol=1e-5)
        for other in result.solutions[i + 1 :]:
            assert np.max(np.abs(solution.q - other.q)) > 1e-4


@settings(max_examples=40, derandomize=True, deadline=None)
@given(u=fractions(6))
def test_irb120_wrist_aligned_targets_have_finite_exact_solutions(u):
    model = load_robot("irb120")
    q = model.lower + np.array(u) * (model.upper - model.lower)
    q[4] = 0.0  # axes 4 and 6 aligned: only q4 + q6 is determined
    target = irb120_pose(q)
    found = closed_form_solutions(model, target, model.frame_index("ee"), parse_task("full"), hint=q)
    assert found.solutions
    for solution in found.solutions:
        check_pose(irb120_pose, solution.q, target, (0, 1, 2, 3, 4, 5))
    # with q as the hint, q4 stays at q[3] and q6 takes the rest: q itself is listed
    assert any(same_modulo_turns(model, s.q, q) for s in found.solutions)
