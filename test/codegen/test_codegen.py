"""Code generation's cache: keyed on structure, bounded, no leak on retuning, readable tracebacks.

The generated kernels (:mod:`manip_kin.codegen.kernel_cache`) are keyed on what their source depends
on; gains, damping, thresholds and limit values are arguments. Retuning a running controller
(the node rebuilds its core objects on every accepted parameter set, see
``CartesianControllerNode._configure``) must therefore compile nothing and keep memory flat.
"""

from __future__ import annotations

import gc
import linecache
import traceback
import tracemalloc
import weakref

import numpy as np
import pytest

from manip_kin.codegen import kernel_cache
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.control.simulation import simulate
from manip_kin.control.state_machines import ControllerSupervisor, ControllerSupervisorConfig
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.model import Joint, JointType, RobotModel
from manip_kin.core.robots import load_robot, with_velocity_limits
from manip_kin.ik.iterative import solve_ik

GENOVA = load_robot("genova7")
Q0 = GENOVA.start_configuration()
GOAL = frame_pose(GENOVA, GENOVA.clip_to_limits(Q0 + 0.02))


def _configure(gain: float, supervisor: ControllerSupervisor | None):
    """What ``CartesianControllerNode._configure`` builds on a live set, with the core classes."""
    config = ControllerConfig(gain_angular=gain, gain_linear=gain, damping_max=0.04 + gain * 1e-3)
    controller = CartesianController(GENOVA, config)
    supervisor_config = ControllerSupervisorConfig(
        joint_state_timeout=0.5,
        goal_timeout=0.0,
        goal_twist_timeout=0.2,
        position_tolerance=1e-4,
        orientation_tolerance=1e-3,
        joint_tolerance=1e-3,
        task=controller.task,
    )
    if supervisor is None:
        supervisor = ControllerSupervisor(supervisor_config, GENOVA.joint_names, 100_000_000)
    else:
        supervisor.reconfigure(supervisor_config, 100_000_000)
    return controller, supervisor


def test_setting_a_gain_ten_thousand_times_keeps_memory_and_the_cache_flat():
    controller, supervisor = _configure(0.5, None)
    for i in range(200):  # warm-up: every kernel built, allocator pools settled
        controller, supervisor = _configure(0.5 + 1e-4 * i, supervisor)
        controller.step(Q0, GOAL, None, 0.01)
    gc.collect()
    builds, size, per_model = kernel_cache.CACHE.builds, len(kernel_cache.CACHE), len(GENOVA.kernels)
    tracemalloc.start()
    try:
        gc.collect()
        before = tracemalloc.get_traced_memory()[0]
        for i in range(10_000):
            controller, supervisor = _configure(0.1 + 1e-4 * i, supervisor)
        controller.step(Q0, GOAL, None, 0.01)
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert kernel_cache.CACHE.builds == builds, "a retune generated code"
    assert len(kernel_cache.CACHE) == size and len(GENOVA.kernels) == per_model
    # One controller's worth of objects, not ten thousand steps' sources (~30 kB each).
    assert grown < 200_000, f"{grown} bytes kept by 10 000 retunes"
    # The last gain is the one in use: the law is linear in the gains away from the limits.
    last = 0.1 + 1e-4 * 9_999
    unit = CartesianController(GENOVA, ControllerConfig(gain_angular=1.0, gain_linear=1.0))
    np.testing.assert_allclose(
        controller.step(Q0, GOAL, None, 0.01).qdot, last * unit.step(Q0, GOAL, None, 0.01).qdot, rtol=1e-9, atol=1e-15
    )


def test_other_gains_and_limit_values_share_one_step_kernel():
    first = CartesianController(GENOVA, ControllerConfig(gain_linear=0.314159))
    # A model of the same structure built now: what a new model needs is in the cache and
    # recently used (GENOVA's own kernels may have been built, and evicted, tests ago).
    CartesianController(with_velocity_limits(GENOVA, GENOVA.velocity_limits * 0.9))
    builds = kernel_cache.CACHE.builds
    slower = with_velocity_limits(GENOVA, GENOVA.velocity_limits * 0.5)
    second = CartesianController(slower, ControllerConfig(gain_linear=3.0, singular_threshold=0.05))
    assert first._step.source == second._step.source
    # The new model builds its own chain function, from code already in the cache.
    assert kernel_cache.CACHE.builds == builds
    # Its values are the new ones: the velocity scale of the slower model binds earlier.
    fast_goal = frame_pose(GENOVA, GENOVA.clip_to_limits(Q0 + 0.3))
    assert second.step(Q0, fast_goal, None, 0.01).velocity_scale < first.step(Q0, fast_goal, None, 0.01).velocity_scale
    assert "0.314159" not in first._step.source and "3.0" not in first._step.source  # no gain literal


def test_a_dropped_model_keeps_nothing_alive():
    model = load_robot("irb120")
    model = RobotModel(name="copy", joints=model.joints, ee_offset=model.ee_offset, tool=model.tool)
    target = frame_pose(model, model.start_configuration() + 0.1)
    assert CartesianController(model).step(model.start_configuration(), target).qdot.shape == (6,)
    assert solve_ik(model, target, restarts=2, seed=0).success
    alive = weakref.ref(model)
    del model
    gc.collect()
    assert alive() is None, "a cache holds the model (keyed on its id)"


def test_the_cache_is_bounded_least_recently_used_and_registers_the_source():
    cache = kernel_cache.KernelCache(capacity=2)
    make = lambda k: lambda: f"def f():\n    return {k}\n"  # noqa: E731
    one = cache.kernel("test", (1,), make(1), "f", {})
    two = cache.kernel("test", (2,), make(2), "f", {})
    assert cache.kernel("test", (1,), make(99), "f", {}) is one  # a hit: the source is not asked for
    three = cache.kernel("test", (3,), make(3), "f", {})
    assert (one(), two(), three()) == (1, 2, 3) and len(cache) == 2 and cache.builds == 3
    # Key 2 was the least recently used: gone, with its lines; 1 and 3 stay.
    assert cache.kernel("test", (1,), make(99), "f", {}) is one
    assert cache.kernel("test", (2,), make(2), "f", {}) is not two
    assert cache.builds == 4
    filename = one.__code__.co_filename
    assert filename.startswith("<manip_kin test ") and linecache.getline(filename, 2).strip() == "return 1"
    cache.clear()
    assert len(cache) == 0 and linecache.getline(filename, 2) == ""
    with pytest.raises(ValueError, match="capacity"):
        kernel_cache.KernelCache(capacity=0)


def test_a_traceback_through_generated_code_shows_its_lines():
    controller = CartesianController(GENOVA)
    with pytest.raises(ValueError) as raised:
        controller._step([0.0] * 3, GOAL.tolist(), [0.0] * 6, 0.01)  # three joint values for seven joints
    text = "".join(traceback.format_exception(raised.value))
    assert '"<manip_kin control step ' in text
    assert "q0, q1, q2, q3, q4, q5, q6 = q" in text


def _long_chain(n: int) -> RobotModel:
    origin = np.eye(4)
    origin[2, 3] = 1e-3
    axes = (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    joints = tuple(
        Joint(name=f"j{i}", type=JointType.REVOLUTE, origin=origin, axis=axes[i % 2], lower=-1.0, upper=1.0)
        for i in range(n)
    )
    return RobotModel(name=f"chain{n}", joints=joints)


def test_a_3000_joint_chain_gives_fk_ik_and_simulate():
    """Generated sums are bracketed, so the compiler never recurses once per joint."""
    model = _long_chain(3000)
    start = np.zeros(3000)
    np.testing.assert_allclose(frame_pose(model, start)[:3, 3], [0.0, 0.0, 3.0], atol=1e-9)
    bent = np.full(3000, 1e-3)
    target = frame_pose(model, bent)
    # Joints about y alternate with joints about z: the y ones bend the 3 m column.
    assert np.linalg.norm(target[:3, 3] - [0.0, 0.0, 3.0]) > 1e-3
    result = solve_ik(
        model, target, start, max_iterations=5, restarts=0, tolerance_position=1e-3, tolerance_orientation=1e-2
    )
    assert result.success, result.reason
    run = simulate(model, start, target, dt=0.01, duration=0.02, tolerance=1e-3)
    assert len(run.q) >= 2 and np.all(np.isfinite(run.q))
    assert np.linalg.norm(frame_pose(model, run.q[-1])[:3, 3] - target[:3, 3]) < np.linalg.norm(
        frame_pose(model, start)[:3, 3] - target[:3, 3]
    )


def test_gains_set_through_the_parameter_services_compile_nothing():
    from node_harness import Harness
    from test_live_tuning import Parameters, _start_controller

    harness = Harness()
    try:
        node, _, stream = _start_controller(harness)
        params = Parameters(harness, "cartesian_controller")
        assert params.set(every=stream, gain_linear=0.7).successful
        builds, size = kernel_cache.CACHE.builds, len(kernel_cache.CACHE)
        for i in range(100):
            assert params.set(every=stream, gain_linear=0.5 + 0.01 * i, gain_angular=0.3 + 0.01 * i)[0].successful
        assert node.controller.config.gain_linear == pytest.approx(0.5 + 0.99)
        assert kernel_cache.CACHE.builds == builds and len(kernel_cache.CACHE) == size
    finally:
        harness.close()
