"""Speed of the collision-aware QP step, for ``make bench`` (section ``collision``).

Targets (issue 26): the collision-aware step for a 7-DoF arm with its URDF collision model and
three obstacles at p99 <= 250 µs per cycle and <= 30 % of a core at 1 kHz; without geometry
the plain pose task as fast as today.

The step runs in a closed loop (q integrated with the commanded rates, dt = 1 ms) from the
Panda's ready pose towards goals that pass near a sphere, beside a post and above the table,
so the pairs within the influence distance, the damper rows and the QP solves are those of a
running controller. Each cycle is timed on its own (p99 needs single cycles, not block means);
the plain step is timed in the same loop, interleaved, so the two share the machine's state.
So is the collision-aware step with the checker's Python path (``native=False``: its broad phase,
coal's Python bindings, numpy damper rows), on the same states: its rates must equal the native
one's to rounding (``largest_qdot_difference``).
Besides wall time, each cycle's thread CPU time is reported (``cpu_*``): on this shared
machine preemption puts milliseconds into the wall-clock tail that are not the step's.

``python bench/bench_collision.py`` prints the rows.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test" / "support"))  # collision_robots

GOAL_OFFSETS = ((0.25, 0.0, -0.1), (0.0, 0.35, 0.0), (0.1, -0.3, -0.25), (-0.1, 0.2, 0.15))
STEPS_PER_GOAL = 1500


def _panda_scene():
    from collision_robots import PANDA_READY, panda_files

    from manip_kin.collision.collision_model import load_collision_model
    from manip_kin.core.kinematics import frame_pose
    from manip_kin.core.rotations import make_transform
    from manip_kin.core.scene import Scene, make_obstacle
    from manip_kin.core.urdf import load_urdf

    urdf, srdf, share = panda_files()
    model = load_urdf(urdf)
    collision = load_collision_model(model, srdf=srdf, mesh_search_path=share)
    hand = frame_pose(model, PANDA_READY, "ee")[:3, 3]
    scene = Scene()
    scene.add(make_obstacle(("cell", 1), "sphere", (0.12,) * 3, make_transform(None, hand + [0.16, 0.0, -0.05])))
    scene.add(make_obstacle(("cell", 2), "cylinder", (0.08, 0.08, 0.8), make_transform(None, [0.35, 0.45, 0.4])))
    scene.add(make_obstacle(("cell", 3), "box", (1.2, 1.2, 0.04), make_transform(None, [0.3, 0.0, -0.03])))
    return model, collision, scene


def _percentiles(samples_ns: list[int], cpu_ns: list[int]) -> dict:
    """Wall-clock figures, and the thread's CPU time per cycle (what preemption by the other
    tenants of a loaded machine does not inflate)."""
    values = np.array(samples_ns, dtype=float) / 1000.0
    cpu = np.array(cpu_ns, dtype=float) / 1000.0
    return {
        "median_us": float(np.median(values)),
        "p90_us": float(np.percentile(values, 90)),
        "p99_us": float(np.percentile(values, 99)),
        "mean_us": float(values.mean()),
        "cpu_median_us": float(np.median(cpu)),
        "cpu_p99_us": float(np.percentile(cpu, 99)),
    }


def benchmark_collision_step(steps_per_goal: int = STEPS_PER_GOAL) -> list[dict]:
    """Rows: the collision-aware QP step, the QP step without geometry, today's plain step."""
    from collision_robots import PANDA_READY

    from manip_kin.collision.distances import CollisionChecker
    from manip_kin.control.qp.law import QpController
    from manip_kin.control.qp.solver import SolveStatus
    from manip_kin.control.resolved_rate import CartesianController
    from manip_kin.core.kinematics import frame_pose

    model, collision, scene = _panda_scene()
    checker = CollisionChecker(model, collision)
    checker.update_scene(scene)
    aware = QpController(model, checker=checker)
    # The same law on the checker's Python path, stepped on the same states: what the native one saves.
    python_checker = CollisionChecker(model, collision, native=False)
    python_checker.update_scene(scene)
    aware_python = QpController(model, checker=python_checker)
    no_geometry = QpController(model)
    plain = CartesianController(model)
    clock, cpu_clock = time.perf_counter_ns, time.thread_time_ns
    laws = (("aware", aware), ("aware_python", aware_python), ("no_geometry", no_geometry), ("plain", plain))
    timings: dict[str, list[int]] = {name: [] for name, _ in laws}
    cpu: dict[str, list[int]] = {name: [] for name, _ in laws}
    solved = rows = cycles = 0
    largest_difference = 0.0
    q = PANDA_READY.copy()
    for offset in GOAL_OFFSETS:
        goal = frame_pose(model, PANDA_READY, "ee")
        goal[:3, 3] += offset
        for _ in range(steps_per_goal):
            results = {}
            for name, law in laws:
                cpu_start, start = cpu_clock(), clock()
                results[name] = law.step(q, goal, dt=0.001)
                timings[name].append(clock() - start)
                cpu[name].append(cpu_clock() - cpu_start)
            output = results["aware"]
            largest_difference = max(
                largest_difference, float(np.abs(output.qdot - results["aware_python"].qdot).max())
            )
            solved += output.status is not SolveStatus.UNCONSTRAINED
            rows += len(output.active_constraints)
            cycles += 1
            q = q + output.qdot * 0.001
    aware_row = _percentiles(timings["aware"], cpu["aware"])
    aware_row.update(
        cpu_percent_at_1khz=float(np.mean(cpu["aware"])) / 1e4,
        qp_solved_fraction=solved / cycles,
        active_constraints_per_cycle=rows / cycles,
        fallbacks=aware.fallback_count,
        cycles=cycles,
        narrow_phase=checker.narrow_phase.name,
    )
    python_row = _percentiles(timings["aware_python"], cpu["aware_python"])
    python_row.update(
        median_ratio_to_native=python_row["median_us"] / aware_row["median_us"],
        p99_ratio_to_native=python_row["p99_us"] / aware_row["p99_us"],
        largest_qdot_difference=largest_difference,
    )
    return [
        {
            "metric": "collision-aware QP step panda (URDF meshes, SRDF, 3 obstacles)",
            **aware_row,
            "target": "p99 ≤ 250 µs, ≤ 30 % of a core at 1 kHz",
            "reference": "MoveIt Servo checks collisions at 10 Hz",
        },
        {
            "metric": "collision-aware QP step panda, Python collision path (same states, interleaved)",
            **python_row,
            "target": "",
            "reference": f"the row above with the {checker.narrow_phase.name} narrow phase",
        },
        {
            "metric": "QP step panda without geometry (joint limits only)",
            **_percentiles(timings["no_geometry"], cpu["no_geometry"]),
            "target": "",
            "reference": "same loop, interleaved",
        },
        {
            "metric": "plain pose-task step panda (today's law, same loop)",
            **_percentiles(timings["plain"], cpu["plain"]),
            "target": "unchanged: the controller keeps it when there is no geometry",
            "reference": "control step panda row",
        },
    ]


def benchmark_pair_distance(repeats: int = 20000) -> dict:
    """coal's distance between two Panda link meshes (convex hulls) and mesh-box, per call [µs]."""
    import coal

    model, collision, _ = _panda_scene()
    link4 = next(g for g in collision.geometries if g.link == "panda_link4").shape.coal_shape
    link6 = next(g for g in collision.geometries if g.link == "panda_link6").shape.coal_shape
    box = coal.Box(0.2, 0.2, 0.2)
    here = coal.Transform3s(np.eye(3), np.zeros(3))
    there = coal.Transform3s(np.eye(3), np.array([0.35, 0.05, 0.02]))
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    figures = {}
    for label, other in (("mesh_mesh", link6), ("mesh_box", box)):
        best = []
        for _ in range(3):
            start = time.perf_counter_ns()
            for _ in range(repeats):
                coal.distance(link4, here, other, there, request, result)
            best.append((time.perf_counter_ns() - start) / repeats / 1000.0)
        figures[f"{label}_us"] = min(best)
    return {
        "metric": "coal distance per pair (Panda link convex hulls)",
        **figures,
        "target": "",
        "reference": "triangle-mesh BVH query ~10 µs",
    }


def benchmark_solvers(problems: int = 300) -> dict:
    """daqp against proxsuite's dense solver on QPs of the Panda's shape (7 rates, bounds, 6 rows)."""
    import daqp

    rng = np.random.default_rng(0)
    cases = []
    for _ in range(problems):
        jacobian = rng.normal(size=(6, 7))
        hessian = jacobian.T @ jacobian + 1e-4 * np.eye(7)
        target = rng.normal(size=7)
        matrix = rng.normal(size=(6, 7))
        cases.append((hessian, -hessian @ target, matrix, matrix @ target - rng.uniform(0.0, 1.0, 6)))
    bounds = np.full(7, 1.5)
    times = []
    for hessian, linear, matrix, bound in cases:
        start = time.perf_counter_ns()
        daqp.solve(
            hessian, linear, matrix, np.concatenate([bounds, bound]), np.concatenate([-bounds, np.full(6, -1e30)])
        )
        times.append(time.perf_counter_ns() - start)
    row = {"metric": "QP solve, 7 rates + 7 bounds + 6 rows", "daqp_median_us": float(np.median(times)) / 1000.0}
    row["daqp_p99_us"] = float(np.percentile(times, 99)) / 1000.0
    try:
        import proxsuite
    except ImportError:
        row["proxsuite"] = "not installed (pip install proxsuite to compare)"
    else:
        solver = proxsuite.proxqp.dense.QP(7, 0, 6, True)
        hessian, linear, matrix, bound = cases[0]
        solver.init(hessian, linear, None, None, matrix, np.full(6, -1e30), bound, -bounds, bounds)
        times = []
        for hessian, linear, matrix, bound in cases:
            start = time.perf_counter_ns()
            solver.update(hessian, linear, None, None, matrix, np.full(6, -1e30), bound, -bounds, bounds)
            solver.solve()
            times.append(time.perf_counter_ns() - start)
        row["proxsuite_median_us"] = float(np.median(times)) / 1000.0
        row["proxsuite_p99_us"] = float(np.percentile(times, 99)) / 1000.0
    row.update(target="", reference="proxsuite dense, updated in place")
    return row


def _obstacle_arguments(hand: np.ndarray) -> list[list[str]]:
    """The three obstacles of :func:`_panda_scene` as ``manip_kin obstacle add`` arguments."""

    def xyz(values) -> list[str]:
        return [f"{v:.4f}" for v in values]

    return [
        ["--shape", "sphere", "--size", "0.12", "--xyz", *xyz(hand + [0.16, 0.0, -0.05])],
        ["--shape", "cylinder", "--size", "0.08", "0.8", "--xyz", *xyz([0.35, 0.45, 0.4])],
        ["--shape", "box", "--size", "1.2", "1.2", "0.04", "--xyz", *xyz([0.3, 0.0, -0.03])],
    ]


def _thread_cpu_ns(pid: int) -> dict[int, int]:
    """Each thread's time on a CPU so far [ns] (``/proc/<pid>/task/<tid>/schedstat``)."""
    times = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            times[int(tid)] = int(open(f"/proc/{pid}/task/{tid}/schedstat").read().split()[0])
        except (OSError, ValueError, IndexError):  # a thread that ended meanwhile
            continue
    return times


def benchmark_controller_cpu(windows: int = 3, window_s: float = 4.0) -> list[dict]:
    """cartesian_controller's process CPU at 1 kHz on the Panda, with and without collision_avoidance.

    The pipeline (robot_state, cartesian_controller, trajectory_generator) runs as processes;
    the three obstacles go on ``collision_objects``; goals alternate every 0.6 s between three
    poses near the sphere, so the law keeps tracking (a blocked goal would halt it). CPU is
    utime + stime of the controller process over each window; ``loop_thread_cpu_percent`` is its
    busiest thread's share (the loop; the rest is the executor and the middleware's threads).
    """
    import subprocess
    import sysconfig

    from bench_nodes import _cpu_seconds
    from collision_robots import PANDA_READY, panda_files

    from manip_kin.core.kinematics import frame_pose
    from manip_kin.core.urdf import load_urdf
    from manip_kin.pipeline import Pipeline, pipeline_processes

    manip_kin = str(Path(sysconfig.get_path("scripts")) / "manip_kin")
    urdf, srdf, share = panda_files()
    model = load_urdf(urdf)
    hand = frame_pose(model, PANDA_READY, "ee")
    goals = []
    for offset in ((0.08, 0.0, -0.04), (0.0, 0.2, 0.0), (0.05, -0.15, -0.1)):
        goal = hand.copy()
        goal[:3, 3] += offset
        goals.append(goal)
    rows = []
    for aware in (True, False):
        controller = {"gain_linear": 2.0, "gain_angular": 2.0}
        if aware:
            controller.update(collision_avoidance=True, srdf=str(srdf), mesh_search_path=share)
        processes = pipeline_processes(
            str(urdf), rate_hz=1000.0, initial_positions=PANDA_READY.tolist(), controller=controller
        )
        pipeline = Pipeline(processes).start()
        try:
            # The plain law has no collision_objects subscriber (nor use for it).
            for k, arguments in enumerate(_obstacle_arguments(hand[:3, 3]) if aware else ()):
                subprocess.run(
                    [manip_kin, "obstacle", "add", "--id", str(k + 1), *arguments, "--frame", model.base_frame],
                    capture_output=True,
                    timeout=30,
                    check=True,
                )
            client = pipeline.client()
            pid = pipeline.pid("cartesian_controller")
            percents, loop_percents = [], []
            for _ in range(windows):
                start_cpu, start_threads, start, sent = _cpu_seconds(pid), _thread_cpu_ns(pid), time.monotonic(), 0
                while time.monotonic() - start < window_s:
                    client.send_goal(goals[sent % len(goals)], model.base_frame)
                    sent += 1
                    client.spin_until(lambda: False, 0.6)
                elapsed = time.monotonic() - start
                percents.append(100.0 * (_cpu_seconds(pid) - start_cpu) / elapsed)
                threads = _thread_cpu_ns(pid)
                # The loop thread: the busiest one (the main thread's executor, Fast DDS's receive
                # threads and the rest are what the process takes besides it).
                loop_percents.append(max(ns - start_threads.get(tid, 0) for tid, ns in threads.items()) / 1e7 / elapsed)
        finally:
            pipeline.stop(timeout=30.0)
        label = "collision_avoidance, 3 obstacles" if aware else "plain law, same goals"
        rows.append(
            {
                "metric": f"cartesian_controller CPU at 1 kHz, panda, {label}",
                "cpu_percent": float(np.median(percents)),
                "cpu_percent_min": float(min(percents)),
                "cpu_percent_max": float(max(percents)),
                "loop_thread_cpu_percent": float(np.median(loop_percents)),
                "load_average": os.getloadavg()[0],
                "target": "≤ 30 % of a core" if aware else "",
                "reference": "process utime + stime over 4 s windows",
            }
        )
    return rows


def run_collision_benchmarks() -> list[dict]:
    """Every row of the ``collision`` section."""
    return [
        *benchmark_collision_step(),
        benchmark_pair_distance(),
        benchmark_solvers(),
        *benchmark_controller_cpu(),
    ]


if __name__ == "__main__":
    for row in run_collision_benchmarks():
        print(row)
