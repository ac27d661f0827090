#!/usr/bin/env python3
"""``make bench-anchors``: manip_kin side by side with pinocchio and robotics-toolbox-python.

Runs in its own venv (``.venv-anchors``, see ``bench/requirements-anchors.txt``); the package
never depends on these libraries. For each robot (genova7, exported to URDF by
:func:`manip_kin.core.urdf.model_to_urdf`; the Franka Panda URDF of example-robot-data, tip
``panda_hand``) every library gets the same random configurations, goals and IK targets,
and the libraries are interleaved block by block in every round, so that the machine's
drift hits all of them alike. Before anything is timed, every library's FK and Jacobian is
checked against manip_kin's at random configurations.

What is timed (per call, Python caller, numpy arrays in and out):

* ``fk``: the pose of the tip frame as a 4x4 array. pinocchio: ``forwardKinematics`` +
  ``updateFramePlacement``; rtb: ``ETS.eval``.
* ``fk_jacobian``: pose and geometric Jacobian. pinocchio: ``computeFrameJacobian``
  (LOCAL_WORLD_ALIGNED) + the frame placement; rtb: ``ETS.eval`` + ``ETS.jacob0``.
* ``control_step``: FK + Jacobian + pose error + a solve for the joint rates. manip_kin: the
  full :meth:`CartesianController.step` (damping near singularities, position and velocity
  limits, a ControlOutput). The anchor is the lightest such step one writes with pinocchio:
  ``computeFrameJacobian``, ``log3`` of ``R_goal Rᵀ``, ``Jᵀ np.linalg.solve(J Jᵀ, K e)`` —
  no damping, no limits.
* ``ik``: random reachable targets (the tip pose of random configurations), each from a random
  initial guess, same targets and guesses for both. manip_kin :func:`solve_ik` (defaults);
  rtb ``ETS.ik_LM`` (C++, Chan's damping, 30 iterations x 100 searches, joint limits) with
  ``tol`` set so that it stops at the same residual (|e| < 1e-6). Success is checked for both
  with manip_kin's FK: position < 1e-5 m, orientation < 1e-4 rad, within the limits.
* ``batched_fk``: 100k configurations. manip_kin ``batch_frame_pose``; rtb ``ETS.fkine`` on the
  (N, n) array; pinocchio a Python loop (it has no batched FK in Python).

Times are CPU time of this process (``time.process_time_ns``), per call, summed over blocks
of calls; wall time on a loaded shared machine mostly measures waiting for a core. Ratios are
manip_kin / anchor per round (< 1: manip_kin faster; for batched FK the ratio is of times
too); the table shows the median over rounds and the range.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "test" / "support"))  # robot_data_files: the example-robot-data URDFs


# --- the robots in each library ---------------------------------------------------------------


class Setup:
    """One robot in manip_kin, pinocchio and rtb, with the same tip frame."""

    def __init__(self, label: str, model, urdf_path: str, tip: str, frame: str):
        import pinocchio as pin
        import roboticstoolbox as rtb

        self.label = label
        self.model = model
        self.frame_index = model.frame_index(frame)
        full = pin.buildModelFromUrdf(urdf_path)
        keep = {full.getJointId(name) for name in model.joint_names}
        lock = [j for j in range(1, full.njoints) if j not in keep]
        self.pin_model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        self.pin_data = self.pin_model.createData()
        self.pin_frame = self.pin_model.getFrameId(tip)
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            robot = rtb.Robot.URDF(urdf_path)
        self.ets = robot.ets(end=tip)
        if self.pin_model.nq != model.dof or self.ets.n != model.dof:
            raise SystemExit(f"{label}: joint counts differ (pinocchio {self.pin_model.nq}, rtb {self.ets.n})")


def _stripped_urdf(path: Path, directory: str) -> str:
    """The URDF without visuals and collisions (rtb would resolve their mesh packages)."""
    tree = ET.parse(path)
    for link in tree.getroot().iter("link"):
        for child in list(link):
            if child.tag in ("visual", "collision"):
                link.remove(child)
    out = Path(directory) / path.name
    tree.write(out)
    return str(out)


def setups(directory: str) -> list[Setup]:
    from robot_data_files import example_robot_data_urdf

    from manip_kin.core.robots import load_robot
    from manip_kin.core.urdf import load_urdf, model_to_urdf

    genova = load_robot("genova7")
    genova_path = Path(directory) / "genova7.urdf"
    genova_path.write_text(model_to_urdf(genova))
    panda_source = example_robot_data_urdf("panda_description/urdf/panda.urdf")
    panda = load_urdf(panda_source, tip_link="panda_hand")
    return [
        Setup("genova7", genova, str(genova_path), "tool", genova.default_frame),
        Setup("panda (URDF)", panda, _stripped_urdf(panda_source, directory), "panda_hand", panda.default_frame),
    ]


# --- the timed functions ------------------------------------------------------------------------


def functions(setup: Setup) -> dict[str, dict]:
    import pinocchio as pin

    from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
    from manip_kin.core.kinematics import pose_and_jacobian_in_base, pose_in_base

    model, frame = setup.model, setup.frame_index
    pm, pd, fid, ets = setup.pin_model, setup.pin_data, setup.pin_frame, setup.ets
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    config = ControllerConfig()
    controller = CartesianController(model, config)
    gain_angular, gain_linear = config.gain_angular, config.gain_linear

    def pin_fk(q):
        pin.forwardKinematics(pm, pd, q)
        return pin.updateFramePlacement(pm, pd, fid).homogeneous

    def pin_fk_jacobian(q):
        jacobian = pin.computeFrameJacobian(pm, pd, q, fid, lwa)
        return pd.oMf[fid].homogeneous, jacobian

    def rtb_fk_jacobian(q):
        return ets.eval(q), ets.jacob0(q)

    def pin_step(case):
        q, goal = case
        jacobian = pin.computeFrameJacobian(pm, pd, q, fid, lwa)  # rows [v; ω]
        pose = pd.oMf[fid]
        error = np.concatenate(
            [gain_linear * (goal[:3, 3] - pose.translation), gain_angular * pin.log3(goal[:3, :3] @ pose.rotation.T)]
        )
        return jacobian.T @ np.linalg.solve(jacobian @ jacobian.T, error)

    def ours_step(case):
        return controller.step(case[0], case[1], None, 0.002)

    return {
        "fk": {
            "manip_kin": lambda q: pose_in_base(model, q, frame),
            "pinocchio": pin_fk,
            "rtb": ets.eval,
        },
        "fk_jacobian": {
            "manip_kin": lambda q: pose_and_jacobian_in_base(model, q, frame),
            "pinocchio": pin_fk_jacobian,
            "rtb": rtb_fk_jacobian,
        },
        "control_step": {"manip_kin": ours_step, "pinocchio": pin_step},
    }


def check_agreement(setup: Setup, configurations) -> float:
    """Largest difference of the other libraries' FK and Jacobian from manip_kin's; exits if > 1e-9."""
    from manip_kin.core.kinematics import pose_and_jacobian_in_base

    timed = functions(setup)["fk_jacobian"]
    worst = 0.0
    for q in configurations[:200]:
        pose, jacobian = pose_and_jacobian_in_base(setup.model, q, setup.frame_index)
        for name in ("pinocchio", "rtb"):
            other_pose, other_jacobian = timed[name](q)
            # both anchors order the rows [v; ω]; manip_kin [ω; v]
            reordered = np.vstack([other_jacobian[3:], other_jacobian[:3]])
            difference = max(np.abs(other_pose - pose).max(), np.abs(reordered - jacobian).max())
            fk_only = np.abs(functions(setup)["fk"][name](q) - pose).max()
            worst = max(worst, difference, fk_only)
    if worst > 1e-9:
        raise SystemExit(f"{setup.label}: the libraries disagree on FK/Jacobian by {worst:.3g}; not timing")
    return worst


# --- interleaved timing -------------------------------------------------------------------------


def interleaved(candidates: dict, arguments: list, rounds: int, block: int) -> dict[str, list[float]]:
    """Per-call times [µs], one per round, each library timing ``block`` calls in turn.

    The clock is this process's CPU time: on a shared machine wall time mostly measures how
    long the process waited for a core, which is nobody's speed.
    """
    clock = time.process_time_ns
    names = list(candidates)
    for name in names:  # warm-up
        for argument in arguments[:100]:
            candidates[name](argument)
    times = {name: [] for name in names}
    for round_index in range(rounds):
        order = names[round_index % len(names) :] + names[: round_index % len(names)]
        sums = dict.fromkeys(names, 0)
        for start in range(0, len(arguments), block):
            chunk = arguments[start : start + block]
            for name in order:
                function = candidates[name]
                begin = clock()
                for argument in chunk:
                    function(argument)
                sums[name] += clock() - begin
            order.reverse()  # alternate who goes first within the round too
        for name in names:
            times[name].append(sums[name] / len(arguments) / 1e3)
    return times


def summarize(metric: str, label: str, times: dict[str, list[float]], unit: str = "us") -> dict:
    row = {"metric": f"{metric} {label}", "unit": unit}
    ours = np.array(times["manip_kin"])
    for name, values in times.items():
        values = np.array(values)
        row[name] = {"median": float(np.median(values)), "min": float(values.min()), "max": float(values.max())}
        if name != "manip_kin":
            ratios = ours / values
            row[f"ratio_vs_{name}"] = {
                "median": float(np.median(ratios)),
                "min": float(ratios.min()),
                "max": float(ratios.max()),
            }
    return row


def singular_versus_regular(setup: Setup, step, cases: list, rounds: int) -> dict:
    """manip_kin's control step near a singularity (σ_min < ε, damped) against a regular one.

    The same cases as ``control_step``, split by the step's own ``singular`` flag; both kinds
    timed in alternating blocks (CPU time), the ratio per round.
    """
    kinds = {"regular": [], "singular": []}
    for case in cases:
        kinds["singular" if step(case).singular else "regular"].append(case)
    count = min(len(kinds["regular"]), len(kinds["singular"]))
    if count == 0:
        return {"metric": f"singular / regular control step {setup.label}", "note": "no singular case drawn"}
    clock = time.process_time_ns
    times = {"regular": [], "singular": []}
    for _ in range(rounds):
        sums = dict.fromkeys(times, 0)
        for start in range(0, max(len(kinds["regular"]), len(kinds["singular"])), 100):
            for kind, chosen in kinds.items():
                chunk = [chosen[(start + i) % len(chosen)] for i in range(100)]  # 100 calls each
                begin = clock()
                for case in chunk:
                    step(case)
                sums[kind] += (clock() - begin) / max(len(chunk), 1)
        for kind in times:
            times[kind].append(sums[kind])
    ratios = np.array(times["singular"]) / np.array(times["regular"])
    blocks = -(-max(len(kinds["regular"]), len(kinds["singular"])) // 100)
    row = {"metric": f"singular / regular control step {setup.label}", "unit": "us"}
    for kind in times:
        values = np.array(times[kind]) / blocks / 1e3  # ns summed over blocks -> µs per call
        row[kind] = {"median": float(np.median(values)), "min": float(values.min()), "max": float(values.max())}
    row["singular_fraction"] = len(kinds["singular"]) / len(cases)
    row["ratio_singular_to_regular"] = {
        "median": float(np.median(ratios)),
        "min": float(ratios.min()),
        "max": float(ratios.max()),
    }
    return row


def bench_ik(setup: Setup, n_targets: int, rounds: int, seed: int) -> dict:
    from manip_kin.control.resolved_rate import pose_error
    from manip_kin.core.kinematics import frame_pose
    from manip_kin.ik.iterative import solve_ik

    model = setup.model
    rng = np.random.default_rng(seed)
    frame = model.frame_name(setup.frame_index)
    targets = [frame_pose(model, model.random_configuration(rng), frame) for _ in range(n_targets)]
    guesses = [model.random_configuration(rng) for _ in range(n_targets)]
    ets = setup.ets

    def ours(index):
        return solve_ik(model, targets[index], guesses[index], frame=frame, seed=seed + index).q

    def rtb(index):
        # E = ½|e|² < tol: tol 5e-13 stops at |e| < 1e-6 like solve_ik's tolerances.
        return np.asarray(ets.ik_LM(targets[index], q0=guesses[index], tol=5e-13).q, dtype=float)

    def succeeded(q, target) -> bool:
        if not model.within_limits(q, 1e-9):
            return False
        orientation, position = pose_error(frame_pose(model, q, frame), target)
        return bool(np.linalg.norm(position) < 1e-5 and np.linalg.norm(orientation) < 1e-4)

    candidates = {"manip_kin": ours, "rtb": rtb}
    ours_results = [solve_ik(model, targets[i], guesses[i], frame=frame, seed=seed + i) for i in range(n_targets)]
    successes = {
        "manip_kin": sum(succeeded(result.q, targets[i]) for i, result in enumerate(ours_results)),
        "rtb": sum(succeeded(rtb(i), targets[i]) for i in range(n_targets)),
    }
    for index, result in enumerate(ours_results):  # why (e.g. the time budget on a loaded machine)
        if not succeeded(result.q, targets[index]):
            print(f"[anchors] {setup.label}: IK target {index} failed: {result.reason}", file=sys.stderr)
    times = interleaved(candidates, list(range(n_targets)), rounds, block=50)
    row = summarize("IK mean per target", f"{setup.label}, {n_targets} random targets", times)
    for name in candidates:
        row[name]["success_rate"] = successes[name] / n_targets
    return row


def bench_batched(setup: Setup, count: int, rounds: int, seed: int) -> dict:
    import pinocchio as pin

    from manip_kin.core.kinematics import batch_frame_pose

    model = setup.model
    rng = np.random.default_rng(seed)
    batch = np.array([model.random_configuration(rng) for _ in range(count)])
    frame = model.frame_name(setup.frame_index)
    check = batch_frame_pose(model, batch[:50], frame)
    other = setup.ets.fkine(batch[:50])
    if np.abs(np.array([t.A for t in other]) - check).max() > 1e-9:
        raise SystemExit(f"{setup.label}: batched FK disagrees with rtb")
    pm, pd, fid = setup.pin_model, setup.pin_data, setup.pin_frame

    def pin_loop(configurations):
        out = np.empty((len(configurations), 4, 4))
        for i, q in enumerate(configurations):
            pin.forwardKinematics(pm, pd, q)
            out[i] = pin.updateFramePlacement(pm, pd, fid).homogeneous
        return out

    candidates = {
        "manip_kin": lambda _: batch_frame_pose(model, batch, frame),
        "pinocchio": lambda _: pin_loop(batch),
        "rtb": lambda _: setup.ets.fkine(batch),
    }
    times = interleaved(candidates, [None], rounds, block=1)
    # per-configuration time in µs; the table also shows configurations per second
    per_config = {name: [t / count for t in values] for name, values in times.items()}
    row = summarize("batched FK", f"{setup.label}, {count // 1000}k configurations", per_config)
    for name in candidates:
        row[name]["configs_per_s"] = 1e6 / row[name]["median"]
    return row


def print_table(rows: list[dict]) -> None:
    width = max(len(row["metric"]) for row in rows)
    print(f"{'metric':<{width}}  {'manip_kin':>22}  {'pinocchio':>22}  {'rtb':>22}  ratios (median [min, max])")
    for row in rows:
        if "regular" in row:
            ratio = row["ratio_singular_to_regular"]
            print(
                f"{row['metric']:<{width}}  regular {row['regular']['median']:.3g} µs, singular "
                f"{row['singular']['median']:.3g} µs ({100 * row['singular_fraction']:.1f} % of the steps): "
                f"ratio {ratio['median']:.2f} [{ratio['min']:.2f}, {ratio['max']:.2f}]"
            )
            continue
        if "manip_kin" not in row:
            print(f"{row['metric']:<{width}}  {row.get('note', '')}")
            continue
        cells = []
        for name in ("manip_kin", "pinocchio", "rtb"):
            if name not in row:
                cells.append(f"{'-':>22}")
                continue
            value = row[name]
            text = f"{value['median']:.3g} µs [{value['min']:.3g}-{value['max']:.3g}]"
            if "success_rate" in value:
                text = f"{value['median'] / 1e3:.3g} ms {100 * value['success_rate']:.2f}%"
            cells.append(f"{text:>22}")
        ratios = ", ".join(
            f"vs {key[len('ratio_vs_') :]} {value['median']:.2f} [{value['min']:.2f}, {value['max']:.2f}]"
            for key, value in row.items()
            if key.startswith("ratio_vs_")
        )
        print(f"{row['metric']:<{width}}  {'  '.join(cells)}  {ratios}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "anchors.json", help="JSON output path")
    parser.add_argument("--rounds", type=int, default=7, help="interleaved rounds per measurement")
    parser.add_argument("--configurations", type=int, default=2000, help="configurations per FK/step round")
    parser.add_argument("--ik-targets", type=int, default=2000, help="random IK targets per robot")
    parser.add_argument("--ik-rounds", type=int, default=3, help="interleaved rounds of the IK")
    parser.add_argument("--batch", type=int, default=100_000, help="configurations of the batched FK")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--only", choices=("all", "ik"), default="all", help="ik: only the IK rows (while working on the IK)"
    )
    args = parser.parse_args()
    try:
        import pinocchio
        import roboticstoolbox
    except ImportError as error:
        print(f"bench-anchors needs pinocchio (pin) and roboticstoolbox-python: {error}", file=sys.stderr)
        return 2
    from manip_kin.core.kinematics import frame_pose
    from manip_kin.core.rotations import angle_axis_to_matrix, make_transform

    rows = []
    with tempfile.TemporaryDirectory(prefix="manip_kin_anchors_") as directory:
        for setup in setups(directory):
            model = setup.model
            rng = np.random.default_rng(args.seed)
            configurations = [model.random_configuration(rng, margin=0.05) for _ in range(args.configurations)]
            worst = check_agreement(setup, configurations)
            print(f"[anchors] {setup.label}: FK and Jacobian agree within {worst:.2g}", file=sys.stderr)
            if args.only == "ik":
                rows.append(bench_ik(setup, args.ik_targets, args.ik_rounds, args.seed))
                continue
            timed = functions(setup)
            for metric in ("fk", "fk_jacobian"):
                times = interleaved(timed[metric], configurations, args.rounds, block=200)
                rows.append(summarize(metric, setup.label, times))
            frame = model.frame_name(setup.frame_index)
            cases = []
            for q in configurations:
                pose = frame_pose(model, q, frame)
                rotation = angle_axis_to_matrix(rng.uniform(0.0, 0.1), rng.normal(size=3)) @ pose[:3, :3]
                cases.append((q, make_transform(rotation, pose[:3, 3] + rng.normal(scale=0.03, size=3))))
            times = interleaved(timed["control_step"], cases, args.rounds, block=200)
            rows.append(summarize("control_step", setup.label, times))
            rows.append(singular_versus_regular(setup, timed["control_step"]["manip_kin"], cases, args.rounds))
            print(f"[anchors] {setup.label}: IK ...", file=sys.stderr, flush=True)
            rows.append(bench_ik(setup, args.ik_targets, args.ik_rounds, args.seed))
            rows.append(bench_batched(setup, args.batch, max(3, args.rounds // 2), args.seed))
    print_table(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "numpy": np.__version__},
        "versions": {"pinocchio": pinocchio.__version__, "roboticstoolbox": roboticstoolbox.__version__},
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "results": rows,
    }
    args.out.write_text(json.dumps(payload, indent=2) + "\n")
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
