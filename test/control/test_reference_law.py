"""The generated control step against the plain numpy law (:mod:`manip_kin.control.reference_law`).

Hypothesis draws the robot, the configuration (some joints exactly on a limit), the goal
(near or far, so the velocity scaling binds), the feed-forward twist and every parameter
of the controller; both implementations must give the same step.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.control.reference_law import reference_step
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.core.kinematics import frame_pose, jacobian
from manip_kin.core.pose_rows import parse_task
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import angle_axis_to_matrix

ROBOTS = {name: load_robot(name) for name in ("genova7", "irb120", "scara", "rpp", "mocom7")}
TASKS = {"genova7": (None, "position", "rz,x,y,z"), "irb120": (None, "position"), "mocom7": (None, "orientation")}

# Where each joint starts, as a fraction of its range: anywhere, or exactly on a limit.
fractions = st.one_of(st.floats(0.0, 1.0), st.sampled_from([0.0, 1.0]))


@st.composite
def cases(draw):
    name = draw(st.sampled_from(sorted(ROBOTS)))
    model = ROBOTS[name]
    n = model.dof
    lower = np.where(np.isfinite(model.lower), model.lower, -np.pi)
    upper = np.where(np.isfinite(model.upper), model.upper, np.pi)
    q = lower + np.array(draw(st.lists(fractions, min_size=n, max_size=n))) * (upper - lower)
    offset = np.array(draw(st.lists(st.floats(-0.6, 0.6), min_size=n, max_size=n)))
    goal = frame_pose(model, model.clip_to_limits(q + offset))
    # A turn of the goal below π (the rotation vector's axis flips at π) and a shift.
    angle = draw(st.floats(0.0, 2.5))
    axis = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3))) + [0.0, 0.0, 1e-3]
    goal[:3, :3] = angle_axis_to_matrix(angle, axis) @ goal[:3, :3]
    goal[:3, 3] += np.array(draw(st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3)))
    twist = None
    if draw(st.booleans()):
        values = np.array(draw(st.lists(st.floats(-0.5, 0.5), min_size=6, max_size=6)))
        twist = (values[:3], values[3:])
    config = ControllerConfig(
        gain_angular=draw(st.floats(0.0, 20.0)),
        gain_linear=draw(st.floats(0.0, 20.0)),
        task=draw(st.sampled_from(TASKS.get(name, (None,)))),
        damping_max=draw(st.sampled_from([0.0, 0.01, 0.04, 0.3])),
        singular_threshold=draw(st.sampled_from([0.005, 0.02, 0.1, 0.5])),
        respect_velocity_limits=draw(st.booleans()),
        respect_position_limits=draw(st.booleans()),
    )
    dt = draw(st.sampled_from([0.001, 0.002, 0.01, 0.1]))
    return model, q, goal, twist, config, dt


def _smallest_singular_value(model, q, config, held) -> float:
    """σ_min of the task Jacobian, and of it without the held joints' columns."""
    rows = list(parse_task(config.task, model).rows)
    task = jacobian(model, q).matrix[rows]
    reduced = task.copy()
    reduced[:, list(held)] = 0.0
    return min(np.linalg.svd(task, compute_uv=False)[-1], np.linalg.svd(reduced, compute_uv=False)[-1])


def _assert_same_step(model, q, dt, config, generated, reference):
    scale = 1.0 + float(np.max(np.abs(reference.qdot)))
    # Both solve from Jacobians equal to rounding; undamped near a singularity the solve
    # amplifies that by 1/σ_min.
    sigma = max(_smallest_singular_value(model, q, config, reference.limited_joints), reference.damping, 1e-12)
    np.testing.assert_allclose(generated.qdot, reference.qdot, rtol=1e-6, atol=scale * (1e-9 + 1e-14 / sigma))
    np.testing.assert_allclose(generated.orientation_error, reference.orientation_error, atol=1e-9)
    np.testing.assert_allclose(generated.position_error, reference.position_error, atol=1e-12)
    # A joint whose step lands on its limit to rounding (a rate of 0 on a limit) may be held by
    # one and not the other; its rate is the same either way (checked above), the flags of the
    # re-solved task are not.
    landing = q + reference.qdot * dt
    on_limit = {
        j
        for j in range(model.dof)
        if min(abs(landing[j] - model.lower[j]), abs(landing[j] - model.upper[j])) < 1e-9 * scale
    }
    assert set(generated.limited_joints) - on_limit == set(reference.limited_joints) - on_limit
    if generated.limited_joints == reference.limited_joints:  # else the re-solved task differs
        assert generated.singular == reference.singular
        assert generated.damping == pytest.approx(reference.damping, rel=1e-6, abs=1e-9)
    assert generated.velocity_scale == pytest.approx(reference.velocity_scale, rel=1e-9)
    assert generated.manipulability == pytest.approx(reference.manipulability, rel=1e-6, abs=1e-6)


@settings(max_examples=500, deadline=None)
@given(cases())
def test_the_generated_step_is_the_reference_law(case):
    model, q, goal, twist, config, dt = case
    generated = CartesianController(model, config).step(q, goal, twist, dt)
    _assert_same_step(model, q, dt, config, generated, reference_step(model, q, goal, config, twist, dt))


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_the_limit_cases_agree(name):
    """Every joint on a limit with the goal beyond it, and a far goal that saturates the rates."""
    model = ROBOTS[name]
    for q in (model.clip_to_limits(np.full(model.dof, -10.0)), model.clip_to_limits(np.full(model.dof, 10.0))):
        far = frame_pose(model, model.clip_to_limits(q[::-1] * 0.5))
        for config in (ControllerConfig(gain_linear=50.0, gain_angular=50.0), ControllerConfig(damping_max=0.0)):
            generated = CartesianController(model, config).step(q, far, None, 0.01)
            reference = reference_step(model, q, far, config, None, 0.01)
            _assert_same_step(model, q, 0.01, config, generated, reference)
        assert generated.velocity_scale < 1.0 or generated.limited_joints
