"""``make bench`` section ``physics``: the MuJoCo plant's speed and the tracking on both plants.

* physics steps per second (``MujocoPlant.step`` of one 1 ms physics step, servo included)
  for each bundled arm and the Panda;
* robot_state's CPU at 1 kHz on each plant, with the controller driving the genova7 pose goal;
* tracking on each plant, side by side: the genova7 pose goal, the irb120 line at 0.4 m/s and
  a Panda goal (final error, overshoot past the goal, settling time to 1 mm, line deviation).
"""

from __future__ import annotations

import math
import tempfile
import time

import numpy as np
from bench_nodes import _cpu_seconds, _line_row

PLANTS = ("kinematic", "mujoco")
SETTLED_M = 1e-3  # settling: the tool within 1 mm of the goal from then on
# The Panda's start: elbow bent, away from the stretched (singular) zero configuration.
PANDA_READY = np.array([0.0, -0.5, 0.0, -2.0, 0.0, 1.6, 0.8])


def _panda_path() -> str:
    from robot_data_files import PANDA, example_robot_data_urdf

    return str(example_robot_data_urdf(PANDA))


def _panda_mesh_search_path() -> str:
    from pathlib import Path

    return str(Path(_panda_path()).parents[4])


def physics_step_rows(repeats: int = 3000) -> list[dict]:
    from run import _time_calls

    from manip_kin.core.robots import bundled_robot_names, load_robot
    from manip_kin.plant.mujoco_plant import MujocoPlant, PhysicsConfig

    rows = []
    arms = [(name, load_robot(name), None, "") for name in bundled_robot_names()]
    path = _panda_path()
    arms.append(("panda (URDF, meshes)", load_robot(path), open(path).read(), _panda_mesh_search_path()))
    for label, model, urdf_text, search in arms:
        plant = MujocoPlant(model, model.start_configuration(), PhysicsConfig(mesh_search_path=search), urdf_text)
        command = 0.1 * np.ones(model.dof)
        timing = _time_calls(lambda c, plant=plant: plant.step(c, 1e-3), [command, -command], repeats)
        rows.append(
            {
                "metric": f"physics step {label} (1 ms, servo included)",
                "steps_per_s": 1e6 / timing["median_us"],
                **timing,
                "target": "≥ 1000/s (real time at physics_rate_hz 1000)",
                "reference": "mj_step alone ~10-20 µs for a 7-DoF arm",
            }
        )
    return rows


def _approach_figures(samples: list[tuple[float, np.ndarray]], goal: np.ndarray, start_time: float) -> dict:
    """Overshoot past the goal along the approach [mm], settling time to 1 mm [s], final error [mm]."""
    times = np.array([t for t, _ in samples]) - start_time
    points = np.array([p for _, p in samples])
    direction = goal - points[0]
    direction /= max(np.linalg.norm(direction), 1e-12)
    beyond = (points - goal) @ direction
    error = np.linalg.norm(points - goal, axis=1)
    outside = np.flatnonzero(error > SETTLED_M)
    settling = float(times[outside[-1] + 1]) if outside.size and outside[-1] + 1 < len(times) else math.nan
    return {
        "final_error_mm": float(error[-1] * 1e3),
        "overshoot_mm": float(max(beyond.max(), 0.0) * 1e3),
        "settling_1mm_s": settling if outside.size else 0.0,
    }


def _goal_run(
    robot: str, plant: str, goal: np.ndarray, rate_hz: float, robot_state: dict, frame_id: str = "base_link", q0=None
) -> dict:
    from geometry_msgs.msg import PoseStamped

    from manip_kin.pipeline import Pipeline, pipeline_processes
    from manip_kin.ros.wire.messages import pose_stamped_to_matrix

    processes = pipeline_processes(
        robot, rate_hz=rate_hz, initial_positions=q0, robot_state={"plant": plant, **robot_state}
    )
    with Pipeline(processes, log_dir=tempfile.mkdtemp(prefix="bench_physics_")) as pipeline:
        client = pipeline.client()
        samples: list[tuple[float, np.ndarray]] = []
        client.node.create_subscription(
            PoseStamped,
            "tool_pose",
            lambda m: samples.append((time.monotonic(), pose_stamped_to_matrix(m)[:3, 3])),
            1000,
        )
        client.spin_for(1.0)
        pid = pipeline.pid("robot_state")
        cpu_start, started = _cpu_seconds(pid), time.monotonic()
        stamp = client.send_goal(goal, frame_id)
        converged, status = client.wait_converged(stamp, 25)
        client.spin_for(1.0)
        elapsed = time.monotonic() - started
        cpu = 100.0 * (_cpu_seconds(pid) - cpu_start) / elapsed
        figures = _approach_figures([s for s in samples if s[0] >= started], goal[:3, 3], started)
        return {
            "converged": converged,
            "time_to_converge_s": client.time_to_converge(stamp, started),
            **figures,
            "robot_state_cpu_percent": cpu,
        }


def tracking_rows(only_panda: bool = False) -> list[dict]:
    from manip_kin.core.kinematics import frame_pose
    from manip_kin.core.robots import load_robot
    from manip_kin.core.rotations import make_transform, rpy_to_matrix

    rows = []
    genova_goal = make_transform(rpy_to_matrix(0.0, 1.57, 0.0), [0.2, -0.7, 0.3])
    panda = load_robot(_panda_path())
    panda_q0 = PANDA_READY
    panda_goal = frame_pose(panda, panda_q0 + np.array([0.4, 0.3, 0.0, -0.4, 0.0, 0.4, 0.0]))
    for plant in PLANTS:
        search = {"mesh_search_path": _panda_mesh_search_path()} if plant == "mujoco" else {}
        run = _goal_run(_panda_path(), plant, panda_goal, 1000.0, search, panda.base_frame, PANDA_READY)
        rows.append({"metric": f"panda goal at 1 kHz, plant {plant}", **run, "target": "converged", "reference": ""})
        if only_panda:
            continue
        run = _goal_run("genova7", plant, genova_goal, 1000.0, {})
        rows.append(
            {
                "metric": f"genova7 pose goal at 1 kHz, plant {plant}",
                **run,
                "target": "converged; robot_state CPU ≤ 20 % of one core",
                "reference": "gains 0.8/0.8 1/s",
            }
        )
        line = _line_row(500.0, 0, robot_state={"plant": plant})
        line["metric"] = f"{line['metric']}, plant {plant}"
        rows.append(line)
    if not only_panda:
        rows += line_remedy_rows()
    return rows


#: What brings the line back on the physics plant (docs/physics.md): a stiffer drive, or a line
#: without velocity steps (trapezoidal, 2 m/s²) that the default drive can follow.
LINE_REMEDIES = (
    ("stiff servo 1000 1/s", {"servo_velocity_gain": 1000.0, "servo_integral_gain": 250000.0}, {}),
    ("trapezoidal 2 m/s²", {}, {"time_scaling": "trapezoidal", "max_linear_acceleration": 2.0}),
)


def line_remedy_rows() -> list[dict]:
    rows = []
    for label, robot_state, generator in LINE_REMEDIES:
        line = _line_row(500.0, 0, robot_state={"plant": "mujoco", **robot_state}, generator=generator)
        line["metric"] = f"{line['metric']}, plant mujoco, {label}"
        rows.append(line)
    return rows


def panda_rows() -> list[dict]:
    """The Panda goal alone on both plants (for a quick re-run)."""
    return tracking_rows(only_panda=True)


def run_physics_benchmarks() -> list[dict]:
    return physics_step_rows() + tracking_rows()
