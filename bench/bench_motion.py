"""Speed of the control step and of the IK, for ``make bench``.

Targets (issue 3, numpy on this machine): one control step ≤ 12 µs; IK ≥ 99.9 % success at
≤ 1 ms mean over random reachable targets from random initial guesses.

``python bench/bench_motion.py [--steps N] [--targets N]`` prints both for genova7
and the Franka Panda URDF of ``example-robot-data``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from manip_kin.control.resolved_rate import CartesianController, ControllerConfig, pose_error
from manip_kin.core.kinematics import KinematicsData, forward_kinematics
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import parse_task
from manip_kin.core.rotations import angle_axis_to_matrix, make_transform
from manip_kin.ik.iterative import solve_ik


def _timer_overhead_ns(samples: int = 2000) -> float:
    clock = time.perf_counter_ns
    deltas = []
    for _ in range(samples):
        start = clock()
        deltas.append(clock() - start)
    return float(np.median(deltas))


def benchmark_control_step(model: RobotModel, n: int = 20000, seed: int = 0, dt: float = 0.002) -> dict:
    """Wall time of :meth:`CartesianController.step` (FK, Jacobian, damped solve, limits).

    Each call gets a different configuration (uniform within the limits, 5 % margin) and a
    goal a few centimetres and a few degrees away, as in a running control loop; calls near
    a singularity or a limit take the general path and are included.

    Args:
        model: the robot.
        n: number of timed steps.
        seed: seed of the configurations.
        dt: control period passed to the step [s].

    Returns:
        ``median_us``, ``p90_us``, ``mean_us``, ``min_us`` (per step, timer overhead removed),
        ``regular_median_us``/``singular_median_us`` and their ratio ``singular_to_regular``
        (steps with σ_min < ε against the others), ``singular_fraction``,
        ``general_path_fraction`` (steps that needed damping, limits or velocity scaling) and
        ``n``.
    """
    rng = np.random.default_rng(seed)
    controller = CartesianController(model, ControllerConfig())
    frame = controller.frame_index
    data = KinematicsData(model)
    cases = []
    for _ in range(min(n, 2000)):
        q = model.random_configuration(rng, margin=0.05)
        forward_kinematics(model, data, q)
        pose = data.tool if frame == model.dof + 2 else data.ee
        rotation = angle_axis_to_matrix(rng.uniform(0.0, 0.1), rng.normal(size=3)) @ pose[:3, :3]
        cases.append((q, make_transform(rotation, pose[:3, 3] + rng.normal(scale=0.03, size=3))))
    for q, goal in cases[:200]:  # warm-up (and generated-code compilation)
        controller.step(q, goal, dt=dt)
    overhead = _timer_overhead_ns()
    clock = time.perf_counter_ns
    step = controller.step
    timings = np.empty(n)
    singular = np.zeros(n, dtype=bool)
    general = 0
    for i in range(n):
        q, goal = cases[i % len(cases)]
        start = clock()
        output = step(q, goal, None, dt)
        timings[i] = clock() - start
        singular[i] = output.singular
        general += output.damping > 0.0 or bool(output.limited_joints) or output.velocity_scale < 1.0
    timings = (timings - overhead) / 1e3
    regular_median = float(np.median(timings[~singular]))
    singular_median = float(np.median(timings[singular])) if singular.any() else float("nan")
    return {
        "median_us": float(np.median(timings)),
        "p90_us": float(np.percentile(timings, 90)),
        "mean_us": float(np.mean(timings)),
        "min_us": float(np.min(timings)),
        # Steps near a singularity (σ_min < ε, damped) against the others, timed in the same run.
        "regular_median_us": regular_median,
        "singular_median_us": singular_median,
        "singular_to_regular": singular_median / regular_median,
        "singular_fraction": float(singular.mean()),
        "general_path_fraction": general / n,
        "n": n,
    }


def benchmark_ik(model: RobotModel, n_targets: int = 2000, seed: int = 0, **ik_options) -> dict:
    """Success rate and wall time of :func:`manip_kin.ik.iterative.solve_ik` on reachable targets.

    Targets are the frame poses of uniformly random configurations within the limits; each
    solve starts from another random configuration. Success means position error < 1e-5 m
    and orientation error < 1e-4 rad on the task components, checked with the core's numpy
    forward kinematics, and the result within the limits.

    Args:
        model: the robot.
        n_targets: number of targets.
        seed: seed of targets, initial guesses and restarts.
        **ik_options: passed to :func:`solve_ik` (method, tolerances, time_budget, …).

    Returns:
        ``success_rate``, ``mean_ms``, ``median_ms``, ``p90_ms``, ``p99_ms``, ``max_ms``,
        ``mean_iterations``, ``mean_attempts``, ``failures`` (count) and ``n_targets``.
    """
    rng = np.random.default_rng(seed)
    data = KinematicsData(model)

    def frame_pose_in_base(q):
        forward_kinematics(model, data, q)
        return data.tool.copy()

    targets = [frame_pose_in_base(model.random_configuration(rng)) for _ in range(n_targets)]
    guesses = [model.random_configuration(rng) for _ in range(n_targets)]
    solve_ik(model, targets[0], guesses[0], seed=seed, **ik_options)  # warm-up: code generation
    times, iterations, attempts = [], [], []
    successes = 0
    for index, (target, guess) in enumerate(zip(targets, guesses)):
        start = time.perf_counter()
        result = solve_ik(model, target, guess, seed=seed + index, **ik_options)
        times.append(time.perf_counter() - start)
        iterations.append(result.iterations)
        attempts.append(result.attempts)
        orientation, position = pose_error(frame_pose_in_base(result.q), target)
        error = np.concatenate([orientation, position])
        rows = parse_task(result.task).rows
        orientation_error = float(np.linalg.norm(error[[r for r in rows if r < 3]]))
        position_error = float(np.linalg.norm(error[[r for r in rows if r >= 3]]))
        successes += bool(position_error < 1e-5 and orientation_error < 1e-4 and model.within_limits(result.q, 0.0))
    milliseconds = np.array(times) * 1e3
    return {
        "success_rate": successes / n_targets,
        "mean_ms": float(np.mean(milliseconds)),
        "median_ms": float(np.median(milliseconds)),
        "p90_ms": float(np.percentile(milliseconds, 90)),
        "p99_ms": float(np.percentile(milliseconds, 99)),
        "max_ms": float(np.max(milliseconds)),
        "mean_iterations": float(np.mean(iterations)),
        "mean_attempts": float(np.mean(attempts)),
        "failures": n_targets - successes,
        "n_targets": n_targets,
    }


def _models() -> dict[str, RobotModel]:
    from manip_kin.core.robots import load_robot

    models = {"genova7": load_robot("genova7")}
    try:
        from robot_data_files import example_robot_data_urdf

        from manip_kin.core.urdf import load_urdf

        models["panda (URDF)"] = load_urdf(example_robot_data_urdf("panda_description/urdf/panda.urdf"))
    except (ImportError, FileNotFoundError) as error:
        print(f"panda URDF skipped: {error}")
    return models


def main(argv=None) -> int:
    """Print the control-step and IK figures next to their targets."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20000, help="timed control steps per robot")
    parser.add_argument("--targets", type=int, default=2000, help="IK targets per robot")
    args = parser.parse_args(argv)
    for name, model in _models().items():
        step = benchmark_control_step(model, args.steps)
        print(
            f"{name:14s} control step: median {step['median_us']:.1f} µs, p90 {step['p90_us']:.1f} µs "
            f"(target ≤ 12 µs; {100 * step['general_path_fraction']:.1f}% general path)"
        )
        ik = benchmark_ik(model, args.targets)
        print(
            f"{name:14s} IK: {100 * ik['success_rate']:.2f}% success, mean {ik['mean_ms']:.3f} ms, "
            f"median {ik['median_ms']:.3f} ms, p99 {ik['p99_ms']:.2f} ms, {ik['mean_iterations']:.1f} iterations, "
            f"{ik['mean_attempts']:.2f} attempts (target ≥ 99.9% at ≤ 1 ms mean)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
