"""What the acceleration and jerk limits (issue 24) cost and change, for ``make bench``.

``run_limits_benchmarks()`` returns rows for ``bench/run.py`` (section ``limits``):

* the command filter's cost per cycle (:meth:`manip_kin.control.command_filter.CommandFilter.update`)
  against the control step (:meth:`manip_kin.control.resolved_rate.CartesianController.step`), timed in the
  same closed loop at 1 kHz: genova7 and the Franka Panda URDF, a new random goal every 0.2 s
  (transients, reversals, braking before position limits), and as a worst case a random target
  every call (ruckig computes a new profile each time);
* the controller's CPU at 1 kHz with the limits and without them (every joint's
  ``has_acceleration_limits`` and ``has_jerk_limits`` false), a goal running, and the
  goal-to-first-reacting-command latency of those pipelines (bench_nodes' loop and latency rows);
* the irb120 line offline (law, filter and a perfect integrator; no ROS, no timing), and the
  same with a starved controller whose cycles sometimes come late (simulated, seeded);
* time to converge on genova7's pose goal scenario and the irb120 line deviation at 0.4 m/s
  (normal scheduling and SCHED_FIFO 20), with and without the limits.

The pipelines with and without the limits run one after the other, ``rounds`` times in turn
(with, without, without, with, ...), so a change in the machine's load shows as spread, not as
a difference between the two.

Run alone: ``.venv/bin/python bench/bench_limits.py [filter|nodes]`` (filter: the rows without ROS).
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

#: genova7's pose goal scenario (robots.md): start, goal tool pose position and rpy.
GENOVA7_Q0 = [math.pi / 2, -math.pi / 4, 0.0, -math.pi / 4, 0.0, 0.15, math.pi / 4]
GENOVA7_GOAL = ([0.2, -0.7, 0.3], (0.0, 1.57, 0.0))

#: The starved rows: the chance that a cycle's next one is late, and by how many periods at most.
STARVED_LATE = (0.01, 0.02, 0.05)
STARVED_PERIODS = 10

#: The labels of the two configurations.
WITH, WITHOUT = "with limits", "without limits"


def without_limits_parameters(model) -> dict:
    """Controller parameters that switch the command filter off (test/support/node_harness.py's
    ``without_acceleration_limits``, the same layout)."""
    from node_harness import without_acceleration_limits

    return without_acceleration_limits(model.joint_names)


def _percentiles(values_ns: np.ndarray, overhead_ns: float) -> dict:
    values = (values_ns - overhead_ns) / 1e3
    return {"median_us": float(np.median(values)), "p99_us": float(np.percentile(values, 99))}


def benchmark_filter(model, n: int = 20_000, dt: float = 0.001, goal_every: int = 200, seed: int = 0) -> dict:
    """Per-call time [µs] of the command filter and of the control step in one closed loop.

    Each cycle runs the law as the controller node does (its position-limit horizon is that
    of a stop from full speed), filters its output and integrates the filtered command into
    ``q``; the goal is the pose of a new random configuration (5 % margin) every
    ``goal_every`` cycles. Three more filters get the same cycle's inputs apart: the same
    target without the positions (ruckig and the velocity scaling, no braking check), the
    same target and positions with the limits off (has_acceleration/jerk_limits false: the
    velocity scaling alone), and a random target within the velocity limits every call (the
    worst case for ruckig: a new profile each time).

    Returns:
        ``filter_median_us``/``filter_p99_us`` (as the node runs it), ``step_median_us``/
        ``step_p99_us``, the ratios ``filter_to_step_median``/``filter_to_step_p99``, the same
        two figures for the variants (``no_braking_check_*``, ``limits_off_*``, ``jump_*``),
        ``limited_fraction`` (cycles whose command differs from the law's: ruckig shaping it),
        ``braking_fraction`` (cycles with a joint braking before a position limit),
        ``step_general_path_fraction`` (steps that needed damping, position or velocity
        limits: the step's slow path, as in bench_motion), ``unsynchronised_cycles`` and ``n``.
    """
    from bench_motion import _timer_overhead_ns

    from manip_kin.control.command_filter import CommandFilter, FilterResult
    from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
    from manip_kin.core.kinematics import pose_in_base

    rng = np.random.default_rng(seed)
    both = limits_on_and_off(model)
    limits, limits_off = both[WITH], both[WITHOUT]
    controller = CartesianController(model, ControllerConfig())
    filters = {
        name: CommandFilter(chosen, model.lower, model.upper, dt)
        for name, chosen in (
            ("node", limits),
            ("no_braking_check", limits),
            ("limits_off", limits_off),
            ("jump", limits),
        )
    }
    velocity = np.where(np.isfinite(limits.velocity), limits.velocity, 0.0)
    horizon = max(dt, limits.stopping_time(velocity))  # as the controller node runs the law
    warm_up = 500
    total = n + warm_up
    goals = [
        pose_in_base(model, model.random_configuration(rng, margin=0.05), controller.frame_index)
        for _ in range(total // goal_every + 1)
    ]
    jumps = [(rng.uniform(-1.0, 1.0, model.dof) * velocity).tolist() for _ in range(1000)]
    lower, upper = model.lower, model.upper
    times = {name: np.empty(total) for name in ("step", *filters)}
    limited = braking = general = 0
    q = model.random_configuration(rng, margin=0.05)
    clock = time.perf_counter_ns
    step = controller.step
    update = filters["node"].update
    no_check, unfiltered, jump = (filters[name].update for name in ("no_braking_check", "limits_off", "jump"))
    for i in range(total):
        goal = goals[i // goal_every]
        t0 = clock()
        output = step(q, goal, None, horizon)
        t1 = clock()
        command = update(output.qdot, q)
        t2 = clock()
        no_check(output.qdot)
        t3 = clock()
        unfiltered(output.qdot, q)
        t4 = clock()
        jump(jumps[i % len(jumps)], q)
        t5 = clock()
        for name, begin, stop in (
            ("step", t0, t1),
            ("node", t1, t2),
            ("no_braking_check", t2, t3),
            ("limits_off", t3, t4),
            ("jump", t4, t5),
        ):
            times[name][i] = stop - begin
        if i >= warm_up:
            limited += filters["node"].result is FilterResult.LIMITED
            braking += bool(filters["node"].braking_joints)
            general += output.damping > 0.0 or bool(output.limited_joints) or output.velocity_scale < 1.0
        q = np.clip(q + dt * np.asarray(command), lower, upper)
    overhead = _timer_overhead_ns()
    figures = {name: _percentiles(values[warm_up:], overhead) for name, values in times.items()}
    row = {
        "filter_median_us": figures["node"]["median_us"],
        "filter_p99_us": figures["node"]["p99_us"],
        "step_median_us": figures["step"]["median_us"],
        "step_p99_us": figures["step"]["p99_us"],
        "filter_to_step_median": figures["node"]["median_us"] / figures["step"]["median_us"],
        "filter_to_step_p99": figures["node"]["p99_us"] / figures["step"]["p99_us"],
    }
    for name in ("no_braking_check", "limits_off", "jump"):
        row[f"{name}_median_us"] = figures[name]["median_us"]
        row[f"{name}_p99_us"] = figures[name]["p99_us"]
    row.update(
        limited_fraction=limited / n,
        braking_fraction=braking / n,
        step_general_path_fraction=general / n,
        unsynchronised_cycles=filters["node"].unsynchronised_cycles,
        n=n,
    )
    return row


def filter_rows(n: int = 20_000) -> list[dict]:
    from run import panda_model

    from manip_kin.core.robots import load_robot

    rows = []
    for label, model in (("genova7", load_robot("genova7")), ("panda (URDF)", panda_model())):
        rows.append(
            {
                "metric": f"command filter per cycle vs control step, {label}, 1 kHz closed loop",
                **benchmark_filter(model, n),
                "target": "(the filter's share of a cycle: the ratio)",
                "reference": "ruckig online velocity interface; jump: a random target every call",
            }
        )
    return rows


def limits_on_and_off(model) -> dict:
    """The default limits of ``model`` and the same with every acceleration and jerk limit off."""
    from manip_kin.control.joint_limits import JointLimits

    defaults = JointLimits.of(model)
    off = {"has_acceleration_limits": False, "has_jerk_limits": False}
    per_joint = {name: replace(limit, **off) for name, limit in zip(model.joint_names, defaults.per_joint)}
    return {WITH: defaults, WITHOUT: JointLimits.of(model, per_joint)}


def closed_loop(
    model,
    limits,
    reference,
    q0,
    steps: int,
    gain: float,
    dt: float = 0.001,
    until=None,
    jitter: float = 0.0,
    late: float = 0.0,
    late_periods: int = 10,
) -> dict:
    """The law, the command filter and a perfect integrator at ``dt``, as the controller node
    runs them (its position-limit horizon: a stop from full speed), without ROS or timing.

    Args:
        reference: ``t [s] -> (goal pose (4, 4), feed-forward twist or None)``.
        until: ``ControlOutput -> bool``: stop at the first step where it is true.
        jitter: the reference is taken at ``t`` plus a uniform error of at most this [s]
            (seeded): a goal paired with a state of a slightly different instant, as in a
            pipeline whose loops and delivery run off time.
        late: the chance [0, 1] that a cycle's next one comes late, by 2 to ``late_periods``
            periods (seeded): a starved loop. Meanwhile the arm keeps driving the last command
            (a hold-last-command interface) and the reference moves on; the late cycle's
            filter update is given the time that passed.

    Returns:
        ``points`` (controlled frame positions after each step, shape (k, 3)), ``steps``
        (steps run) and ``lag`` (the largest ``|law's rate - command|`` of any joint [rad/s | m/s]).
    """
    from manip_kin.control.command_filter import CommandFilter
    from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
    from manip_kin.core.kinematics import pose_in_base

    controller = CartesianController(model, ControllerConfig(gain_angular=gain, gain_linear=gain))
    command_filter = CommandFilter(limits, model.lower, model.upper, dt)
    velocity = np.where(np.isfinite(limits.velocity), limits.velocity, 0.0)
    horizon = max(dt, limits.stopping_time(velocity))
    q, points, lag = np.array(q0, dtype=float), [], 0.0
    rng = np.random.default_rng(0)
    timing_errors = rng.uniform(-jitter, jitter, steps)
    command, next_cycle, last_cycle = np.zeros(model.dof), 0, None
    for k in range(steps):
        if k >= next_cycle:
            pose, twist = reference(max(0.0, k * dt + timing_errors[k]))
            output = controller.step(q, pose, twist, horizon)
            if until is not None and until(output):
                break
            elapsed = None if last_cycle is None else (k - last_cycle) * dt
            # As the node: a law with a feed-forward twist follows a moving reference.
            command = np.asarray(command_filter.update(output.qdot, q, elapsed, twist is not None))
            lag = max(lag, float(np.max(np.abs(output.qdot - command))))
            last_cycle = k
            next_cycle = k + (int(rng.integers(2, late_periods + 1)) if late and rng.random() < late else 1)
        q = q + dt * command
        points.append(pose_in_base(model, q, controller.frame_index)[:3, 3])
    return {"points": np.array(points), "steps": k, "lag": lag}


def _along(line):
    """``t [s] -> (pose, twist)`` of ``line``, held at its end (no twist after it)."""

    def along_line(t: float):
        pose, twist = line.sample(min(t, line.duration))
        return pose, twist if t < line.duration else None

    return along_line


def offline_rows(dt: float = 0.001) -> list[dict]:
    """Without ROS (:func:`closed_loop`), with and without the limits: the irb120 line of
    bench_nodes (0.4 m/s, IRB120_LINE_GENERATOR's trapezoid, gains 6/s, feed-forward twist) and
    genova7's pose goal scenario. No timing in them: what the filter alone changes. Then the
    node rows' line (``jerk_limited``) with a starved controller (``late``, simulated): what a
    late cycle costs with and without the limits."""
    from bench_nodes import LINE_GENERATOR

    from manip_kin.core.robots import load_robot
    from manip_kin.core.rotations import make_transform, rpy_to_matrix
    from manip_kin.ik.iterative import solve_ik
    from manip_kin.motion.lines import LineTrajectory, MotionLimits, distance_to_segment
    from manip_kin.pipeline import IRB120_LINE_GENERATOR

    irb120 = load_robot("irb120")
    down = rpy_to_matrix(0.0, math.pi / 2, 0.0)
    start, end = make_transform(down, [0.4, 0.1, 0.6]), make_transform(down, [-0.4, 0.3, 0.5])
    motion = MotionLimits(
        IRB120_LINE_GENERATOR["max_linear_velocity"],
        IRB120_LINE_GENERATOR["max_linear_acceleration"],
        IRB120_LINE_GENERATOR["max_angular_velocity"],
    )
    line = LineTrajectory.plan(start, end, IRB120_LINE_GENERATOR["time_scaling"], motion)

    q_start = solve_ik(irb120, start, np.zeros(irb120.dof)).q
    steps = int((line.duration + 0.5) / dt)
    line_row: dict = {"metric": "irb120 line 0.4 m/s, offline closed loop at 1 kHz (no ROS)"}
    for tag, limits in limits_on_and_off(irb120).items():
        run = closed_loop(irb120, limits, _along(line), q_start, steps, 6.0, dt)
        deviation = distance_to_segment(run["points"], start[:3, 3], end[:3, 3])
        key = tag.replace(" ", "_")
        line_row[f"{key}_max_deviation_mm"] = float(deviation.max() * 1e3)
        line_row[f"{key}_max_command_lag"] = run["lag"]
        # What the limits do with a goal taken a little off the state's instant.
        for jitter_ms in (0.1, 0.5):
            run = closed_loop(irb120, limits, _along(line), q_start, steps, 6.0, dt, jitter=jitter_ms * 1e-3)
            deviation = distance_to_segment(run["points"], start[:3, 3], end[:3, 3])
            line_row[f"{key}_goal_jitter_{jitter_ms}ms_max_deviation_mm"] = float(deviation.max() * 1e3)
    line_row["target"] = "≤ 0.2 mm (issue 24)"
    line_row["reference"] = (
        "deterministic; lag: max |law's rate - command| of any joint [rad/s]; goal_jitter: the goal taken at "
        "its instant ± up to that much (uniform, seeded)"
    )
    # The node rows' line (jerk_limited) with a starved controller: what a late cycle costs.
    jerk_line = LineTrajectory.plan(start, end, LINE_GENERATOR["time_scaling"], motion)
    starved_row: dict = {
        "metric": f"irb120 line 0.4 m/s ({LINE_GENERATOR['time_scaling']}), offline at 1 kHz, the controller starved"
    }
    steps = int((jerk_line.duration + 0.5) / dt)
    for late in STARVED_LATE:
        for tag, limits in limits_on_and_off(irb120).items():
            run = closed_loop(
                irb120, limits, _along(jerk_line), q_start, steps, 6.0, dt, late=late, late_periods=STARVED_PERIODS
            )
            deviation = distance_to_segment(run["points"], start[:3, 3], end[:3, 3])
            starved_row[f"late_{late:g}_{tag.replace(' ', '_')}_max_deviation_mm"] = float(deviation.max() * 1e3)
    starved_row["target"] = "≤ 0.2 mm (issue 24)"
    starved_row["reference"] = (
        f"deterministic; late_p: each cycle's next one comes 2-{STARVED_PERIODS} periods late with chance p "
        "(seeded), the arm holding the last command meanwhile"
    )

    genova7 = load_robot("genova7")
    goal = make_transform(rpy_to_matrix(*GENOVA7_GOAL[1]), GENOVA7_GOAL[0])

    def converged(output) -> bool:  # the controller's default tolerances
        return np.linalg.norm(output.position_error) <= 1e-4 and np.linalg.norm(output.orientation_error) <= 1e-3

    converge_row: dict = {"metric": "genova7 pose goal, offline closed loop at 1 kHz (no ROS): time to converge"}
    for tag, limits in limits_on_and_off(genova7).items():
        run = closed_loop(genova7, limits, lambda t: (goal, None), GENOVA7_Q0, int(40 / dt), 0.8, dt, converged)
        converge_row[f"{tag.replace(' ', '_')}_s"] = run["steps"] * dt
    converge_row["exponential_s"] = _exponential_time(genova7, goal)
    converge_row["target"] = "close to the exponential time"
    converge_row["reference"] = "deterministic; gains 0.8/0.8 1/s, tolerances 1e-4 m, 1e-3 rad"
    return [line_row, starved_row, converge_row]


def _exponential_time(model, goal) -> float:
    """Pure exponential convergence from GENOVA7_Q0 at 0.8 1/s to the tolerances 1e-4 m, 1e-3 rad [s]."""
    from manip_kin.control.resolved_rate import pose_error
    from manip_kin.core.kinematics import frame_pose

    orientation, position = pose_error(frame_pose(model, GENOVA7_Q0), goal)
    return max(math.log(np.linalg.norm(position) / 1e-4), math.log(np.linalg.norm(orientation) / 1e-3)) / 0.8


def _converge_row(controller: dict, tag: str) -> dict:
    """genova7's pose goal scenario at 1 kHz: the time until the controller reports converged."""
    from manip_kin.core.robots import load_robot
    from manip_kin.core.rotations import make_transform, rpy_to_matrix
    from manip_kin.pipeline import Pipeline, pipeline_processes

    model = load_robot("genova7")
    goal = make_transform(rpy_to_matrix(*GENOVA7_GOAL[1]), GENOVA7_GOAL[0])
    processes = pipeline_processes(
        "genova7",
        rate_hz=1000.0,
        initial_positions=GENOVA7_Q0,
        controller={"gain_linear": 0.8, "gain_angular": 0.8, **controller},
    )
    with Pipeline(processes, log_dir=tempfile.mkdtemp(prefix="bench_limits_")) as pipeline:
        client = pipeline.client()
        client.spin_for(1.0)
        started = time.monotonic()
        stamp = client.send_goal(goal)
        converged, status = client.wait_converged(stamp, 40)
        return {
            "metric": f"genova7 pose goal at 1 kHz, time to converge, {tag}",
            "converged": converged,
            "time_to_converge_s": client.time_to_converge(stamp, started),
            "exponential_s": _exponential_time(model, goal),
            "position_error_m": status.number("position_error") if status is not None else math.nan,
            "target": "converged, close to the exponential time",
            "reference": "gains 0.8/0.8 1/s; exponential: ln(e0/tolerance)/0.8",
        }


def node_rows(rounds: int = 2) -> list[dict]:
    """CPU and latency at 1 kHz, convergence and the line, with and without the limits, in
    ``rounds`` rounds (the order alternating), then the ratios with/without of each round."""
    from bench_nodes import _line_row, _loop_rows

    from manip_kin.core.robots import load_robot
    from manip_kin.pipeline import ensure_ros_isolation

    ensure_ros_isolation()
    configurations = {
        WITH: ({}, {}),
        WITHOUT: (
            without_limits_parameters(load_robot("genova7")),
            without_limits_parameters(load_robot("irb120")),
        ),
    }
    rows: list[dict] = []
    by_round: list[dict[str, dict[str, dict]]] = []
    for number in range(rounds):
        order = (WITH, WITHOUT) if number % 2 == 0 else (WITHOUT, WITH)
        measured: dict[str, dict[str, dict]] = {}
        for tag in order:
            genova, irb = configurations[tag]
            label = f"{tag}, round {number + 1}"
            found = _measured(
                f"genova7 pipeline at 1 kHz, {label}",
                _loop_rows,
                1000.0,
                0,
                controller=genova,
                tag=label,
                floor=False,
                latency_steps=LATENCY_STEPS,
            )
            found += _measured(f"genova7 pose goal, {label}", _converge_row, genova, label)
            for priority in LINE_PRIORITIES:
                found += _measured(
                    f"irb120 line, priority {priority}, {label}", _line_row, 1000.0, priority, controller=irb, tag=label
                )
            measured[tag] = {row["metric"].replace(f", {label}", ""): row for row in found}
            rows += found
        by_round.append(measured)
    rows += _ratio_rows(by_round)
    return rows


def _measured(what: str, measure, *args, **kwargs) -> list[dict]:
    """The rows of ``measure(*args, **kwargs)`` (a row or a list of rows), or one row saying why
    there are none: on this shared machine a pipeline sometimes does not start in time (seen:
    robot_state after 30 s at a load average of 7), and the other figures are still worth having."""
    from manip_kin.pipeline import PipelineError

    try:
        found = measure(*args, **kwargs)
        return found if isinstance(found, list) else [found]
    except PipelineError as error:
        print(f"[bench] {what}: {str(error).splitlines()[0]}", file=sys.stderr)
        return [{"metric": what, "error": str(error).splitlines()[0], "target": "", "reference": ""}]


#: Latency goal steps [m] and trials: 10 µm (the limits let it through in one period: the
#: reaction alone) and 1 cm (a reversal within the limits).
LATENCY_STEPS = ((1e-5, 500), (0.01, 200))

#: The line at normal scheduling (the target's case) and at SCHED_FIFO 20 (where the machine
#: allows: the loops on time, so the limits' own share of the deviation shows).
LINE_PRIORITIES = (0, 20)

#: The figures compared with/without: (row metric without its label, value key, what it is).
COMPARED = (
    ("cartesian_controller loop, 1000 Hz", "cpu_percent", "controller CPU [% of a core]"),
    ("cartesian_controller loop, 1000 Hz", "compute_mean_ms", "controller compute per cycle [ms]"),
    ("goal-to-first-reacting-command latency, 1000 Hz, goals ±0.01 mm", "p99_ms", "goal to first command p99 [ms]"),
    ("goal-to-first-reacting-command latency, 1000 Hz, goals ±0.01 mm", "p50_ms", "goal to first command p50 [ms]"),
    ("goal-to-first-reacting-command latency, 1000 Hz", "p99_ms", "1 cm reversal, first command p99 [ms]"),
    ("genova7 pose goal at 1 kHz, time to converge", "time_to_converge_s", "time to converge [s]"),
    ("irb120 line 0.4 m/s, max deviation from the planned segment, 1000 Hz", "max_deviation_mm", "line deviation [mm]"),
    (
        "irb120 line 0.4 m/s, max deviation from the planned segment, 1000 Hz, SCHED_FIFO 20",
        "max_deviation_mm",
        "line deviation at SCHED_FIFO 20 [mm]",
    ),
)


def _ratio_rows(by_round: list[dict[str, dict[str, dict]]]) -> list[dict]:
    """Per compared figure: its value with and without the limits in each round and their ratio."""
    rows = []
    for metric, key, what in COMPARED:
        pairs = [
            (m[WITH].get(metric, {}).get(key, math.nan), m[WITHOUT].get(metric, {}).get(key, math.nan))
            for m in by_round
        ]
        rows.append(
            {
                "metric": f"with/without limits: {what}",
                "with": [round(w, 4) for w, _ in pairs],
                "without": [round(o, 4) for _, o in pairs],
                "ratio_per_round": [round(w / o, 3) if o else math.nan for w, o in pairs],
                "target": "latency p99: ratio ≤ 1 (not worse); line ≤ 0.2 mm",
                "reference": "one value per round; a round runs both, in turn",
            }
        )
    return rows


def run_limits_benchmarks(rounds: int = 2) -> list[dict]:
    return filter_rows() + offline_rows() + node_rows(rounds)


if __name__ == "__main__":
    sys.path.insert(1, str(__import__("pathlib").Path(__file__).resolve().parent.parent / "test" / "support"))
    part = sys.argv[1] if len(sys.argv) > 1 else ""
    chosen = {"filter": lambda: filter_rows() + offline_rows(), "nodes": node_rows}.get(part, run_limits_benchmarks)
    json.dump(chosen(), sys.stdout, indent=1)
    sys.stdout.write("\n")
