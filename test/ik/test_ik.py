"""Iterative IK: the robots.md scenarios, a closed-form oracle, and property tests.

Every returned configuration is checked with a forward kinematics that does not share code
with the solver: textbook reference constructions from ``kin_reference`` (robots.md tables
typed in here) or the numpy path of the core (``forward_kinematics`` on a ``KinematicsData``),
never the unrolled chain the solver runs on.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from kin_reference import dh_fk, homogeneous, poe_fk, rodrigues

from manip_kin.control.resolved_rate import CartesianController, pose_error
from manip_kin.core.kinematics import KinematicsData, forward_kinematics, jacobian
from manip_kin.core.pose_rows import parse_task
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform
from manip_kin.errors import InvalidArgumentError, JointCountError, ManipKinError, NonFiniteError
from manip_kin.ik.closed_form import closed_form_solutions
from manip_kin.ik.iterative import IK_METHODS, solve_ik

BUNDLED = ("genova7", "mocom7", "irb120", "rpp", "scara")


def reference_pose(model, q) -> np.ndarray:
    """Tool (or end-effector) pose through the core's numpy path, not the unrolled chain."""
    data = KinematicsData(model)
    forward_kinematics(model, data, np.asarray(q, dtype=float))
    return data.tool.copy()


def task_errors(model, q, target, rows) -> tuple[float, float]:
    orientation, position = pose_error(reference_pose(model, q), target)
    error = np.concatenate([orientation, position])
    return float(np.linalg.norm(error[[r for r in rows if r < 3]])), float(
        np.linalg.norm(error[[r for r in rows if r >= 3]])
    )


def panda():
    """The Franka Panda from example-robot-data (a test dependency)."""
    from robot_data_files import example_robot_data_urdf

    from manip_kin.core.urdf import load_urdf

    return load_urdf(example_robot_data_urdf("panda_description/urdf/panda.urdf"))


# --- robots.md scenarios ------------------------------------------------------------------

SCARA_SCREWS = [
    [0, 0, 1, 0, 0, 0],
    [0, 0, 1, 0, -0.5, 0],
    [0, 0, 0, 0, 0, 1],
    [0, 0, 1, 0, -1.0, 0],
]
SCARA_HOME = homogeneous(translation=(1.0, 0.0, 0.0))


@pytest.mark.parametrize(
    "initial",
    [[0.0, 0.0, 0.0, 0.0], [math.pi / 2, -math.pi / 4, 0.1, math.pi / 6], [math.pi, math.pi / 2, 0.0, -math.pi / 2]],
)
def test_scara_newton_raphson_from_the_three_guesses(initial):
    model = load_robot("scara")
    target = make_transform(rodrigues([0, 0, 1], math.pi / 4), [0.7, 0.7, 0.2])
    result = solve_ik(model, target, initial, method="nr", restarts=0)
    assert result.success, result.reason
    assert result.task == "position_yaw" and result.attempts == 1
    # The product of exponentials typed in from robots.md confirms the pose: a 4-DoF SCARA
    # reaches this target exactly (its orientation is a pure yaw), so all six components match.
    reached = poe_fk(SCARA_SCREWS, SCARA_HOME, result.q)
    np.testing.assert_allclose(reached[:3, 3], [0.7, 0.7, 0.2], atol=1e-6)
    np.testing.assert_allclose(reached[:3, :3], target[:3, :3], atol=1e-6)
    assert model.within_limits(result.q, 0.0)


def test_scara_stretched_start_is_singular():
    """The first guess really is singular: the planar Jacobian loses rank when q2 = 0, in the
    model (its Jacobian, and the controller's flag) as in the product of exponentials."""
    model = load_robot("scara")
    stretched = np.zeros(4)
    # The model is the robots.md arm: its FK agrees with the typed-in screws.
    for q in (stretched, np.array([0.3, -0.7, 0.1, 0.5])):
        np.testing.assert_allclose(reference_pose(model, q), poe_fk(SCARA_SCREWS, SCARA_HOME, q), atol=1e-12)
    oracle = np.array(
        [
            (
                poe_fk(SCARA_SCREWS, SCARA_HOME, np.eye(4)[j] * 1e-6)[:2, 3]
                - poe_fk(SCARA_SCREWS, SCARA_HOME, -np.eye(4)[j] * 1e-6)[:2, 3]
            )
            / 2e-6
            for j in (0, 1)
        ]
    ).T
    planar = jacobian(model, stretched).linear[:2, :2]  # x, y rates of the two arm joints
    np.testing.assert_allclose(planar, oracle, atol=1e-8)
    assert abs(np.linalg.det(planar)) < 1e-12
    # Bent by q2 the determinant is l1 l2 sin q2 = 0.25 sin q2.
    bent = jacobian(model, [0.0, 0.5, 0.0, 0.0]).linear[:2, :2]
    assert np.linalg.det(bent) == pytest.approx(0.25 * math.sin(0.5), rel=1e-9)
    goal = reference_pose(model, [0.2, 0.4, 0.05, 0.0])
    output = CartesianController(model).step(stretched, goal)
    assert output.singular and output.damping > 0.0 and output.manipulability < 1e-9


def irb120_reference_pose(q) -> np.ndarray:
    """robots.md irb120 table: joint origins and axes, URDF style."""
    origins = [[0, 0, 0.145], [0, 0, 0.145], [0, 0, 0.270], [0.134, 0, 0.070], [0.168, 0, 0], [0.072, 0, 0]]
    axes = [[0, 0, 1], [0, 1, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]]
    pose = np.eye(4)
    for origin, axis, value in zip(origins, axes, q):
        pose = pose @ homogeneous(translation=origin) @ homogeneous(rodrigues(axis, value))
    return pose


def test_irb120_scenario_a_converges():
    model = load_robot("irb120")
    target = make_transform(np.eye(3), [0.5649, 0.0, 0.5509])
    result = solve_ik(
        model,
        target,
        np.zeros(6),
        method="dls",
        damping=0.001,
        step=0.5,
        restarts=0,
        max_iterations=200,
        closed_form=False,  # scenario (a) is about the iteration
    )
    assert result.success, result.reason
    reached = irb120_reference_pose(result.q)
    np.testing.assert_allclose(reached[:3, 3], [0.5649, 0.0, 0.5509], atol=1e-6)
    np.testing.assert_allclose(reached[:3, :3], np.eye(3), atol=1e-6)
    assert model.within_limits(result.q, 0.0)
    # Half steps: the error shrinks by about half per iteration, so it takes a couple dozen.
    assert 10 <= result.iterations <= 40


@pytest.mark.parametrize("method", IK_METHODS)
def test_irb120_scenario_a_with_every_method(method):
    model = load_robot("irb120")
    target = make_transform(np.eye(3), [0.5649, 0.0, 0.5509])
    result = solve_ik(model, target, np.zeros(6), method=method, restarts=0, max_iterations=200)
    assert result.success, result.reason
    np.testing.assert_allclose(irb120_reference_pose(result.q)[:3, 3], [0.5649, 0.0, 0.5509], atol=1e-6)


# --- rpp against its closed form ----------------------------------------------------------

RPP_DH = [  # (d, θ, a, α, joint variable) — robots.md, l0 = 0.4, l1 = 0.3, l2 = 0.2, l3 = 0.1
    (0.4, 0.0, 0.0, math.pi / 2, None),
    (0.0, 0.0, 0.3, 0.0, "theta"),
    (0.2, math.pi / 2, 0.0, math.pi / 2, "d"),
    (0.1, math.pi / 2, 0.0, 0.0, "d"),
]


def rpp_closed_form(position) -> np.ndarray:
    """Position IK of the rpp arm, derived from its DH table.

    Frame 3's origin is (0, 0, l3 + d3) in frame 2. Through A2 = Rz(π/2) Tz(l2 + d2) Rx(π/2)
    it is (l3 + d3, 0, l2 + d2) in frame 1; through A1 = Rz(θ1) Tx(l1) it is
    ((l1 + l3 + d3) cos θ1, (l1 + l3 + d3) sin θ1, l2 + d2) in frame 0; and A0 = Tz(l0) Rx(π/2)
    maps (x, y, z) to (x, -z, y + l0). So with r = l1 + l3 + d3:
    x = r cos θ1, y = -(l2 + d2), z = l0 + r sin θ1, hence θ1 = atan2(z - l0, x),
    r = hypot(x, z - l0) (r > 0 because d3 >= 0), d3 = r - l1 - l3 and d2 = -y - l2.
    """
    x, y, z = position
    radius = math.hypot(x, z - 0.4)
    return np.array([math.atan2(z - 0.4, x), -y - 0.2, radius - 0.3 - 0.1])


def test_rpp_closed_form_matches_the_dh_table():
    """The model is the robots.md DH table, and the package's closed form inverts it (as the
    oracle the next test relies on does)."""
    rng = np.random.default_rng(20)
    model = load_robot("rpp")
    frame = model.frame_index(model.default_frame)
    task = parse_task(None, model)
    for _ in range(20):
        q = model.random_configuration(rng)
        table = dh_fk(RPP_DH, q)
        np.testing.assert_allclose(reference_pose(model, q)[:3, 3], table[:3, 3], atol=1e-12)
        np.testing.assert_allclose(rpp_closed_form(table[:3, 3]), q, atol=1e-12)
        found = closed_form_solutions(model, table, frame, task)
        assert found is not None and found.solver == "closed_form:rpp"
        assert any(np.allclose(solution.q, q, atol=1e-9) for solution in found.solutions), found


def test_rpp_agrees_with_the_closed_form():
    rng = np.random.default_rng(21)
    model = load_robot("rpp")
    for _ in range(30):
        position = dh_fk(RPP_DH, model.random_configuration(rng))[:3, 3]
        target = make_transform(rodrigues(rng.normal(size=3), 1.0), position)  # orientation ignored
        result = solve_ik(model, target, model.random_configuration(rng), seed=1)
        assert result.success and result.task == "position", result.reason
        expected = rpp_closed_form(position)
        # θ1 is unique within [-π, π] except for its wrap-around at ±π.
        difference = result.q - expected
        difference[0] = (difference[0] + math.pi) % (2 * math.pi) - math.pi
        np.testing.assert_allclose(difference, 0.0, atol=1e-6)


# --- property tests: targets from FK of random configurations -----------------------------

# Fixed seed, random targets and random initial guesses; iteration bounds are about twice
# what was measured when they were written (a regression check, not a benchmark).
ITERATION_BOUNDS = {"genova7": 20, "mocom7": 17, "irb120": 45, "rpp": 12, "scara": 15, "panda": 42}


def _property_run(model, count: int, seed: int):
    rng = np.random.default_rng(seed)
    iterations, successes = [], 0
    for _ in range(count):
        target = reference_pose(model, model.random_configuration(rng))
        result = solve_ik(model, target, model.random_configuration(rng), seed=seed)
        rows = parse_task(result.task).rows
        orientation, position = task_errors(model, result.q, target, rows)
        ok = result.success and position < 1e-5 and orientation < 1e-4 and model.within_limits(result.q, 0.0)
        successes += ok
        iterations.append(result.iterations)
        assert result.position_error == pytest.approx(position, abs=1e-9)
    return successes / count, float(np.mean(iterations))


@pytest.mark.parametrize("robot", BUNDLED)
def test_ik_solves_targets_from_random_configurations(robot):
    model = load_robot(robot)
    success_rate, mean_iterations = _property_run(model, 60, seed=30)
    assert success_rate == 1.0
    assert mean_iterations <= ITERATION_BOUNDS[robot]


def test_ik_solves_panda_targets_from_random_configurations():
    model = panda()
    success_rate, mean_iterations = _property_run(model, 60, seed=31)
    assert success_rate == 1.0
    assert mean_iterations <= ITERATION_BOUNDS["panda"]


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.integers(min_value=0, max_value=2**32 - 1))
def test_genova7_any_reachable_target_is_solved_within_limits(seed):
    model = load_robot("genova7")
    rng = np.random.default_rng(seed)
    target = reference_pose(model, model.random_configuration(rng))
    result = solve_ik(model, target, model.random_configuration(rng), seed=seed)
    assert result.success, result.reason
    orientation, position = task_errors(model, result.q, target, range(6))
    assert position < 1e-6 and orientation < 1e-6
    assert model.within_limits(result.q, 0.0)


def test_the_solver_lets_the_prismatic_joint_rest_on_its_limit():
    """A target whose only nearby solutions have the prismatic joint at 0 is still solved."""
    model = load_robot("genova7")
    rng = np.random.default_rng(40)
    solved = 0
    for _ in range(10):
        q = model.random_configuration(rng)
        q[5] = 0.0
        target = reference_pose(model, q)
        start = q + rng.normal(scale=0.3, size=7)
        start[5] = 0.3
        result = solve_ik(model, target, start, restarts=0, max_iterations=100)
        solved += result.success
    assert solved >= 9


# --- task selection -----------------------------------------------------------------------


def test_mask_and_named_task_are_the_same():
    model = load_robot("scara")
    target = make_transform(rodrigues([0, 0, 1], 0.3), [0.4, 0.5, 0.3])
    by_mask = solve_ik(model, target, np.zeros(4), mask=(0, 0, 1, 1, 1, 1), seed=2)
    by_name = solve_ik(model, target, np.zeros(4), task="position_yaw", seed=2)
    assert by_mask.task == by_name.task == "position_yaw"
    np.testing.assert_array_equal(by_mask.q, by_name.q)


def test_position_only_task_on_a_redundant_arm_ignores_orientation():
    model = load_robot("genova7")
    rng = np.random.default_rng(41)
    position = reference_pose(model, model.random_configuration(rng))[:3, 3]
    target = make_transform(rodrigues([1, 1, 0], 2.0), position)
    result = solve_ik(model, target, model.initial_positions, task="position", seed=3)
    assert result.success and result.task == "position"
    np.testing.assert_allclose(reference_pose(model, result.q)[:3, 3], position, atol=1e-6)
    assert result.orientation_error == 0.0


def test_full_pose_on_a_four_joint_scara_fails_and_says_why():
    model = load_robot("scara")
    tilted = make_transform(rodrigues([1, 0, 0], 0.5), [0.5, 0.5, 0.2])
    result = solve_ik(model, tilted, np.zeros(4), task="full", restarts=3, seed=4)
    assert not result.success
    assert result.reason.split(":")[0] in ("stalled", "limits", "iterations")
    assert result.orientation_error == pytest.approx(0.5, abs=1e-3)  # the tilt it cannot produce


# --- failures and their reasons -----------------------------------------------------------


def test_target_beyond_reach_is_reported_unreachable():
    model = load_robot("irb120")
    result = solve_ik(model, make_transform(np.eye(3), [2.0, 0.0, 0.5]), np.zeros(6), restarts=5, seed=5)
    assert not result.success
    assert result.reason.startswith("unreachable:")
    assert result.attempts == 6
    assert model.within_limits(result.q, 0.0)
    assert np.all(np.isfinite(result.q))


def test_target_only_reachable_past_a_limit_is_reported_as_limits():
    model = load_robot("rpp")
    # hypot(x, z - l0) = 0.35 < l1 + l3: it needs d3 = -0.05 below its lower limit 0.
    target = make_transform(np.eye(3), [0.35, -0.1, 0.4])
    result = solve_ik(model, target, np.zeros(3), restarts=5, seed=6)
    assert not result.success
    assert result.reason.startswith("limits:") and "d3" in result.reason
    assert result.position_error == pytest.approx(0.05, abs=1e-6)
    assert result.q[2] == 0.0


def test_time_budget_stops_the_restarts(monkeypatch):
    import manip_kin.ik.iterative as ik_module

    model = load_robot("rpp")
    target = make_transform(np.eye(3), [0.35, -0.1, 0.4])
    # Generate (and cache) the model's IK code first: the budget is about solving, and code
    # generation on a loaded machine can take longer than the whole budget.
    solve_ik(model, target, np.zeros(3), restarts=0)
    # The budget logic on a clock the test controls: every reading advances 5 ms, so the
    # 20 ms budget is spent after a known number of readings, however fast the machine is.
    readings = []

    def clock():
        readings.append(len(readings) * 0.005)
        return readings[-1]

    monkeypatch.setattr(ik_module.time, "perf_counter", clock)
    result = solve_ik(model, target, np.zeros(3), restarts=10**6, time_budget=0.02, seed=7)
    monkeypatch.undo()
    assert not result.success and result.reason.startswith("budget: the time budget of 0.02 s ran out")
    # One reading at the start, one after each attempt; the one that reaches 20 ms ends it.
    assert result.attempts == 4, (result.attempts, readings)
    assert result.elapsed == pytest.approx(readings[-1] - readings[0])
    # And on the real clock: it stops (not 10^6 restarts), some restarts in. 0.5 s bound: the
    # budget plus one attempt (~1 ms here) with room for a descheduled process on a loaded machine.
    result = solve_ik(model, target, np.zeros(3), restarts=10**6, time_budget=0.02, seed=7)
    assert not result.success and result.reason.startswith("budget:")
    assert 1 < result.attempts < 10**6
    assert result.elapsed < 0.5


def test_restarts_are_reproducible_with_a_seed():
    model = load_robot("irb120")
    rng = np.random.default_rng(42)
    target = reference_pose(model, model.random_configuration(rng))
    start = model.random_configuration(rng)
    options = {"restarts": 50, "max_iterations": 5, "closed_form": False}  # the restarts are numeric
    first = solve_ik(model, target, start, seed=9, **options)
    second = solve_ik(model, target, start, seed=9, **options)
    third = solve_ik(model, target, start, rng=np.random.default_rng(9), **options)
    assert first.attempts > 1  # the short iteration cap forces restarts
    np.testing.assert_array_equal(first.q, second.q)
    np.testing.assert_array_equal(first.q, third.q)
    assert first.iterations == second.iterations


def test_bad_arguments_raise_clear_errors():
    model = load_robot("genova7")
    target = reference_pose(model, model.initial_positions)
    with pytest.raises(InvalidArgumentError, match="method"):
        solve_ik(model, target, method="bfgs")
    with pytest.raises(InvalidArgumentError, match="step"):
        solve_ik(model, target, step=0.0)
    with pytest.raises(InvalidArgumentError, match="either task or mask"):
        solve_ik(model, target, task="position", mask=(0, 0, 0, 1, 1, 1))
    with pytest.raises(JointCountError):
        solve_ik(model, target, np.zeros(6))
    with pytest.raises(NonFiniteError):
        solve_ik(model, np.full((4, 4), np.nan))
    skewed = target.copy()
    skewed[:3, :3] *= 2.0
    with pytest.raises(ManipKinError, match="rotation"):
        solve_ik(model, skewed)
    with pytest.raises(InvalidArgumentError, match="4x4"):
        solve_ik(model, np.eye(3))
    with pytest.raises(InvalidArgumentError, match="tolerance_position"):
        solve_ik(model, target, tolerance_position=0.0)


# --- the generated iteration is the plain one, faster ---------------------------------------


@pytest.mark.parametrize("robot", ["genova7", "irb120", "scara", "panda"])
def test_generated_iteration_matches_the_plain_python_one(robot):
    from manip_kin.ik import iteration as ik_iteration
    from manip_kin.ik import problem as ik_problem

    model = panda() if robot == "panda" else load_robot(robot)
    rng = np.random.default_rng(50)
    task = parse_task(None, model)
    problem = ik_problem.problem_for(model, model.frame_index(model.default_frame), task)
    assert problem.iterate is not None
    held_seen = 0
    for _ in range(40):
        q = model.random_configuration(rng)
        # Put a few clipped joints exactly on a limit so that holding them is exercised.
        for j in problem.clipped:
            if rng.random() < 0.4:
                q[j] = problem.lower[j] if rng.random() < 0.5 else problem.upper[j]
        # Targets from configurations up to 30% beyond the limits: some pull joints outside.
        span = model.upper - model.lower
        target = reference_pose(model, rng.uniform(model.lower - 0.3 * span, model.upper + 0.3 * span)).tolist()
        for method, weight, shift, damping in (
            ("lm", ik_iteration.LM_ERROR_WEIGHT, 1e-9, 1e-9),
            ("dls", 0.0, 1e-4, 1e-2),
        ):
            status, fused_q, orientation, position = problem.iterate(q.tolist(), target, weight, shift, 0.7, 1e-6, 1e-6)
            assert status == 0
            plain = ik_iteration.general_iteration(problem, target, q.tolist(), method, 0.7, damping, (1e-6, 1e-6))
            np.testing.assert_allclose(fused_q, plain[1], rtol=1e-9, atol=1e-11)
            assert (orientation, position) == pytest.approx(plain[2:], rel=1e-12)
            assert model.within_limits(fused_q, 0.0)
        values = problem.chain(q.tolist())
        error, _, _ = problem.errors(values, target)
        held_seen += bool(problem.held_joints(values, q.tolist(), error))
    assert held_seen >= 3  # the held-joint branch was exercised
