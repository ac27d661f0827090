"""``manip_kin ik --all``: every distinct solution within the joint limits (closed form or numeric),
the ±2π wraps of revolute joints as a count per solution (``--wraps`` lists them)."""

from __future__ import annotations

import argparse

from manip_kin.cli.common import print_json
from manip_kin.core.model import RobotModel
from manip_kin.ik.all_solutions import all_ik_solutions, group_wraps


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
    groups = group_wraps(model, found.solutions)
    wrap_count = sum(len(group.wraps) for group in groups)
    if args.json:
        entries = []
        for group in groups:
            solution = group.solution
            entry = {
                "q": solution.q.tolist(),
                "branch": solution.branch,
                "position_error": solution.position_error,
                "orientation_error": solution.orientation_error,
                "wraps": len(group.wraps),
            }
            if args.wraps:
                entry["wrap_q"] = [wrap.q.tolist() for wrap in group.wraps]
            entries.append(entry)
        payload = {
            "solutions": entries,
            "solver": found.solver,
            "count": len(groups),
            "wrap_count": wrap_count,
            "task": found.task,
            "frame": frame,
            "elapsed_s": found.elapsed,
        }
        if found.reason:
            payload["reason"] = found.reason
        print_json(payload)
    else:
        wraps_text = f", and {wrap_count} ±2π wraps of them{'' if args.wraps else ' (--wraps lists them)'}"
        print(
            f"{model.name}: {len(groups)} distinct IK solution(s) within the limits for frame '{frame}'"
            f"{wraps_text if wrap_count else ''} ({found.solver}, task {found.task}, {found.elapsed * 1e3:.2f} ms)"
        )
        if found.reason:
            print(f"  reason: {found.reason}")
        for group in groups:
            solution = group.solution
            wraps = f"  +{len(group.wraps)} wrap{'s' if len(group.wraps) != 1 else ''}" if group.wraps else ""
            print(
                f"  [{_values(solution.q)}]  {solution.branch}  (errors {solution.position_error:.1e} m, "
                f"{solution.orientation_error:.1e} rad){wraps}"
            )
            for wrap in group.wraps if args.wraps else ():
                print(f"      [{_values(wrap.q)}]  {wrap.branch}")
    return 0 if found.solutions else 1


def _values(q) -> str:
    return " ".join(f"{value:9.5f}" for value in q)
