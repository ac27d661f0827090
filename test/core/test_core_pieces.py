"""The core's single implementations: errors and exit codes, the joint integrator, the inliner."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from kin_reference import rodrigues

from manip_kin.codegen.inlined import rotvec_from_quaternion, shepperd_quaternion
from manip_kin.codegen.ir import Names, indented
from manip_kin.codegen.source_inline import inline_lines
from manip_kin.control.integration import integrate_joint_rates
from manip_kin.core.rotations import rotvec_from_entries
from manip_kin.errors import (
    InputError,
    InvalidArgumentError,
    ManipKinError,
    OperationError,
    UnknownRobotError,
    exit_code_for,
)
from manip_kin.pipeline import PipelineError, pick_free_domain
from manip_kin.recording.errors import RecordingError

# --- errors ---------------------------------------------------------------------------------


def test_input_errors_and_failures_are_separate_families():
    assert issubclass(InvalidArgumentError, InputError) and issubclass(InputError, ValueError)
    assert issubclass(RecordingError, InputError)
    assert issubclass(PipelineError, OperationError) and not issubclass(PipelineError, ValueError)
    assert not issubclass(ManipKinError, ValueError)
    assert exit_code_for(UnknownRobotError("nosuchbot", ["genova7"])) == 2
    assert exit_code_for(PipelineError("robot_state exited")) == 1
    assert exit_code_for(ManipKinError("nothing to plot")) == 1


HOLD_A_DOMAIN = """
import sys
from manip_kin.pipeline import pick_free_domain
print(pick_free_domain(), flush=True)
sys.stdin.read()  # hold it until the test closes stdin
"""


def test_a_picked_domain_stays_reserved_while_its_process_lives():
    """Between two tests a test session has no participant on its domain: a benchmark started
    then once picked the same domain, and the two runs saw each other's topics."""
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_A_DOMAIN], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        held = int(holder.stdout.readline())
        every_other = [str(d) for d in range(1, 101) if d != held]
        with pytest.raises(PipelineError, match="no free ROS_DOMAIN_ID"):
            pick_free_domain(exclude=every_other)  # the only candidate is reserved
    finally:
        holder.stdin.close()
        assert holder.wait(30) == 0
    assert pick_free_domain(exclude=every_other) == held  # free again once its process ended


def test_node_runner_exit_codes(monkeypatch):
    """run_node: 2 for a configuration error, 1 for a failure that is not one."""
    from manip_kin.ros.runtime.runner import run_node

    def configuration_error():
        raise InvalidArgumentError("rate_hz = -5; valid: > 0")

    def failure():
        raise PipelineError("the recording directory vanished")

    assert run_node(configuration_error, "usage", argv=["node"]) == 2
    assert run_node(failure, "usage", argv=["node"]) == 1


def test_a_stop_signal_that_breaks_a_nodes_start_is_a_clean_stop(capfd):
    """A SIGINT while the node is made shuts its context down; what that breaks is a stop (0)."""
    import os
    import signal

    from manip_kin.ros.runtime.runner import run_node

    def interrupted():
        os.kill(os.getpid(), signal.SIGINT)  # rclpy's handler shuts the context down
        raise RuntimeError("failed to create publisher: rcl node's context is invalid")

    previous = signal.getsignal(signal.SIGINT)
    try:
        assert run_node(interrupted, "usage", argv=["node"]) == 0
    finally:
        signal.signal(signal.SIGINT, previous)
    assert "could not start" not in capfd.readouterr().err


def test_cli_maps_failures_to_exit_1(monkeypatch, capsys):
    import manip_kin.cli.model_commands as model_commands
    from manip_kin.cli import main

    def fail(args):
        raise PipelineError("no /joint_states within 1 s")

    original = model_commands.register

    def register(subparsers):
        original(subparsers)
        subparsers.choices["robots"].set_defaults(run=fail)

    monkeypatch.setattr(model_commands, "register", register)
    assert main(["robots"]) == 1
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "no /joint_states" in error[0]


# --- the joint integrator -------------------------------------------------------------------

joint_values = st.floats(-3.0, 3.0, allow_nan=False)


@settings(derandomize=True, max_examples=200)
@given(st.lists(st.tuples(joint_values, joint_values), min_size=1, max_size=7), st.floats(1e-4, 0.5))
def test_integrator_stays_in_limits_and_keeps_the_direction(joints, dt):
    q = [min(max(position, -1.0), 1.5) for position, _ in joints]
    rates = [rate for _, rate in joints]
    lower, upper = [-1.0] * len(q), [1.5] * len(q)
    inverse_limits = [1.0 / 2.0] * len(q)
    q_next, applied, scale, overshoot = integrate_joint_rates(q, rates, dt, lower, upper, inverse_limits)
    unclamped = np.array(q) + scale * np.array(rates) * dt
    np.testing.assert_allclose(q_next, np.clip(unclamped, lower, upper), atol=1e-15)
    assert overshoot == pytest.approx(max(0.0, float(np.max(np.maximum(-1.0 - unclamped, unclamped - 1.5)))))
    # scaled as a whole into the velocity limits: the direction of the command holds
    peak = max(abs(r) / 2.0 for r in rates)
    assert scale == pytest.approx(min(1.0, 1.0 / peak) if peak > 0 else 1.0)
    assert max(abs(r) for r in applied) <= 2.0 * (1 + 1e-12)
    np.testing.assert_allclose(np.array(applied) * dt, np.array(q_next) - np.array(q), atol=1e-12)


def test_integrator_without_velocity_limits_does_not_scale():
    q_next, applied, scale, overshoot = integrate_joint_rates([0.0, 0.9], [10.0, 10.0], 0.01, [-1, -1], [1, 1])
    assert scale == 1.0 and q_next == [0.1, 1.0] and overshoot == pytest.approx(0.0)
    assert applied == pytest.approx([10.0, 10.0])
    _, _, _, overshoot = integrate_joint_rates([0.0, 0.95], [10.0, 10.0], 0.01, [-1, -1], [1, 1])
    assert overshoot == pytest.approx(0.05)


# --- the inliner ----------------------------------------------------------------------------


def _run_inlined(entries: list[float]) -> tuple[float, float, float]:
    names = [f"M{i}{j}" for i in range(3) for j in range(3)]
    local = Names(["sqrt", "atan2", *names, "QX", "QY", "QZ", "QW", "E0", "E1", "E2"])
    lines = [f"{name} = {value!r}" for name, value in zip(names, entries)]
    lines += inline_lines(shepperd_quaternion, names, ["QX", "QY", "QZ", "QW"], local, "SQ_")
    lines += inline_lines(rotvec_from_quaternion, ["QX", "QY", "QZ", "QW"], ["E0", "E1", "E2"], local, "RV_")
    source = "def f():\n" + "\n".join(indented(lines)) + "\n    return E0, E1, E2\n"
    namespace = {"sqrt": math.sqrt, "atan2": math.atan2}
    exec(source, namespace)  # noqa: S102 - test source
    return namespace["f"]()


@settings(derandomize=True, max_examples=200)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 0.1),
    st.sampled_from([0.0, 1e-9, 1e-3, 1.0, 2.5, math.pi - 1e-7, math.pi]) | st.floats(0.0, math.pi),
)
def test_inlined_rotation_vector_is_axis_times_angle(axis, angle):
    """The inlined code computes rotvec_from_entries exactly, and that is axis·angle (Rodrigues)."""
    axis = np.array(axis) / np.linalg.norm(axis)
    rotation = rodrigues(axis, angle)
    inlined = _run_inlined(rotation.ravel().tolist())
    assert inlined == rotvec_from_entries(*rotation.ravel().tolist())
    if angle < math.pi - 1e-6:  # at π the axis sign is ambiguous
        np.testing.assert_allclose(inlined, axis * angle, atol=1e-9)
    else:
        assert np.linalg.norm(inlined) == pytest.approx(angle, abs=1e-6)
        assert abs(float(np.dot(inlined, axis))) == pytest.approx(angle, abs=1e-6)


@settings(max_examples=100)
@given(
    st.floats(0.0, 1e6),
    st.floats(1e-6, 1e3),
    st.integers(0, 4),
    st.floats(1e-6, 1e3),
    st.integers(0, 4),
)
def test_inliner_puts_literal_arguments_in_as_constants(determinant, trace_a, size_a, trace_b, size_b):
    """A number literal replaces its parameter (no local holds it, so arithmetic on it folds)
    and the inlined code computes what the function returns; names and expressions as before."""
    from manip_kin.codegen.inlined import smallest_eigenvalue_bound

    names = Names(["DET", "TA", "TB", "BOUND"])
    arguments = ["DET", "TA", str(size_a), "(TB)", str(size_b)]
    lines = inline_lines(smallest_eigenvalue_bound, arguments, ["BOUND"], names, "EB_")
    assert not any(line.startswith(("EB_size_a", "EB_size_b")) for line in lines)
    assert any(line.startswith("EB_trace_b") and line.endswith(" = (TB)") for line in lines)
    source = "def f(DET, TA, TB):\n" + "\n".join(indented(lines)) + "\n    return BOUND\n"
    namespace: dict = {}
    exec(source, namespace)  # noqa: S102 - test source
    if size_a + size_b == 0:
        return
    expected = smallest_eigenvalue_bound(determinant, trace_a, size_a, trace_b, size_b)
    assert namespace["f"](determinant, trace_a, trace_b) == expected


def test_inliner_refuses_what_it_cannot_inline():
    def early_return(x):
        if x > 0:
            return x
        return -x

    with pytest.raises(ValueError, match="Return"):
        inline_lines(early_return, ["a"], ["b"], Names(), "P_")
    with pytest.raises(ValueError, match="takes 1 arguments"):
        inline_lines(early_return, ["a", "b"], ["c"], Names(), "P_")


# --- the damped least-squares pieces --------------------------------------------------------


def test_damping_rule_is_chiaverinis():
    from manip_kin.codegen.inlined import damping_sq

    assert damping_sq(0.0, 4e-4, 1.6e-3) == pytest.approx(1.6e-3)  # λ_max² at a singularity
    assert damping_sq(1e-4, 4e-4, 1.6e-3) == pytest.approx(1.6e-3 * 0.75)
    assert damping_sq(4e-4, 4e-4, 1.6e-3) == 0.0 and damping_sq(1.0, 4e-4, 1.6e-3) == 0.0


@pytest.mark.parametrize("kernel", ["numpy's LAPACK kernel", "public eigvalsh"])
def test_symmetric_eigenvalues_match_eigvalsh_on_both_paths(monkeypatch, kernel):
    import manip_kin.core.damped_least_squares as dls

    if kernel == "public eigvalsh":
        monkeypatch.setattr(dls, "_EIGENVALUES_KERNEL", None)
    rng = np.random.default_rng(21)
    for size in (1, 3, 6):
        for _ in range(50):
            factor = rng.normal(size=(size, size + 1)) * rng.uniform(1e-4, 3.0, size=(size, 1))
            matrix = factor @ factor.T
            values = dls.symmetric_eigenvalues(tuple(matrix.ravel().tolist()), size)
            np.testing.assert_allclose(values, np.linalg.eigvalsh(matrix), rtol=1e-12, atol=1e-15)
