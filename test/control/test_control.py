"""The resolved-rate control law: error, damped solve, limits, singularities.

Expected values come from independent computations: rotation errors are checked by
exponentiating them back (textbook Rodrigues), joint rates against numpy's pseudo-inverse of
a Jacobian obtained by numeric differentiation of the forward kinematics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from kin_reference import rodrigues

from manip_kin.control.resolved_rate import CartesianController, ControllerConfig, pose_error
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.errors import InvalidArgumentError, JointCountError, ManipKinError, NonFiniteError, UnknownFrameError

ROBOTS = ("genova7", "mocom7", "irb120", "rpp", "scara")


def numeric_jacobian(model, q, frame=None, step=1e-6) -> np.ndarray:
    """Geometric Jacobian [angular; linear] by central differences of the FK, shape (6, n)."""
    q = np.asarray(q, dtype=float)
    columns = []
    for j in range(model.dof):
        dq = np.zeros_like(q)
        dq[j] = step
        plus, minus = frame_pose(model, q + dq, frame), frame_pose(model, q - dq, frame)
        # ω× = Ṙ Rᵀ; read ω from the skew part.
        r_dot = (plus[:3, :3] - minus[:3, :3]) / (2 * step)
        omega_skew = r_dot @ frame_pose(model, q, frame)[:3, :3].T
        omega = 0.5 * np.array(
            [
                omega_skew[2, 1] - omega_skew[1, 2],
                omega_skew[0, 2] - omega_skew[2, 0],
                omega_skew[1, 0] - omega_skew[0, 1],
            ]
        )
        columns.append(np.concatenate([omega, (plus[:3, 3] - minus[:3, 3]) / (2 * step)]))
    return np.array(columns).T


def random_rotation(rng) -> np.ndarray:
    axis = rng.normal(size=3)
    return rodrigues(axis, rng.uniform(0, math.pi))


def genova7_scenario_goal() -> np.ndarray:
    return make_transform(rpy_to_matrix(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])


# --- pose error ---------------------------------------------------------------------------


def test_pose_error_rotates_current_onto_goal():
    rng = np.random.default_rng(1)
    for _ in range(50):
        current = make_transform(random_rotation(rng), rng.normal(size=3))
        goal = make_transform(random_rotation(rng), rng.normal(size=3))
        orientation, position = pose_error(current, goal)
        angle = np.linalg.norm(orientation)
        assert angle <= math.pi + 1e-12
        # exp([e]×) applied in base takes the current orientation onto the goal.
        np.testing.assert_allclose(rodrigues(orientation, angle) @ current[:3, :3], goal[:3, :3], atol=1e-12)
        np.testing.assert_allclose(position, goal[:3, 3] - current[:3, 3], atol=1e-15)


def test_pose_error_is_angle_axis_of_current_R_goal_expressed_in_base():
    rng = np.random.default_rng(2)
    current = make_transform(random_rotation(rng))
    goal = make_transform(random_rotation(rng))
    orientation, _ = pose_error(current, goal)
    relative = current[:3, :3].T @ goal[:3, :3]  # current_R_goal
    # Textbook log for an angle well inside (0, π).
    angle = math.acos((np.trace(relative) - 1) / 2)
    axis_in_current = np.array(
        [relative[2, 1] - relative[1, 2], relative[0, 2] - relative[2, 0], relative[1, 0] - relative[0, 1]]
    ) / (2 * math.sin(angle))
    np.testing.assert_allclose(orientation, current[:3, :3] @ axis_in_current * angle, atol=1e-10)


def test_pose_error_near_pi_and_zero():
    current = make_transform(rodrigues([1, 2, 3], 0.3))
    for angle in (math.pi - 1e-9, math.pi, 1e-12, 0.0):
        goal = make_transform(rodrigues([0.2, -1, 0.5], angle) @ current[:3, :3])
        orientation, _ = pose_error(current, goal)
        assert np.linalg.norm(orientation) == pytest.approx(angle, abs=1e-12)
        np.testing.assert_allclose(
            rodrigues(orientation if angle > 0 else [0, 0, 1], np.linalg.norm(orientation)) @ current[:3, :3],
            goal[:3, :3],
            atol=1e-9,
        )


def test_controller_error_matches_pose_error():
    model = load_robot("genova7")
    q = model.initial_positions
    goal = genova7_scenario_goal()
    controller = CartesianController(model)
    orientation, position = controller.error(q, goal)
    expected = pose_error(frame_pose(model, q), goal)
    np.testing.assert_allclose(orientation, expected[0], atol=1e-13)
    np.testing.assert_allclose(position, expected[1], atol=1e-15)
    output = controller.step(q, goal, dt=0.001)
    np.testing.assert_allclose(output.orientation_error, expected[0], atol=1e-13)
    assert output.orientation_error_norm == pytest.approx(np.linalg.norm(expected[0]), abs=1e-13)
    assert output.position_error_norm == pytest.approx(np.linalg.norm(expected[1]), abs=1e-15)


# --- joint rates --------------------------------------------------------------------------


def _goal_near(model, q, rng, frame=None):
    current = frame_pose(model, q, frame)
    return make_transform(
        rodrigues(rng.normal(size=3), 0.3) @ current[:3, :3], current[:3, 3] + rng.normal(scale=0.05, size=3)
    )


@pytest.mark.parametrize("robot", ["genova7", "mocom7", "irb120"])
def test_rates_are_the_pseudo_inverse_of_the_reference_twist(robot):
    model = load_robot(robot)
    rng = np.random.default_rng(3)
    config = ControllerConfig(
        gain_angular=0.7, gain_linear=1.3, respect_velocity_limits=False, respect_position_limits=False
    )
    controller = CartesianController(model, config)
    checked = 0
    while checked < 10:
        q = model.random_configuration(rng, margin=0.1)
        jacobian = numeric_jacobian(model, q)
        if np.linalg.svd(jacobian, compute_uv=False)[-1] < 0.05:
            continue  # near a singularity damping applies; covered below
        goal = _goal_near(model, q, rng)
        feed_forward = (rng.normal(size=3) * 0.1, rng.normal(size=3) * 0.05)
        output = controller.step(q, goal, feed_forward, dt=0.002)
        orientation, position = pose_error(frame_pose(model, q), goal)
        reference = np.concatenate([0.7 * orientation + feed_forward[0], 1.3 * position + feed_forward[1]])
        np.testing.assert_allclose(output.qdot, np.linalg.pinv(jacobian) @ reference, atol=1e-7)
        assert output.damping == 0.0 and not output.singular and output.velocity_scale == 1.0
        assert output.manipulability == pytest.approx(math.sqrt(np.linalg.det(jacobian @ jacobian.T)), rel=1e-6)
        checked += 1


def reference_step(model, config, q, goal, twist, dt):
    """The control law written plainly in numpy (the numpy FK and Jacobian, eigvalsh, an SNS
    loop), independent of the generated step: ``(qdot, λ, singular, held, scale, manipulability)``."""
    from manip_kin.core.kinematics import frame_poses, jacobian

    rows = list(CartesianController(model, config).task.rows)
    frame = model.default_frame
    current = frame_poses(model, q)[model.frame_index(frame)]
    orientation, position = pose_error(current, goal)
    reference = np.concatenate([config.gain_angular * orientation, config.gain_linear * position])
    reference += np.concatenate(twist)
    full = jacobian(model, q, frame).matrix
    rhs = reference[rows]

    def solve(columns_held):
        j = full[rows].copy()
        j[:, columns_held] = 0.0
        eigenvalues = np.linalg.eigvalsh(j @ j.T)
        sigma_sq = max(eigenvalues[0], 0.0)
        eps_sq = config.singular_threshold**2
        lam_sq = config.damping_max**2 * (1 - sigma_sq / eps_sq) if sigma_sq < eps_sq else 0.0
        manip = math.sqrt(np.prod(np.maximum(eigenvalues, 0.0)))
        return j, lam_sq, sigma_sq < eps_sq, manip

    j, lam_sq, singular, manipulability = solve([])
    qdot = j.T @ np.linalg.solve(j @ j.T + lam_sq * np.eye(len(rows)), rhs)
    held = {}
    for _ in range(model.dof):
        worst, worst_excess, worst_bound = -1, 0.0, 0.0
        for k in range(model.dof):
            if k in held:
                continue
            # At most the velocity limit: the scaling below brings every rate there.
            reach = min(abs(qdot[k]), model.velocity_limits[k]) * dt
            if qdot[k] < 0 and q[k] - reach < model.lower[k]:
                bound = min((model.lower[k] - q[k]) / dt, 0.0)
            elif qdot[k] > 0 and q[k] + reach > model.upper[k]:
                bound = max((model.upper[k] - q[k]) / dt, 0.0)
            else:
                continue
            excess = abs(qdot[k] - bound) / model.velocity_limits[k]
            if excess > worst_excess or worst < 0:
                worst, worst_excess, worst_bound = k, excess, bound
        if worst < 0:
            break
        held[worst] = worst_bound
        qdot[worst] = worst_bound
        if len(held) == model.dof:
            break
        j, lam_sq, singular, _ = solve(list(held))
        residual = rhs - full[rows][:, list(held)] @ np.array(list(held.values()))
        free = j.T @ np.linalg.solve(j @ j.T + lam_sq * np.eye(len(rows)), residual)
        for k in range(model.dof):
            if k not in held:
                qdot[k] = free[k]
    worst = np.max(np.abs(qdot) / model.velocity_limits)
    scale = 1.0 / worst if worst > 1.0 else 1.0
    return qdot * scale, math.sqrt(lam_sq), singular, tuple(sorted(held)), scale, manipulability


def test_a_goal_metres_away_holds_only_joints_that_can_reach_a_limit():
    """The law's rates for a goal 3 m out of reach are far above the velocity limits before
    the scaling; the position limits judge the rate a joint can have. Over a long horizon (the
    node's: a stop from full speed, 0.5 s here) only a joint within its velocity limit's travel
    of a limit is held, not joints 1.6 and 3.1 rad away (held before, and the arm then crawled:
    a held joint's landing rate set the scale)."""
    model = load_robot("genova7")
    q = model.start_configuration()
    goal = frame_pose(model, q)
    goal[:3, 3] = [3.0, 0.0, 0.3]
    horizon = 0.5
    output = CartesianController(model, ControllerConfig()).step(q, goal, (np.zeros(3), np.zeros(3)), horizon)
    clearance = np.minimum(q - model.lower, model.upper - q)
    reachable = set(np.flatnonzero(clearance < model.velocity_limits * horizon).tolist())
    assert reachable == {5}  # the prismatic joint, 0.15 m from its limits at 0.5 m/s
    assert set(output.limited_joints) <= reachable
    assert np.max(np.abs(output.qdot) / model.velocity_limits) == pytest.approx(1.0)  # scaled, not crawling


def test_generated_step_matches_a_plain_numpy_law():
    """The generated step (the one implementation of the law) against the law written plainly:
    regular, damped near singularities, with position limits (a long period) and scaling."""
    rng = np.random.default_rng(4)
    config = ControllerConfig()
    for robot in ROBOTS:
        model = load_robot(robot)
        controller = CartesianController(model, config)
        for _ in range(20):
            q = model.random_configuration(rng, margin=0.05)
            goal = _goal_near(model, q, rng)
            twist = (rng.normal(size=3), rng.normal(size=3))
            for dt in (0.002, 0.5):  # a long period makes limits matter
                a = controller.step(q, goal, twist, dt)
                qdot, damping, singular, held, scale, manipulability = reference_step(model, config, q, goal, twist, dt)
                np.testing.assert_allclose(a.qdot, qdot, rtol=1e-7, atol=1e-10)
                np.testing.assert_allclose(a.orientation_error, pose_error(frame_pose(model, q), goal)[0], atol=1e-13)
                assert a.manipulability == pytest.approx(manipulability, rel=1e-7)
                assert (a.singular, a.limited_joints) == (singular, held)
                assert a.damping == pytest.approx(damping, rel=1e-7, abs=1e-12)
                assert a.velocity_scale == pytest.approx(scale, rel=1e-9)


@pytest.mark.parametrize("robot", ROBOTS)
def test_rates_produce_the_reference_twist_on_the_task(robot):
    """J q̇ = K e on the task components (checked by moving along q̇ a tiny bit)."""
    model = load_robot(robot)
    rng = np.random.default_rng(5)
    controller = CartesianController(model, ControllerConfig(respect_velocity_limits=False))
    rows = list(controller.task.rows)
    checked = skipped = 0
    while checked < 5:
        q = model.random_configuration(rng, margin=0.2)
        if np.linalg.svd(numeric_jacobian(model, q)[rows], compute_uv=False)[-1] < 0.05:
            skipped += 1  # near a singularity damping applies (tested below)
            assert skipped < 50, f"{robot}: 50 near-singular samples in a row (seed 5)"
            continue
        goal = _goal_near(model, q, rng)
        output = controller.step(q, goal, dt=1e-3)
        achieved = numeric_jacobian(model, q) @ output.qdot
        reference = np.concatenate([0.8 * output.orientation_error, 0.8 * output.position_error])
        np.testing.assert_allclose(achieved[rows], reference[rows], atol=1e-7, err_msg=f"seed 5, q {q.tolist()}")
        checked += 1


def test_default_tasks_for_under_actuated_arms():
    assert CartesianController(load_robot("scara")).task.name == "position_yaw"
    assert CartesianController(load_robot("rpp")).task.name == "position"
    assert CartesianController(load_robot("genova7")).task.name == "full"
    assert CartesianController(load_robot("genova7"), ControllerConfig(task="position")).task.rows == (3, 4, 5)
    assert (
        CartesianController(load_robot("genova7"), ControllerConfig(task=(0, 0, 1, 1, 1, 1))).task.name
        == "position_yaw"
    )


def test_controlled_frame_can_be_chosen():
    model = load_robot("genova7")
    rng = np.random.default_rng(6)
    q = model.initial_positions
    goal = _goal_near(model, q, rng, frame="ee")
    output = CartesianController(model, ControllerConfig(frame="ee", respect_velocity_limits=False)).step(q, goal)
    expected = pose_error(frame_pose(model, q, "ee"), goal)
    np.testing.assert_allclose(output.position_error, expected[1], atol=1e-15)
    achieved = numeric_jacobian(model, q, "ee") @ output.qdot
    np.testing.assert_allclose(achieved, 0.8 * np.concatenate(expected), atol=1e-7)
    with pytest.raises(UnknownFrameError):
        CartesianController(model, ControllerConfig(frame="camera"))


# --- velocity limits ----------------------------------------------------------------------


def test_velocity_limits_scale_the_whole_vector():
    model = load_robot("genova7")
    q = model.initial_positions
    goal = genova7_scenario_goal()
    config = ControllerConfig(gain_angular=20.0, gain_linear=20.0)
    limited = CartesianController(model, config).step(q, goal, dt=0.001)
    free = CartesianController(
        model, ControllerConfig(gain_angular=20.0, gain_linear=20.0, respect_velocity_limits=False)
    ).step(q, goal, dt=0.001)
    ratios = np.abs(free.qdot) / model.velocity_limits
    assert ratios.max() > 1.0  # the unscaled command would exceed a limit
    assert limited.velocity_scale == pytest.approx(1.0 / ratios.max(), rel=1e-12)
    np.testing.assert_allclose(limited.qdot, free.qdot / ratios.max(), rtol=1e-12)
    assert np.max(np.abs(limited.qdot) / model.velocity_limits) == pytest.approx(1.0, abs=1e-12)


# --- position limits ----------------------------------------------------------------------


def test_joint_at_a_limit_is_not_pushed_and_the_task_is_redistributed():
    model = load_robot("genova7")
    rng = np.random.default_rng(7)
    controller = CartesianController(model, ControllerConfig(respect_velocity_limits=False))
    ignoring = CartesianController(
        model, ControllerConfig(respect_velocity_limits=False, respect_position_limits=False)
    )
    found = 0
    for _ in range(400):
        q = model.random_configuration(rng, margin=0.1)
        q[5] = 0.0  # the prismatic joint at its lower limit
        goal = _goal_near(model, q, rng)
        if ignoring.step(q, goal, dt=0.001).qdot[5] >= 0.0:
            continue  # the unconstrained solution would not push it further
        jacobian = numeric_jacobian(model, q)
        others = np.delete(jacobian, 5, axis=1)
        if np.linalg.svd(others, compute_uv=False)[-1] < 0.05:
            continue
        output = controller.step(q, goal, dt=0.001)
        assert output.limited_joints == (5,)
        assert output.qdot[5] == 0.0
        # The six other joints still produce the whole reference twist.
        reference = 0.8 * np.concatenate([output.orientation_error, output.position_error])
        np.testing.assert_allclose(jacobian @ output.qdot, reference, atol=1e-7)
        np.testing.assert_allclose(output.qdot[np.arange(7) != 5], np.linalg.pinv(others) @ reference, atol=1e-7)
        found += 1
        if found == 5:
            break
    assert found == 5


def test_joint_approaching_a_limit_lands_exactly_on_it():
    model = load_robot("genova7")
    rng = np.random.default_rng(8)
    controller = CartesianController(model, ControllerConfig(respect_velocity_limits=False))
    ignoring = CartesianController(
        model, ControllerConfig(respect_velocity_limits=False, respect_position_limits=False)
    )
    dt = 0.001
    for _ in range(200):
        q = model.random_configuration(rng, margin=0.1)
        q[5] = 1e-5  # 10 µm above the lower limit
        goal = _goal_near(model, q, rng)
        if q[5] + ignoring.step(q, goal, dt=dt).qdot[5] * dt >= 0.0:
            continue  # this step would not reach the limit
        output = controller.step(q, goal, dt=dt)
        assert output.limited_joints == (5,)
        assert q[5] + output.qdot[5] * dt == pytest.approx(0.0, abs=1e-15)
        return
    pytest.fail("no configuration moving the prismatic joint down")


def test_joint_outside_its_limits_may_move_back_only():
    model = load_robot("genova7")
    controller = CartesianController(model, ControllerConfig(respect_velocity_limits=False))
    ignoring = CartesianController(
        model, ControllerConfig(respect_velocity_limits=False, respect_position_limits=False)
    )
    q = np.array(model.initial_positions)
    q[5] = -0.01  # below the lower limit 0
    jacobian = numeric_jacobian(model, q)
    back = held = 0
    for goal_offset in ([0, 0, 0.05], [0, 0, -0.05], [0, 0.05, 0], [0, -0.05, 0]):
        current = frame_pose(model, q)
        goal = make_transform(current[:3, :3], current[:3, 3] + goal_offset)
        output = controller.step(q, goal, dt=0.001)
        free = ignoring.step(q, goal, dt=0.001).qdot
        assert np.all(np.isfinite(output.qdot))
        if free[5] > 1e-6:  # the task pulls it back inside: allowed, unchanged
            np.testing.assert_allclose(output.qdot, free, atol=1e-12)
            assert output.limited_joints == ()
            back += 1
        else:  # it would go further out: held, and the other joints still do the whole task
            assert free[5] < -1e-6
            assert output.qdot[5] == 0.0 and output.limited_joints == (5,)
            reference = 0.8 * np.concatenate([output.orientation_error, output.position_error])
            np.testing.assert_allclose(jacobian @ output.qdot, reference, atol=1e-7)
            assert np.linalg.norm(output.qdot) > 0.01  # not an all-zero command
            held += 1
    assert back == 2 and held == 2


@pytest.mark.parametrize(
    "joint, side",
    [(5, "upper"), (0, "lower"), (2, "upper"), (6, "lower")],
    ids=["prismatic-upper", "base-lower", "shoulder-upper", "wrist-lower"],
)
def test_joint_at_either_limit_with_an_outward_rate_is_held(joint, side):
    """At a lower or upper limit, prismatic or revolute: an outward rate is refused, the task
    redistributed over the other joints; an inward rate is left alone."""
    model = load_robot("genova7")
    limit = model.upper[joint] if side == "upper" else model.lower[joint]
    outward = 1.0 if side == "upper" else -1.0
    controller = CartesianController(model, ControllerConfig(respect_velocity_limits=False))
    ignoring = CartesianController(
        model, ControllerConfig(respect_velocity_limits=False, respect_position_limits=False)
    )
    rng = np.random.default_rng(100 + joint)
    held = inward = 0
    for _ in range(2000):
        q = model.random_configuration(rng, margin=0.1)
        q[joint] = limit
        goal = _goal_near(model, q, rng)
        free = ignoring.step(q, goal, dt=0.001).qdot
        output = controller.step(q, goal, dt=0.001)
        if free[joint] * outward < -1e-6 and inward < 3:  # moving back inside: untouched
            np.testing.assert_allclose(output.qdot, free, atol=1e-12)
            inward += 1
            continue
        if free[joint] * outward <= 1e-6 or held == 3:
            continue
        jacobian = numeric_jacobian(model, q)
        others = np.delete(jacobian, joint, axis=1)
        if np.linalg.svd(others, compute_uv=False)[-1] < 0.05:
            continue  # damping would bend the task (at ±π joints 2, 4 and 5 fold the arm: not used)
        assert output.limited_joints == (joint,), (output.limited_joints, q.tolist())
        assert output.qdot[joint] == 0.0
        reference = 0.8 * np.concatenate([output.orientation_error, output.position_error])
        np.testing.assert_allclose(jacobian @ output.qdot, reference, atol=1e-7)
        assert q[joint] + output.qdot[joint] * 0.001 == limit  # stays exactly on the limit
        held += 1
        if held == 3 and inward == 3:
            break
    assert held == 3 and inward == 3, (held, inward)


SPINNER_URDF = """<robot name="spinner">
  <link name="base_link"/><link name="link1"/><link name="link2"/><link name="tool0"/>
  <joint name="spin" type="continuous">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit effort="1" velocity="2.0"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="1" velocity="2.0"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="link2"/><child link="tool0"/><origin xyz="0.2 0 0"/>
  </joint>
</robot>"""


def test_continuous_joint_is_driven_through_plus_minus_pi(tmp_path):
    """A continuous base joint: no limit at ±π, the law is 2π-periodic in it, and a goal on the
    other side of π is reached by passing through π (not by unwinding the long way round)."""
    from manip_kin.control.simulation import simulate

    path = tmp_path / "spinner.urdf"
    path.write_text(SPINNER_URDF)
    model = load_robot(str(path))
    assert np.isinf(model.lower[0]) and np.isinf(model.upper[0])
    config = ControllerConfig(task="x,y", gain_linear=2.0)
    controller = CartesianController(model, config)
    start = np.array([math.pi - 0.05, 0.6])
    goal = frame_pose(model, np.array([math.pi + 0.3, 0.6]))
    for q in (start, np.array([math.pi + 0.01, 0.6]), np.array([-math.pi - 0.2, 0.6])):
        output = controller.step(q, goal, dt=0.001)
        wrapped = controller.step(q - 2 * math.pi * np.sign(q[0]) * np.array([1, 0]), goal, dt=0.001)
        np.testing.assert_allclose(output.qdot, wrapped.qdot, atol=1e-9)
        assert output.limited_joints == ()
    result = simulate(model, start, goal, config, dt=0.001, duration=10.0, record_every=1)
    assert result.converged, result.reason
    assert result.q[:, 0].max() > math.pi  # it went through π ...
    assert np.all(np.diff(result.q[: len(result.time), 0]) >= -1e-12)  # ... monotonically, not the long way
    assert result.q_final[0] == pytest.approx(math.pi + 0.3, abs=1e-5)
    assert not result.limited[:, 0].any()


# --- singularities ------------------------------------------------------------------------


def test_stretched_scara_rates_stay_bounded():
    model = load_robot("scara")
    goal = make_transform(rodrigues([0, 0, 1], math.pi / 4), [0.7, 0.7, 0.2])
    controller = CartesianController(model)
    output = controller.step(np.zeros(4), goal, dt=0.001)
    assert output.singular and output.damping > 0.0
    assert np.all(np.isfinite(output.qdot))
    assert np.all(np.abs(output.qdot) <= model.velocity_limits * (1 + 1e-12))
    assert np.abs(output.qdot).max() > 0.1  # it moves: the singularity does not stop the arm
    assert output.manipulability == pytest.approx(0.0, abs=1e-9)


def test_irb120_wrist_singularity_rates_stay_bounded():
    model = load_robot("irb120")
    q = np.array([0.3, 0.2, -0.4, 0.5, 0.0, -0.2])  # q5 = 0: axes 4 and 6 aligned
    assert np.linalg.svd(numeric_jacobian(model, q), compute_uv=False)[-1] < 1e-6
    controller = CartesianController(model)
    current = frame_pose(model, q)
    for rotation_axis in ([0, 0, 1], [0, 1, 0], [1, 0, 0]):
        goal = make_transform(rodrigues(rotation_axis, 0.5) @ current[:3, :3], current[:3, 3] + [0.02, -0.03, 0.01])
        output = controller.step(q, goal, dt=0.001)
        assert output.singular and output.damping == pytest.approx(controller.config.damping_max, rel=1e-6)
        assert np.all(np.isfinite(output.qdot))
        assert np.all(np.abs(output.qdot) <= model.velocity_limits * (1 + 1e-12))


def test_damping_rises_smoothly_below_the_threshold():
    """Approaching the stretched scara, λ goes continuously from 0 to λ_max as σ_min -> 0."""
    model = load_robot("scara")
    config = ControllerConfig(respect_velocity_limits=False)
    controller = CartesianController(model, config)
    goal = make_transform(np.eye(3), [0.5, 0.5, 0.2])
    rows = list(controller.task.rows)
    previous_sigma, previous_damping = None, None
    dampings = []
    for elbow in np.linspace(0.3, 0.0, 301):
        q = np.array([0.0, elbow, 0.1, 0.0])
        sigma = np.linalg.svd(numeric_jacobian(model, q)[rows], compute_uv=False)[-1]
        output = controller.step(q, goal, dt=0.001)
        epsilon, damping_max = config.singular_threshold, config.damping_max
        expected = damping_max * math.sqrt(max(0.0, 1 - (sigma / epsilon) ** 2))
        assert output.damping == pytest.approx(expected, abs=1e-6)
        assert output.singular == (sigma < epsilon - 1e-9) or abs(sigma - epsilon) < 1e-6
        if previous_damping is not None:
            assert output.damping >= previous_damping - 1e-12
            # continuity: a small step in σ gives a small step in λ
            assert abs(output.damping - previous_damping) < 0.25 * damping_max
        previous_sigma, previous_damping = sigma, output.damping
        dampings.append(output.damping)
    assert dampings[0] == 0.0 and dampings[-1] == pytest.approx(config.damping_max)
    assert previous_sigma < 1e-12


# --- bad input ----------------------------------------------------------------------------


def test_bad_inputs_raise_clear_errors():
    model = load_robot("genova7")
    controller = CartesianController(model)
    q = model.initial_positions
    goal = genova7_scenario_goal()
    with pytest.raises(JointCountError, match="6 values.*7 joints"):
        controller.step(q[:6], goal)
    with pytest.raises(InvalidArgumentError, match="dt"):
        controller.step(q, goal, dt=0.0)
    with pytest.raises(InvalidArgumentError, match="dt"):
        controller.step(q, goal, dt=float("nan"))
    with pytest.raises(NonFiniteError):
        controller.step(np.full(7, np.nan), goal)
    with pytest.raises(NonFiniteError):
        controller.step(np.array([0, 0, 0, np.inf, 0, 0.1, 0]), goal)
    bad_goal = goal.copy()
    bad_goal[0, 3] = np.nan
    with pytest.raises(NonFiniteError):
        controller.step(q, bad_goal)
    with pytest.raises(InvalidArgumentError, match="4x4"):
        controller.step(q, np.eye(3))
    with pytest.raises(InvalidArgumentError, match="goal_twist"):
        controller.step(q, goal, goal_twist=np.zeros(6))
    with pytest.raises(InvalidArgumentError, match="gain_linear"):
        ControllerConfig(gain_linear=-1.0)
    with pytest.raises(InvalidArgumentError, match="singular_threshold"):
        ControllerConfig(singular_threshold=0.0)
    with pytest.raises(ManipKinError, match="task"):
        CartesianController(model, ControllerConfig(task="elbow"))


# --- the unrolled solver the hot path runs on -----------------------------------------------


def test_unrolled_damped_solve_matches_numpy():
    from manip_kin.codegen.unrolled_linalg import damped_solver
    from manip_kin.core.kinematics import compiled_kinematics

    rng = np.random.default_rng(12)
    model = load_robot("genova7")
    chain = compiled_kinematics(model, model.dof + 2, True)
    for rows in ((0, 1, 2, 3, 4, 5), (3, 4, 5), (2, 3, 4, 5)):
        folded = damped_solver(chain, 7, rows, inverse_trace=True)
        unfolded = damped_solver(chain, 7, rows, inverse_trace=True, fold_constants=False)
        for _ in range(10):
            q = model.random_configuration(rng)
            values = chain(q.tolist())
            jacobian = numeric_jacobian(model, q)[list(rows)]
            b = rng.normal(size=len(rows))
            shift = rng.choice([0.0, 1e-3])
            gram = jacobian @ jacobian.T + shift * np.eye(len(rows))
            qdot, determinant, trace_angular, trace_linear, inverse_trace = folded(values, b.tolist(), shift)
            np.testing.assert_allclose(qdot, jacobian.T @ np.linalg.solve(gram, b), rtol=1e-5, atol=1e-8)
            assert determinant == pytest.approx(np.linalg.det(gram), rel=1e-5)
            angular = [i for i, r in enumerate(rows) if r < 3]
            linear = [i for i, r in enumerate(rows) if r >= 3]
            assert trace_angular == pytest.approx(np.trace(gram[np.ix_(angular, angular)]), rel=1e-8, abs=0.0)
            assert trace_linear == pytest.approx(np.trace(gram[np.ix_(linear, linear)]), rel=1e-8)
            assert inverse_trace == pytest.approx(np.trace(np.linalg.inv(gram)), rel=1e-5)
            np.testing.assert_allclose(unfolded(values, b.tolist(), shift)[0], qdot, rtol=1e-12, atol=1e-15)
    # A zero Jacobian (every column zeroed) without damping is singular: None, not a crash.
    zeroed = list(chain(model.initial_positions.tolist()))
    zeroed[16:] = [0.0] * 42
    assert damped_solver(chain, 7, range(6), fold_constants=False)(zeroed, [1.0] * 6, 0.0) is None


@settings(max_examples=300, deadline=None)
@given(
    size_a=st.integers(0, 4),
    size_b=st.integers(0, 4),
    scale_b=st.floats(1e-3, 1e3),
    spread=st.floats(0.0, 8.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_smallest_eigenvalue_bound_is_a_lower_bound(size_a, size_b, scale_b, spread, seed):
    """The scaled AM–GM bound never exceeds λ_min (numpy's eigvalsh, with a margin for its
    rounding), is never below the plain bound det·((m-1)/tr)^(m-1), and is the optimum it claims
    to be: shrinking either group's diagonal by any u <= 1 gives a bound no larger."""
    from manip_kin.codegen.inlined import smallest_eigenvalue_bound

    size = size_a + size_b
    assume(size >= 1)
    rng = np.random.default_rng(seed)
    # Columns of spread magnitudes; the second group's rows in another unit (metres against radians).
    factor = rng.normal(size=(size, size + 1)) * np.exp(rng.uniform(-spread, spread, size=size + 1))
    factor[size_a:] *= scale_b
    matrix = factor @ factor.T
    eigenvalues = np.linalg.eigvalsh(matrix)
    determinant = float(np.prod(eigenvalues))
    trace_a, trace_b = float(np.trace(matrix[:size_a, :size_a])), float(np.trace(matrix[size_a:, size_a:]))
    bound = smallest_eigenvalue_bound(determinant, trace_a, size_a, trace_b, size_b)
    assert bound <= eigenvalues[0] + 1e-9 * eigenvalues[-1]
    if size == 1:
        assert bound == pytest.approx(determinant)
        return
    plain = determinant * ((size - 1) / (trace_a + trace_b)) ** (size - 1)
    if determinant <= 0.0:
        # A singular matrix whose determinant rounded below zero (seen: -6.6e-37): both bounds
        # are <= 0 there and certify nothing, which is all the step needs of them.
        assert bound <= 0.0 and plain <= 0.0
        return
    assert bound >= plain * (1 - 1e-12)
    for shrink in np.linspace(0.01, 1.0, 25):
        for u_a, u_b in ((shrink, 1.0), (1.0, shrink)):
            scaled_trace = u_a * trace_a + u_b * trace_b
            scaled = determinant * u_a**size_a * u_b**size_b * ((size - 1) / scaled_trace) ** (size - 1)
            assert bound >= scaled * (1 - 1e-9)


def test_smallest_eigenvalue_bound_is_nearly_tight_where_it_should_be():
    from manip_kin.codegen.inlined import smallest_eigenvalue_bound

    # The other eigenvalues equal and much larger than λ_min: the plain bound is nearly λ_min.
    eigenvalues = np.array([1e-4] + [2.0] * 5)
    bound = smallest_eigenvalue_bound(float(np.prod(eigenvalues)), 6.0, 3, 4.0 + 1e-4, 3)
    assert bound == pytest.approx(1e-4, rel=1e-3)
    # Angular rows ~1, linear rows ~0.01 (a short arm): the plain bound is hundreds of times
    # below λ_min, the scaled one close to it.
    matrix = np.diag([1.0, 1.2, 0.9, 0.01, 0.012, 2e-4])
    determinant = float(np.linalg.det(matrix))
    plain = determinant * (5 / np.trace(matrix)) ** 5
    scaled = smallest_eigenvalue_bound(determinant, 3.1, 3, 0.0222, 3)
    assert plain < 2e-4 / 500
    assert 2e-4 / 1.2 < scaled <= 2e-4
