"""The QP law: today's law when nothing binds, the limits, collision avoidance, fallback, blocked."""

import math
from dataclasses import replace

import numpy as np
import pytest
from collision_robots import (
    PANDA_FOLDED,
    PANDA_READY,
    ball_obstacle_distance,
    fresh_hand_link1_distance,
)
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from manip_kin.collision.distances import CollisionChecker
from manip_kin.control.qp.blocked import blocked_by
from manip_kin.control.qp.law import QpConfig, QpController, QpOutput
from manip_kin.control.qp.solver import SolveStatus, solve_qp
from manip_kin.control.qp.tasks import PostureTask
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.core.kinematics import frame_pose, jacobian
from manip_kin.core.robots import with_velocity_limits
from manip_kin.core.rotations import make_transform
from manip_kin.core.scene import Scene, make_obstacle

DT = 0.001  # the offline loop's period [s]
POSITION_TASK = ControllerConfig(task="position", gain_linear=3.0)


def _sphere_scene(centre, radius) -> Scene:
    scene = Scene()
    scene.add(make_obstacle(("cell", 1), "sphere", (2 * radius,) * 3, make_transform(None, centre)))
    return scene


def _run(law: QpController, q0, goal, steps: int, every=None):
    """Integrate the law's q̇ with DT; yields (q, output) after each step."""
    q = np.array(q0, dtype=float)
    for _ in range(steps):
        output = law.step(q, goal, dt=DT)
        q = q + output.qdot * DT
        yield q, output


# --- with no constraint active, the QP is today's law ---------------------------------------------


@given(seed=st.integers(0, 2**31 - 1))
@settings(max_examples=25)
def test_unconstrained_qp_is_todays_law(panda, seed):
    model, _ = panda
    rng = np.random.default_rng(seed)
    q = model.random_configuration(rng, margin=0.1)
    goal = frame_pose(model, q + rng.normal(0.0, 0.05, model.dof), "ee")
    today = CartesianController(model).step(q, goal, dt=DT)
    qp = QpController(model).step(q, goal, dt=DT)
    # 10 % inside the limits and a goal a few cm away: no limit binds.
    assert qp.status is SolveStatus.UNCONSTRAINED and not qp.active_constraints and not qp.fallback
    assert np.array_equal(qp.qdot, today.qdot)
    assert qp.damping == today.damping and np.array_equal(qp.position_error, today.position_error)


def test_qp_solve_with_nothing_binding_gives_todays_law(panda):
    """Through the solver too: the cost's minimiser is today's rates."""
    model, _ = panda
    rng = np.random.default_rng(7)
    law = QpController(model)
    for _ in range(30):
        q = model.random_configuration(rng, margin=0.1)
        goal = frame_pose(model, q + rng.normal(0.0, 0.05, model.dof), "ee")
        today = CartesianController(model).step(q, goal, dt=DT)
        task_jacobian = law.pose_task.jacobian(q)
        mu = max(today.damping**2, law.config.regularization)
        hessian = task_jacobian.T @ task_jacobian + mu * np.eye(model.dof)
        wide = np.full(model.dof, 1e3)
        solution = solve_qp(hessian, -hessian @ today.qdot, -wide, wide)
        assert np.allclose(solution.x, today.qdot, atol=1e-9, rtol=0)


# --- joint limits ------------------------------------------------------------------------------------


def test_a_joint_reaches_its_position_limit_smoothly(ball_arm):
    model, _ = ball_arm
    config = QpConfig(controller=POSITION_TASK, position_margin=0.05, position_gain=5.0)
    law = QpController(model, config)
    # A goal behind the shoulder: j2 would have to pass its upper limit (2 rad).
    goal = make_transform(None, [-0.5, 0.0, 0.5])
    limit = model.upper[1] - 0.05
    positions, rates = [], []
    for q, output in _run(law, [0.0, 1.5, 0.0], goal, 800):
        positions.append(q[1])
        rates.append(output.qdot[1])
    assert max(positions) <= limit + 1e-9
    assert max(positions) > limit - 0.01  # it gets there
    gap = limit - np.array(positions[:-1])
    assert np.all(np.array(rates[1:]) <= 5.0 * gap + 1e-9)  # the rate falls with the distance left


def test_acceleration_limit_bounds_each_change_of_command(ball_arm):
    model, _ = ball_arm
    law = QpController(model, QpConfig(controller=POSITION_TASK, max_acceleration=4.0))
    goal = frame_pose(model, [0.8, 0.3, 0.9], "ee")
    previous = np.zeros(model.dof)
    changes = []
    for _, output in _run(law, [0.0, 0.4, 0.8], goal, 300):
        changes.append(np.abs(output.qdot - previous).max())
        previous = output.qdot
    assert max(changes) <= 4.0 * DT + 1e-9
    assert any("acceleration:" in name for name in law.step([0.0, 0.4, 0.8], goal, dt=DT).active_constraints)


def test_posture_moves_only_the_null_space(panda):
    model, _ = panda
    reference = PANDA_READY + np.array([0.6, 0.0, -0.5, 0.0, 0.4, 0.0, 0.0])
    posture = PostureTask(reference, gain=2.0, weight=1.0)
    law = QpController(model, QpConfig(posture=posture))
    plain = CartesianController(model)
    goal = frame_pose(model, PANDA_READY, "ee")
    goal[:3, 3] += [0.03, -0.02, 0.01]
    q, q_plain = PANDA_READY.copy(), PANDA_READY.copy()
    start = np.linalg.norm(q - reference)
    for _ in range(400):
        output = law.step(q, goal, dt=DT)
        matrix = jacobian(model, q, "ee").matrix
        # The frame moves exactly as with today's law; the joints do something else.
        assert np.allclose(matrix @ output.qdot, matrix @ plain.step(q, goal, dt=DT).qdot, atol=1e-9)
        q = q + output.qdot * DT
        q_plain = q_plain + plain.step(q_plain, goal, dt=DT).qdot * DT
    assert np.linalg.norm(q - reference) < start - 0.05
    same_path = law.step(q, goal, dt=DT).position_error - plain.step(q_plain, goal, dt=DT).position_error
    assert np.linalg.norm(same_path) < 1e-4


# --- collision avoidance --------------------------------------------------------------------------


@given(
    offset=st.tuples(st.floats(-0.04, 0.04), st.floats(-0.06, 0.06), st.floats(-0.06, 0.06)),
    radius=st.floats(0.03, 0.07),
)
@settings(max_examples=8)
def test_goal_behind_an_obstacle_never_closer_than_the_safety_distance(ball_arm, offset, radius):
    model, collision = ball_arm
    start_q, goal_q = np.array([-0.6, 0.4, 0.8]), np.array([0.6, 0.4, 0.8])
    start, goal = frame_pose(model, start_q, "ee"), frame_pose(model, goal_q, "ee")
    centre = 0.5 * (start[:3, 3] + goal[:3, 3]) + np.array(offset)
    assume(ball_obstacle_distance(model, start_q, centre, radius) > 0.03)  # the start is clear
    checker = CollisionChecker(model, collision)
    checker.update_scene(_sphere_scene(centre, radius))
    config = QpConfig(controller=POSITION_TASK, collision_safety_distance=0.02, influence_distance=0.1)
    law = QpController(model, config, checker)
    nearest = math.inf
    for q, output in _run(law, start_q, goal, 700):
        nearest = min(nearest, ball_obstacle_distance(model, q, centre, radius))
        assert np.all(np.isfinite(output.qdot))
        assert np.all(np.abs(output.qdot) <= model.velocity_limits + 1e-9)
    assert nearest >= 0.02 - 1e-4
    assert law.fallback_count == 0


def test_goal_beside_an_obstacle_is_reached(ball_arm):
    model, collision = ball_arm
    start_q, goal_q = np.array([-0.6, 0.4, 0.8]), np.array([0.6, 0.4, 0.8])
    start, goal = frame_pose(model, start_q, "ee"), frame_pose(model, goal_q, "ee")
    centre = 0.5 * (start[:3, 3] + goal[:3, 3]) + np.array([0.0, 0.0, 0.12])  # above the chord
    checker = CollisionChecker(model, collision)
    checker.update_scene(_sphere_scene(centre, 0.05))
    law = QpController(model, QpConfig(controller=replace(POSITION_TASK, gain_linear=5.0)), checker)
    damped = 0
    for q, output in _run(law, start_q, goal, 1500):
        assert ball_obstacle_distance(model, q, centre, 0.05) >= 0.02 - 1e-4
        damped += output.nearest_pair is not None
    assert output.position_error_norm < 2e-3
    assert damped > 0  # it passed within the influence distance


def test_a_self_collision_goal_on_the_panda_stalls_without_contact_and_is_blocked(panda):
    model, collision = panda
    goal = frame_pose(model, PANDA_FOLDED, "ee")  # the hand inside link 1
    assert fresh_hand_link1_distance(model, PANDA_FOLDED) < -0.03
    config = QpConfig(controller=ControllerConfig(gain_linear=2.0, gain_angular=2.0))
    law = QpController(model, config, CollisionChecker(model, collision))
    history: list[QpOutput] = []
    nearest = math.inf
    for step, (q, output) in enumerate(_run(law, PANDA_READY, goal, 2500)):
        history.append(output)
        if step % 25 == 0:
            nearest = min(nearest, fresh_hand_link1_distance(model, q))
    assert nearest >= 0.02 - 1e-3
    assert output.position_error_norm > 0.05  # stalled short of the goal
    assert np.abs(output.qdot).max() < 0.05
    blocked = blocked_by(history[-300:])
    assert blocked is not None and blocked.pair == "panda_link1-panda_hand"
    assert blocked.distance == pytest.approx(0.02, abs=1e-3)
    assert "blocked by panda_link1-panda_hand" in blocked.reason
    # Today's law, same goal, same start: the hand goes into link 1.
    today = CartesianController(model, config.controller)
    q = PANDA_READY.copy()
    for _ in range(2500):
        q = q + today.step(q, goal, dt=DT).qdot * DT
    assert fresh_hand_link1_distance(model, q) < -0.02


def test_infeasible_qp_falls_back_to_todays_law_counted_and_safe(ball_arm):
    model, collision = ball_arm
    slow = with_velocity_limits(model, [1e-3, 1e-3, 1e-3])  # too slow to back out in time
    q = np.array([0.0, 0.4, 0.8])
    tip = frame_pose(model, q, "link3") @ np.array([0.25, 0.0, 0.0, 1.0])
    centre = tip[:3] + np.array([0.0, 0.0, 0.06])  # 1 cm into the tip sphere
    checker = CollisionChecker(slow, collision)
    checker.update_scene(_sphere_scene(centre, 0.03))
    law = QpController(slow, QpConfig(controller=POSITION_TASK), checker)
    goal = make_transform(None, tip[:3] + np.array([0.0, 0.0, 0.2]))  # straight into the obstacle
    first = law.step(q, goal, dt=DT)
    second = law.step(q, goal, dt=DT)
    assert first.fallback and first.status is SolveStatus.INFEASIBLE
    assert (first.fallback_count, second.fallback_count, law.fallback_count) == (1, 2, 2)
    rows = checker.evaluate(q, 0.1, 0.02, 0.5)
    assert np.all(rows.matrix @ first.qdot <= 1e-12)  # it does not close the pair any further
    assert np.all(np.isfinite(first.qdot))


# --- blocked ----------------------------------------------------------------------------------------


def _output(position_error: float, active=()) -> QpOutput:
    return QpOutput(
        qdot=np.zeros(3),
        orientation_error=np.zeros(3),
        position_error=np.array([position_error, 0.0, 0.0]),
        manipulability=0.1,
        damping=0.0,
        velocity_scale=1.0,
        limited_joints=(),
        singular=False,
        nearest_pair=("a", "b") if active else None,
        nearest_distance=0.02 if active else math.inf,
        active_constraints=active,
    )


def test_blocked_needs_a_stall_and_a_binding_collision_pair():
    held = ("collision:link3-obstacle:cell/1", "position:j2")
    assert blocked_by([_output(0.2, held)] * 10).pair == "link3-obstacle:cell/1"
    assert blocked_by([_output(0.2 - 0.01 * i, held) for i in range(10)]) is None  # progressing
    assert blocked_by([_output(0.2, ("position:j2",))] * 10) is None  # only a joint limit
    assert blocked_by([_output(0.2, held)]) is None  # too short a history
    assert blocked_by([_output(1e-4, held)] * 10) is None  # reached: nothing to block
    few = [_output(0.2, held)] * 5 + [_output(0.2)] * 5
    assert blocked_by(few) is None and blocked_by(few, active_fraction=0.5) is not None


def test_config_errors_say_what_is_valid(ball_arm):
    model, collision = ball_arm
    checker = CollisionChecker(model, collision)
    with pytest.raises(ValueError, match=r"influence distance = 0.01; valid: > collision_safety_distance"):
        QpController(model, QpConfig(influence_distance=0.01), checker)
    with pytest.raises(ValueError, match=r"posture reference has 2 values; the robot has 3 joints"):
        QpController(model, QpConfig(posture=PostureTask(np.zeros(2))))
    with pytest.raises(ValueError, match=r"max_acceleration"):
        QpController(model, replace(QpConfig(), max_acceleration=-1.0))


def _through_the_filter(law, model, soft, q0, goal, steps: int, braking, dt: float = 0.004, late=None):
    """The QP's rates through a CommandFilter with the ``soft`` limits, integrated: the positions.

    ``braking``: the law is given the filter's command (True), that command without its stretch
    (``"unstretched"``) or nothing (False). ``late``: each update's elapsed time, in periods (the
    arm drives each command that long); None: on time."""
    from manip_kin.control.command_filter import CommandFilter

    command_filter = CommandFilter(soft, model.lower, model.upper, dt)
    q, path, elapsed = np.array(q0, dtype=float), [], None
    for step in range(steps):
        command = command_filter.state if braking else None
        if braking == "unstretched":
            command = replace(command, stretch=1.0)
        output = law.step(q, goal, dt=dt, command=command)
        # The status names the nearest pair within the influence distance only (docs/interfaces.md).
        assert output.nearest_distance < law.config.influence_distance or math.isinf(output.nearest_distance)
        drive = dt if late is None else dt * late[step]
        q = q + np.array(command_filter.update(output.qdot, q, elapsed)) * drive
        elapsed = drive
        path.append(q)
    return path


def _nearest_through_the_filter(ball_arm, acceleration: float, variants, late=None) -> dict:
    """The ball arm driven from START to GOAL through the box between them, the QP's rates through
    a CommandFilter with ``acceleration`` [rad/s²] on every joint: for each of ``variants`` (as
    ``_through_the_filter``'s ``braking``), the nearest approach of its spheres to the box [m],
    in closed form."""
    from collision_robots import ball_centres, point_box_distance

    from manip_kin.control.joint_limits import JointLimit, JointLimits

    model, collision = ball_arm
    start_q, goal_q = np.array([-0.6, 0.4, 0.8]), np.array([0.6, 0.4, 0.8])
    start, goal = frame_pose(model, start_q), frame_pose(model, goal_q)
    centre, extents = 0.5 * (start[:3, 3] + goal[:3, 3]), (0.08, 0.08, 0.08)
    scene = Scene()
    scene.add(make_obstacle(("cell", 1), "box", extents, make_transform(None, centre)))
    soft = JointLimits.of(
        model, {n: JointLimit(True, 2.0, True, acceleration, False, 1.0, True, 50.0) for n in model.joint_names}
    )
    nearest = {}
    for braking in variants:
        checker = CollisionChecker(model, collision)
        checker.update_scene(scene)
        law = QpController(model, QpConfig(controller=POSITION_TASK, braking=soft), checker)
        path = _through_the_filter(law, model, soft, start_q, goal, 1500, braking, late=late)
        nearest[braking] = min(
            point_box_distance(c, centre, extents) - r for q in path for _, c, r in ball_centres(model, q)
        )
    return nearest


@pytest.mark.parametrize("acceleration", [1.0, 0.3])
def test_with_the_filters_braking_counted_soft_joint_limits_keep_the_safety_distance(ball_arm, acceleration):
    """A command filter that stops slowly (1 and 0.3 rad/s², stops of 2 and 6.7 s from full
    speed) takes the ball into the box when the dampers assume the rates are applied at once;
    with its braking counted the ball stops at the safety distance."""
    nearest = _nearest_through_the_filter(ball_arm, acceleration, (False, True))
    assert nearest[True] >= 0.02 - 1e-3, nearest
    assert nearest[False] < 0.02 - 5e-3, nearest  # the same run without: into the safety distance


@pytest.mark.parametrize("acceleration", [1.0, 0.3])
def test_a_loop_that_runs_late_keeps_the_safety_distance_with_soft_joint_limits(ball_arm, acceleration):
    """A loop that runs late (updates 1-6 periods apart, 2.3 on average) stretches the filter's
    stop, whose limits hold per update; the dampers count the stretch the filter measures, and
    the ball stops at the safety distance. Without the stretch counted it went into the safety
    distance."""
    late = np.random.default_rng(26).choice([1, 2, 3, 6], size=1500, p=[0.4, 0.3, 0.2, 0.1])
    nearest = _nearest_through_the_filter(ball_arm, acceleration, ("unstretched", True), late)
    assert nearest[True] >= 0.02 - 1e-3, nearest
    assert nearest["unstretched"] < 0.02 - 5e-3, nearest


@given(
    speed=st.floats(-3.0, 3.0),
    acceleration=st.floats(-20.0, 20.0),
    bound=st.floats(0.1, 20.0),
    jerk=st.floats(1.0, 5000.0) | st.just(math.inf),
)
@settings(max_examples=300, deadline=None)
def test_the_stopping_travel_bounds_the_time_optimal_stop(speed, acceleration, bound, jerk):
    from manip_kin.control.joint_limits import JointLimit, JointLimits, stopping_distance
    from manip_kin.core.robots import load_robot

    model = load_robot("scara")
    limit = JointLimit(True, 5.0, True, bound, False, bound, not math.isinf(jerk), 1.0 if math.isinf(jerk) else jerk)
    limits = JointLimits.of(model, dict.fromkeys(model.joint_names, limit))
    travel = limits.stopping_travel([speed] * 4, [acceleration] * 4)[0]
    direction = math.copysign(1.0, speed) if speed else math.copysign(1.0, acceleration)
    exact = stopping_distance(abs(speed), acceleration * direction, bound, jerk)
    assert travel * direction >= exact - 1e-12
    if acceleration == 0.0 and abs(speed) >= bound * bound / jerk:  # a stop that reaches -A: exact
        assert travel * direction == pytest.approx(exact, rel=1e-9)
