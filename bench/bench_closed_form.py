"""``make bench`` section ``closedform``: closed-form IK per call, and solve_ik with and without it.

* ``closed-form solve``: the solver alone (every branch, no limits), µs per call;
* ``closed-form listing``: what ``ik --all`` does (branches, in-limit wraps, FK check of each);
* ``solve_ik``: random reachable targets from random starts, with the closed form (nearest
  solution to the start) and without (the iteration with restarts), same targets and starts.
"""

from __future__ import annotations

import numpy as np
from bench_motion import benchmark_ik

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.pose_rows import default_task
from manip_kin.core.robots import load_robot
from manip_kin.ik.closed_form import closed_form_solutions, closed_form_solver


def _arms():
    from robot_data_files import example_robot_data_urdf

    from manip_kin.core.urdf import load_urdf

    arms = [(name, load_robot(name)) for name in ("rpp", "scara", "irb120")]
    arms.append(("kinova jaco (URDF)", load_urdf(example_robot_data_urdf("kinova_description/robots/kinova.urdf"))))
    return arms


def run_closed_form_benchmarks(time_calls, repeats: int, ik_targets: int) -> list[dict]:
    """Rows for the bench table; ``time_calls(function, arguments, repeats)`` is run.py's timer."""
    rows = []
    rng = np.random.default_rng(0)
    for label, model in _arms():
        frame = model.frame_index(model.default_frame)
        task = default_task(model)
        solver = closed_form_solver(model, frame)
        targets = [frame_pose(model, model.random_configuration(rng), frame) for _ in range(500)]
        hint = np.zeros(model.dof)
        solve = time_calls(lambda target, s=solver, h=hint: s.solve(target, h), targets, repeats // 4)
        rows.append(
            {
                "metric": f"closed-form solve {label} ({solver.structure})",
                **solve,
                "target": "",
                "reference": "",
            }
        )
        listing = time_calls(
            lambda target, m=model, f=frame, t=task: closed_form_solutions(m, target, f, t), targets, repeats // 10
        )
        rows.append(
            {
                "metric": f"closed-form listing {label} (limits, wraps, FK check)",
                **listing,
                "target": "",
                "reference": "",
            }
        )
        with_closed_form = benchmark_ik(model, ik_targets, seed=0, closed_form=True)
        without = benchmark_ik(model, ik_targets, seed=0, closed_form=False)
        rows.append(
            {
                "metric": f"solve_ik {label}, {ik_targets} targets: closed form vs numeric",
                "closed_form_success": with_closed_form["success_rate"],
                "closed_form_median_ms": with_closed_form["median_ms"],
                "closed_form_p90_ms": with_closed_form["p90_ms"],
                "numeric_success": without["success_rate"],
                "numeric_median_ms": without["median_ms"],
                "numeric_p90_ms": without["p90_ms"],
                "speedup_median": without["median_ms"] / with_closed_form["median_ms"],
                "target": "",
                "reference": "",
            }
        )
    return rows
