"""Every node parameter has a physical range, strict types and bounded refusals; no value inside
the declared ranges raises or makes an output non-finite (hypothesis over the ranges, in-process).

The ranges are read from the nodes' own tables (``PARAMETERS``), so a change of a range is
tested here as it is declared.
"""

import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from manip_kin.control.joint_tracking import joint_tracking_step
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.control.state_prediction import PLAUSIBLE_RATE_FACTOR, state_for_command
from manip_kin.control.status import StatusThrottle
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.errors import InvalidArgumentError
from manip_kin.motion.lines import TIME_SCALINGS, LineTrajectory, MotionLimits
from manip_kin.ros.nodes import (
    cartesian_controller_interface,
    live_view,
    recorder_config,
    robot_state_interface,
    trajectory_generator_interface,
)
from manip_kin.ros.runtime.params import QUOTE_LENGTH, ParamSpec, period_ns

LOOP_NODES = (robot_state_interface, cartesian_controller_interface, trajectory_generator_interface)
TABLES = {
    module.NODE_NAME: {spec.name: spec for spec in module.PARAMETERS}
    for module in (*LOOP_NODES, recorder_config, live_view)
}
LOOP_TABLES = {module.NODE_NAME: TABLES[module.NODE_NAME] for module in LOOP_NODES}
CONTROLLER = TABLES["cartesian_controller"]
GENERATOR = TABLES["trajectory_generator"]
RECORDER = TABLES["recorder"]
NUMBERS = [
    pytest.param(spec, id=f"{node}.{name}")
    for node, table in TABLES.items()
    for name, spec in table.items()
    if spec.kind in ("float", "int", "float_list")
]
ROBOTS = {name: load_robot(name) for name in ("genova7", "irb120", "scara", "rpp")}


def in_range(spec: ParamSpec):
    """Values a parameter accepts: its bounds, 0 where 0 means off, and anything between."""
    low, high = spec.minimum, spec.maximum
    if spec.kind == "int":
        values = st.integers(int(low), int(high))
    else:
        # Log-uniform as well as uniform: the range's small end (1e-6, 1e-9) is drawn too.
        values = st.floats(low, high)
        if low > 0:
            values = values | st.floats(math.log(low), math.log(high)).map(lambda x: min(max(math.exp(x), low), high))
    edges = st.sampled_from([low, high] + ([0.0] if spec.zero_is_off else []))
    return edges | values


# --- the tables -------------------------------------------------------------------------------------


@pytest.mark.parametrize("spec", NUMBERS)
def test_every_number_parameter_has_both_bounds_and_its_default_within_them(spec):
    assert spec.minimum is not None and spec.maximum is not None, spec.name
    assert spec.minimum <= spec.maximum
    assert spec.minimum > -math.inf and spec.maximum < math.inf
    if spec.default is not None:
        defaults = spec.default if isinstance(spec.default, list) else [spec.default]
        for value in defaults:
            assert spec.coerce(value) == value
    text = spec.constraint_text()
    assert f"{spec.minimum:g}" in text and f"{spec.maximum:g}" in text, text


@pytest.mark.parametrize("spec", NUMBERS)
def test_values_just_outside_the_range_are_refused_and_the_bounds_taken(spec):
    low, high = spec.minimum, spec.maximum
    as_value = (lambda v: [v]) if spec.kind == "float_list" else (lambda v: v)
    assert spec.coerce(as_value(low)) == as_value(low) and spec.coerce(as_value(high)) == as_value(high)
    below = low - 1 if spec.kind == "int" else (math.nextafter(low, -math.inf) if low != 0 else -1e-300)
    above = high + 1 if spec.kind == "int" else math.nextafter(high, math.inf)
    for value in (below, above):
        if spec.zero_is_off and value == 0:
            continue
        with pytest.raises(
            InvalidArgumentError, match=f"parameter {spec.name} = .*; valid: .*{re.escape(f'{high:g}')}"
        ):
            spec.coerce(as_value(value))


def test_the_reported_hostile_values_are_refused():
    # Each of these passed the old checks (finite, > 0) and then failed in the loop.
    for table, name, value in (
        (CONTROLLER, "damping_max", 1e200),  # damping_max**2 overflowed
        (CONTROLLER, "singular_threshold", 1e308),
        (CONTROLLER, "singular_threshold", 1e-300),  # epsilon**2 underflows to 0: a division by zero
        (CONTROLLER, "diagnostics_rate_hz", 1e-300),  # int(1e9 / rate) overflowed
        (GENERATOR, "diagnostics_rate_hz", 1e-300),
        (TABLES["robot_state"], "diagnostics_rate_hz", 1e-300),
        (CONTROLLER, "gain_linear", 1e308),  # NaN commands
        (CONTROLLER, "gain_angular", 1e308),
        (GENERATOR, "path_points", 10**12),  # MemoryError on the next line
        (CONTROLLER, "rate_hz", 1e-300),
        (GENERATOR, "max_linear_velocity", 1e-300),  # an infinite duration
        (RECORDER, "tf_rate_hz", 1e-300),  # OverflowError at start: int(1e9 / rate)
        (RECORDER, "duration", 1e300),  # a timer period beyond any integer of ns
        (RECORDER, "max_messages", 10**15),
        (TABLES["live_view"], "rate_hz", 1e-300),
        (TABLES["live_view"], "port", 70000),
    ):
        with pytest.raises(InvalidArgumentError, match=f"parameter {name} = "):
            table[name].coerce(value)


@pytest.mark.parametrize(
    ("table", "name", "value", "words"),
    [
        (CONTROLLER, "gain_linear", "1.5", "(text) has the wrong type; valid: a number"),
        (GENERATOR, "path_points", "50", "(text) has the wrong type; valid: an integer"),
        (CONTROLLER, "gain_linear", True, "(bool) has the wrong type"),
        (GENERATOR, "path_points", False, "(bool) has the wrong type"),
        (GENERATOR, "path_points", 2.5, "(float) has the wrong type"),
        (CONTROLLER, "velocity_limits", ["1.0", "2.0"], "(list) has the wrong type"),
        (CONTROLLER, "velocity_limits", [1.0, True], "(list) has the wrong type"),
        (CONTROLLER, "velocity_limits", "1.0", "(text) has the wrong type"),
        (CONTROLLER, "respect_velocity_limits", 1, "(int) has the wrong type; valid: true or false"),
        (CONTROLLER, "frame", 5, "(int) has the wrong type; valid: a string"),
        (RECORDER, "duration", "2", "(text) has the wrong type; valid: a number"),
        (RECORDER, "topics", [5], "(list) has the wrong type; valid: a list of strings"),
        (RECORDER, "topics", "joint_states", "(text) has the wrong type; valid: a list of strings"),
        (RECORDER, "all_topics", 1, "(int) has the wrong type; valid: true or false"),
    ],
)
def test_types_are_strict(table, name, value, words):
    with pytest.raises(InvalidArgumentError) as error:
        table[name].coerce(value)
    assert words in str(error.value), str(error.value)


def test_an_int_is_taken_for_a_float_as_on_the_command_line():
    assert CONTROLLER["rate_hz"].coerce(1000) == 1000.0 and isinstance(CONTROLLER["rate_hz"].coerce(1000), float)
    assert GENERATOR["path_points"].coerce(50.0) == 50  # an integral double for an integer


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("velocity_limits", [1.0] * 100_000),  # too many values
        ("velocity_limits", [1.0] * 5000 + [float("nan")]),  # one bad value among many
        ("velocity_limits", [1.0] * 5000 + [-1.0]),
        ("velocity_limits", ["x" * 1000] * 100),
        ("frame", "x" * 100_000),
        ("gain_linear", "9" * 100_000),
        ("gain_linear", [0.5] * 100_000),
        ("time_scaling", "y" * 500),
    ],
)
def test_refusals_quote_at_most_80_characters_of_the_value(name, value):
    spec = CONTROLLER.get(name) or GENERATOR[name]
    with pytest.raises(InvalidArgumentError) as error:
        spec.coerce(value)
    message = str(error.value)
    assert f"parameter {name} = " in message and "valid: " in message
    quoted_part = message.split(" = ", 1)[1].split("; valid", 1)[0]
    quoted_part = quoted_part.split(" has the wrong type")[0]
    assert len(quoted_part) <= QUOTE_LENGTH + 30, message  # the quote, its size and its type
    assert len(message) < 300, len(message)


# --- no value in the ranges raises or gives a non-finite output -----------------------------------


@given(rate=st.one_of(*(in_range(table["diagnostics_rate_hz"]) for table in LOOP_TABLES.values())))
def test_diagnostics_periods_are_finite_integers_for_every_valid_rate(rate):
    period = period_ns(rate)
    assert isinstance(period, int)
    if rate == 0:
        assert period == 0  # off
    else:
        assert 1_000_000 <= period <= 10_000_000_000  # 1 ms .. 10 s
        assert StatusThrottle(period).period_ns == period


@given(
    rate=in_range(CONTROLLER["rate_hz"]),
    timeout=in_range(CONTROLLER["joint_state_timeout"]) | in_range(CONTROLLER["goal_timeout"]),
)
def test_loop_periods_and_timeouts_are_finite_integers(rate, timeout):
    # The conversions the loop and the supervisors make (rate_loop, supervisors).
    assert 100_000 <= int(round(1e9 / rate)) <= 1_000_000_000
    assert 0 <= int(timeout * 1e9) <= 86_400 * 10**9


def _configuration(model, fractions):
    """Joint values at ``fractions`` (0..1) of each joint's range (limits clipped to +-pi)."""
    lower = np.maximum(model.lower, -math.pi)
    upper = np.minimum(model.upper, math.pi)
    return lower + np.asarray(fractions[: model.dof]) * (upper - lower)


unit = st.floats(0.0, 1.0)


@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow])
@given(
    robot=st.sampled_from(sorted(ROBOTS)),
    gain_angular=in_range(CONTROLLER["gain_angular"]),
    gain_linear=in_range(CONTROLLER["gain_linear"]),
    damping_max=in_range(CONTROLLER["damping_max"]),
    singular_threshold=in_range(CONTROLLER["singular_threshold"]),
    rate=in_range(CONTROLLER["rate_hz"]),
    respect_velocity_limits=st.booleans(),
    respect_position_limits=st.booleans(),
    q_fractions=st.lists(unit, min_size=7, max_size=7),
    # The goal: a pose of the arm (reachable) or one moved by up to 3 m (often out of reach), and
    # the stretched, singular configuration (all zeros) now and then.
    goal_fractions=st.lists(unit, min_size=7, max_size=7),
    goal_offset=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
    singular=st.booleans(),
    twist=st.none() | st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6),
)
def test_the_control_step_is_finite_and_within_the_limits_for_every_valid_configuration(
    robot,
    gain_angular,
    gain_linear,
    damping_max,
    singular_threshold,
    rate,
    respect_velocity_limits,
    respect_position_limits,
    q_fractions,
    goal_fractions,
    goal_offset,
    singular,
    twist,
):
    model = ROBOTS[robot]
    config = ControllerConfig(
        gain_angular=CONTROLLER["gain_angular"].coerce(gain_angular),
        gain_linear=CONTROLLER["gain_linear"].coerce(gain_linear),
        damping_max=CONTROLLER["damping_max"].coerce(damping_max),
        singular_threshold=CONTROLLER["singular_threshold"].coerce(singular_threshold),
        respect_velocity_limits=respect_velocity_limits,
        respect_position_limits=respect_position_limits,
    )
    controller = CartesianController(model, config)
    q = model.clip_to_limits(np.zeros(model.dof)) if singular else _configuration(model, q_fractions)
    goal = frame_pose(model, _configuration(model, goal_fractions), controller.frame_index)
    goal[:3, 3] += goal_offset
    feed_forward = None if twist is None else (np.array(twist[:3]), np.array(twist[3:]))
    dt = 1.0 / CONTROLLER["rate_hz"].coerce(rate)
    output = controller.step(q, goal, feed_forward, dt)
    assert np.all(np.isfinite(output.qdot)), output
    for value in (output.damping, output.manipulability, output.velocity_scale):
        assert math.isfinite(value), output
    assert 0.0 <= output.damping <= config.damping_max + 1e-12
    if respect_velocity_limits:
        assert np.all(np.abs(output.qdot) <= model.velocity_limits * (1 + 1e-9)), (output.qdot, model.velocity_limits)
    if respect_position_limits:
        q_next = q + output.qdot * dt
        span = model.upper - model.lower
        slack = 1e-9 * np.where(np.isfinite(span), np.maximum(span, 1.0), 1.0)
        assert np.all(q_next >= model.lower - slack) and np.all(q_next <= model.upper + slack), q_next


@settings(max_examples=150)
@given(
    scaling=st.sampled_from(TIME_SCALINGS),
    linear_velocity=in_range(GENERATOR["max_linear_velocity"]),
    linear_acceleration=in_range(GENERATOR["max_linear_acceleration"]),
    angular_velocity=in_range(GENERATOR["max_angular_velocity"]),
    angular_acceleration=in_range(GENERATOR["max_angular_acceleration"]),
    path_points=in_range(GENERATOR["path_points"]),
    start_fractions=st.lists(unit, min_size=6, max_size=6),
    goal_fractions=st.lists(unit, min_size=6, max_size=6),
    times=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=5),
)
def test_lines_planned_with_any_valid_limits_have_finite_timing_and_samples(
    scaling,
    linear_velocity,
    linear_acceleration,
    angular_velocity,
    angular_acceleration,
    path_points,
    start_fractions,
    goal_fractions,
    times,
):
    model = ROBOTS["irb120"]
    limits = MotionLimits(
        max_linear_velocity=GENERATOR["max_linear_velocity"].coerce(linear_velocity),
        max_linear_acceleration=GENERATOR["max_linear_acceleration"].coerce(linear_acceleration),
        max_angular_velocity=GENERATOR["max_angular_velocity"].coerce(angular_velocity),
        max_angular_acceleration=GENERATOR["max_angular_acceleration"].coerce(angular_acceleration),
    )
    start = frame_pose(model, _configuration(model, start_fractions))
    goal = frame_pose(model, _configuration(model, goal_fractions))
    line = LineTrajectory.plan(start, goal, scaling, limits)
    assert math.isfinite(line.duration) and line.duration >= 0.0
    assert int(line.duration * 1e9) >= 0  # the generator's stamps: start + int(t * 1e9)
    for fraction in times + [1.0]:
        pose, (angular, linear) = line.sample(fraction * line.duration)
        assert np.all(np.isfinite(pose)) and np.all(np.isfinite(angular)) and np.all(np.isfinite(linear))
        assert np.linalg.norm(linear) <= limits.max_linear_velocity * (1 + 1e-6) + 1e-12
        assert np.linalg.norm(angular) <= limits.max_angular_velocity * (1 + 1e-6) + 1e-12
    # planned_path: the generator publishes path_points poses (at least 2), sampled the same way.
    count = GENERATOR["path_points"].coerce(path_points)
    if count <= 500:  # the full range is covered by the bounds test; keep this one fast
        path = line.sample_path(count)
        assert len(path) == count and np.all(np.isfinite(path))


@settings(max_examples=150)
@given(
    robot=st.sampled_from(sorted(ROBOTS)),
    gain=in_range(CONTROLLER["gain_joint"]),
    rate=in_range(CONTROLLER["rate_hz"]),
    latency=in_range(CONTROLLER["command_latency"]),
    q_fractions=st.lists(unit, min_size=7, max_size=7),
    reference_fractions=st.lists(unit, min_size=7, max_size=7),
    velocity_fractions=st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7),
    age_periods=st.floats(-1.0, 20.0),
    respect_position_limits=st.booleans(),
)
def test_the_joint_law_and_the_state_prediction_are_finite_for_every_valid_gain_rate_and_latency(
    robot,
    gain,
    rate,
    latency,
    q_fractions,
    reference_fractions,
    velocity_fractions,
    age_periods,
    respect_position_limits,
):
    model = ROBOTS[robot]
    dt = 1.0 / CONTROLLER["rate_hz"].coerce(rate)
    q = _configuration(model, q_fractions)
    velocities = np.asarray(velocity_fractions[: model.dof]) * model.velocity_limits
    # The node's prediction (cartesian_controller.law_state) with the latency parameter.
    predicted = state_for_command(
        q,
        velocities,
        age_periods * dt,
        dt,
        CONTROLLER["command_latency"].coerce(latency),
        model.lower.tolist(),
        model.upper.tolist(),
        (PLAUSIBLE_RATE_FACTOR * model.velocity_limits).tolist(),
    )
    assert np.all(np.isfinite(predicted))
    output = joint_tracking_step(
        model,
        np.asarray(predicted),
        _configuration(model, reference_fractions),
        velocities,
        CONTROLLER["gain_joint"].coerce(gain),
        dt,
        respect_position_limits,
        True,
    )
    assert np.all(np.isfinite(output.qdot))
    assert np.all(np.abs(output.qdot) <= model.velocity_limits * (1 + 1e-9))
