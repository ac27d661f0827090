"""The QP law for joint references and jogs (QpController.joint_step): the joint tracking law when
nothing binds, collision-limited otherwise.

Every distance asserted here is computed in closed form from plain forward kinematics (the ball
arm's spheres against an axis-aligned box, test/support/collision_robots.py), not through the
collision checker the law uses.
"""

import math

import numpy as np
import pytest
from collision_robots import BALL_ARM_BASE_BOX, ball_centres, point_box_distance
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.collision.distances import CollisionChecker
from manip_kin.control.joint_tracking import joint_tracking_step
from manip_kin.control.qp.blocked import joint_blocked_by
from manip_kin.control.qp.law import QpConfig, QpController, QpJointOutput
from manip_kin.control.qp.solver import SolveStatus
from manip_kin.control.qp.tasks import JointTask
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import with_velocity_limits
from manip_kin.core.rotations import make_transform
from manip_kin.core.scene import Scene, make_obstacle

DT = 0.001  # the offline loop's period [s]
GAIN = 5.0  # K [1/s]
SAFETY = 0.02
START_Q, GOAL_Q = np.array([-0.6, 0.4, 0.8]), np.array([0.6, 0.4, 0.8])  # j1 sweeps the arm across


def _box_scene(centre, extents) -> Scene:
    scene = Scene()
    scene.add(make_obstacle(("cell", 1), "box", extents, make_transform(None, centre)))
    return scene


def _box_distance(model, q, centre, extents) -> float:
    """The nearest of the ball arm's moving spheres to the box, in closed form [m]."""
    return min(point_box_distance(c, centre, extents) - r for _, c, r in ball_centres(model, q))


def _self_clearance(model, q) -> float:
    """A lower bound on the ball arm's spheres' distance to its base box and link 1's cylinder
    (radius 0.03 m around the z axis, z in [0.1, 0.3] m) [m]."""
    distances = []
    for _, centre, radius in ball_centres(model, q):
        distances.append(point_box_distance(centre, *BALL_ARM_BASE_BOX) - radius)
        axis = np.array([0.0, 0.0, np.clip(centre[2], 0.1, 0.3)])
        distances.append(float(np.linalg.norm(centre - axis)) - 0.03 - radius)
    return min(distances)


def _on_the_tool_path(model) -> np.ndarray:
    """Midway between the tool's positions at START_Q and GOAL_Q: on the swept arc's chord."""
    return 0.5 * (frame_pose(model, START_Q)[:3, 3] + frame_pose(model, GOAL_Q)[:3, 3])


def _law(model, collision, centre, extents, **config) -> QpController:
    checker = CollisionChecker(model, collision)
    checker.update_scene(_box_scene(centre, extents))
    return QpController(model, QpConfig(collision_safety_distance=SAFETY, **config), checker)


def _track(law: QpController, q0, reference, steps: int):
    """Integrate the joint step's q̇ with DT; yields (q, output) after each step."""
    q = np.array(q0, dtype=float)
    for _ in range(steps):
        output = law.joint_step(q, reference, None, GAIN, DT)
        q = q + output.qdot * DT
        yield q, output


def _plain(model, q0, reference, steps: int) -> list[np.ndarray]:
    """The joint tracking law alone (no collision limit), the same integration."""
    q, path = np.array(q0, dtype=float), []
    for _ in range(steps):
        q = q + joint_tracking_step(model, q, reference, None, GAIN, DT).qdot * DT
        path.append(q)
    return path


# --- with no constraint active, the QP is the joint tracking law ---------------------------------


@given(
    seed=st.integers(0, 2**31 - 1),
    gain=st.floats(0.0, 5.0),
    feed_forward=st.booleans(),
    robot=st.sampled_from(["panda", "ball_arm"]),
)
@settings(max_examples=40)
def test_unconstrained_joint_step_is_the_joint_tracking_law(panda, ball_arm, seed, gain, feed_forward, robot):
    model, collision = panda if robot == "panda" else ball_arm
    # The ball arm with its checker and an obstacle far off: damper rows are evaluated, none is near.
    law = QpController(model) if robot == "panda" else _law(model, collision, (3.0, 3.0, 3.0), (0.1, 0.1, 0.1))
    rng = np.random.default_rng(seed)
    if robot == "panda":
        q = model.random_configuration(rng, margin=0.1)
    else:  # arm raised, elbow not folded back: clear of its own base
        q = rng.uniform([-2.8, 0.0, -0.5], [2.8, 1.2, 1.5])
        assert _self_clearance(model, q) > law.config.influence_distance + 0.05
    reference = q + rng.uniform(-0.05, 0.05, model.dof)
    velocity = rng.uniform(-0.1, 0.1, model.dof) if feed_forward else None
    # >= 0.2 rad inside the limits: the position limit allows K_p (0.2 - 0.02) = 0.9 rad/s; asked: K·0.05 + 0.1.
    output = law.joint_step(q, reference, velocity, gain, DT)
    today = joint_tracking_step(model, q, reference, velocity, gain, DT)
    assert isinstance(output, QpJointOutput)
    assert output.status is SolveStatus.UNCONSTRAINED and not output.active_constraints and not output.fallback
    assert np.array_equal(output.qdot, today.qdot)
    assert np.array_equal(output.joint_error, today.joint_error)
    assert output.limited_joints == today.limited_joints == () and output.velocity_scale == today.velocity_scale


# --- collision avoidance --------------------------------------------------------------------------


def test_a_joint_reference_behind_a_pillar_stops_at_the_safety_distance_and_is_blocked(ball_arm):
    model, collision = ball_arm
    centre, extents = _on_the_tool_path(model), (0.08, 0.08, 0.6)  # too tall to pass over or under
    assert _box_distance(model, START_Q, centre, extents) > 0.05
    law = _law(model, collision, centre, extents)
    nearest, history = math.inf, []
    for q, output in _track(law, START_Q, GOAL_Q, 3000):
        nearest = min(nearest, _box_distance(model, q, centre, extents))
        history.append(output)
        assert np.all(np.abs(output.qdot) <= model.velocity_limits + 1e-9)
    assert nearest >= SAFETY - 1e-4, nearest
    assert np.abs(GOAL_Q - q).max() > 0.5  # held off, far from the reference
    assert np.abs(output.qdot).max() < 1e-3 and law.fallback_count == 0
    blocked = joint_blocked_by(history[-300:])
    assert blocked is not None and blocked.pair == "link2-obstacle:cell/1"
    assert blocked.distance == pytest.approx(SAFETY, abs=1e-3)
    assert blocked.joint_progress < 1e-3 and "blocked by link2-obstacle:cell/1" in blocked.reason
    # The joint tracking law alone, same start and reference: through the pillar.
    assert min(_box_distance(model, q, centre, extents) for q in _plain(model, START_Q, GOAL_Q, 3000)) < -0.03


def test_a_joint_reference_past_a_small_box_slides_around_it_and_is_reached(ball_arm):
    model, collision = ball_arm
    centre, extents = _on_the_tool_path(model), (0.08, 0.08, 0.08)
    law = _law(model, collision, centre, extents)
    nearest, damped, history = math.inf, 0, []
    for q, output in _track(law, START_Q, GOAL_Q, 3000):
        nearest = min(nearest, _box_distance(model, q, centre, extents))
        damped += bool(output.active_collision_pairs)
        history.append(output)
    assert nearest >= SAFETY - 1e-4, nearest
    assert damped > 0  # the damper bent the path
    assert np.abs(GOAL_Q - q).max() < 1e-4  # and the reference is reached
    assert joint_blocked_by(history[-300:]) is None
    # The joint tracking law alone goes through the box.
    assert min(_box_distance(model, q, centre, extents) for q in _plain(model, START_Q, GOAL_Q, 3000)) < 0.0


def test_an_infeasible_joint_step_falls_back_to_the_joint_law_counted_and_safe(ball_arm):
    model, collision = ball_arm
    slow = with_velocity_limits(model, [1e-3, 1e-3, 1e-3])  # too slow to back out in time
    q = np.array([0.0, 0.4, 0.8])
    tip = frame_pose(model, q, "link3") @ np.array([0.25, 0.0, 0.0, 1.0])
    centre = tip[:3] + np.array([0.0, 0.0, 0.06])  # 1 cm into the tip sphere
    checker = CollisionChecker(slow, collision)
    checker.update_scene(_box_scene(centre, (0.06, 0.06, 0.06)))
    law = QpController(slow, QpConfig(), checker)
    reference = q + np.array([0.0, 0.3, 0.0])  # j2 up: the tip into the box
    first = law.joint_step(q, reference, None, GAIN, DT)
    second = law.joint_step(q, reference, None, GAIN, DT)
    assert first.fallback and first.status is SolveStatus.INFEASIBLE
    assert (first.fallback_count, second.fallback_count, law.fallback_count) == (1, 2, 2)
    rows = checker.evaluate(q, 0.1, SAFETY, 0.5)
    assert np.all(rows.matrix @ first.qdot <= 1e-12)  # it does not close the pair any further
    assert np.all(np.isfinite(first.qdot)) and np.array_equal(first.joint_error, reference - q)


def test_joint_task_errors_say_what_is_valid(ball_arm):
    model, _ = ball_arm
    with pytest.raises(ValueError, match=r"joint gain -1.0; valid: a finite rate >= 0 \[1/s\]"):
        JointTask(model, -1.0)
    with pytest.raises(ValueError, match=r"joint gain"):
        QpController(model).joint_step(np.zeros(3), np.zeros(3), None, math.nan, DT)
    with pytest.raises(ValueError, match=r"q_reference"):
        QpController(model).joint_step(np.zeros(3), np.zeros(2), None, GAIN, DT)
