"""``manip_kin ik --all``: every solution within the joint limits, closed form or numeric."""

from __future__ import annotations

import argparse

from manip_kin.cli.common import print_json
from manip_kin.ik_all import all_ik_solutions
from manip_kin.model import RobotModel


def run_ik_all(args: argparse.Namespace, model: RobotModel, target, q0, task: str | None) -> int:
    """List the solutions (exit 0), or say why there is none (exit 1)."""
    found = all_ik_solutions(
        model,
        target,
        q0,
        frame=args.frame,
        task=task,
        solver=args.solver,
        tolerance_position=args.tolerance_position,
        tolerance_orientation=args.tolerance_orientation,
        restarts=args.restarts,
        time_budget=args.time_budget,
        seed=args.seed,
    )
    frame = model.frame_name(model.frame_index(args.frame or model.default_frame))
    if args.json:
        payload = {
            "solutions": [
                {
                    "q": solution.q.tolist(),
                    "branch": solution.branch,
                    "position_error": solution.position_error,
                    "orientation_error": solution.orientation_error,
                }
                for solution in found.solutions
            ],
            "solver": found.solver,
            "count": len(found.solutions),
            "task": found.task,
            "frame": frame,
            "elapsed_s": found.elapsed,
        }
        if found.reason:
            payload["reason"] = found.reason
        print_json(payload)
    else:
        print(
            f"{model.name}: {len(found.solutions)} IK solution(s) within the limits for frame '{frame}' "
            f"({found.solver}, task {found.task}, {found.elapsed * 1e3:.2f} ms)"
        )
        if found.reason:
            print(f"  reason: {found.reason}")
        for solution in found.solutions:
            q = " ".join(f"{value:9.5f}" for value in solution.q)
            print(
                f"  [{q}]  {solution.branch}  (errors {solution.position_error:.1e} m, "
                f"{solution.orientation_error:.1e} rad)"
            )
    return 0 if found.solutions else 1
