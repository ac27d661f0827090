"""Record a real collision-avoidance run and draw it: the picture in docs/collision_run.png.

Runs robot_state, cartesian_controller (collision_avoidance, the example-robot-data Panda with
its SRDF) and the recorder as processes, puts a box on ``collision_objects`` with
``manip_kin obstacle add`` between the hand and a goal 0.35 m away, sends the goal with
``manip_kin goal --wait`` (which must end ``blocked``, exit code 1, the pair in its words),
then draws the recording with ``manip_kin plot``.

    .venv/bin/python test/support/record_collision_run.py [OUT.png]

Needs ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a ``ROS_DOMAIN_ID`` of its own.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

from collision_robots import PANDA_READY, panda_files

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.urdf import load_urdf
from manip_kin.pipeline import NodeProcess, Pipeline, pipeline_processes

MANIP_KIN = str(Path(sysconfig.get_path("scripts")) / "manip_kin")


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([MANIP_KIN, *args], capture_output=True, text=True, timeout=60)


def record(out_dir: Path) -> Path:
    """Run the scene; returns the recording's path."""
    urdf, srdf, share = panda_files()
    model = load_urdf(urdf)
    hand = frame_pose(model, PANDA_READY)[:3, 3]
    recording = out_dir / "collision_run.mcap"
    controller = {
        "collision_avoidance": True,
        "srdf": str(srdf),
        "mesh_search_path": share,
        "gain_linear": 2.0,
        "gain_angular": 2.0,
        "position_tolerance": 1e-3,
    }
    processes = [NodeProcess("recorder", "recorder", {"output": str(recording)})] + pipeline_processes(
        str(urdf), rate_hz=500.0, initial_positions=PANDA_READY.tolist(), controller=controller
    )
    pipeline = Pipeline(processes).start()
    try:
        box = hand + [0.0, 0.2, 0.0]  # a wall across the way
        added = _cli("obstacle", "add", "--id", "1", "--shape", "box", "--size", "0.4", "0.06", "0.6", "--xyz",
                     *(f"{v:.4f}" for v in box), "--frame", model.base_frame)  # fmt: skip
        print(added.stdout + added.stderr, file=sys.stderr)
        goal = hand + [0.0, 0.35, 0.0]
        waited = _cli("goal", "--xyz", *(f"{v:.4f}" for v in goal), "--wait", "--timeout", "20")
        print(
            f"goal --wait: exit {waited.returncode}: {waited.stdout.strip()} {waited.stderr.strip()}", file=sys.stderr
        )
        if waited.returncode != 1 or "blocked" not in waited.stdout + waited.stderr:
            raise SystemExit(f"expected blocked with exit code 1, got {waited.returncode}")
    finally:
        codes = pipeline.stop(timeout=30.0)
        print(f"exit codes: {codes}", file=sys.stderr)
    return recording


def main() -> int:
    target = (
        Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "docs" / "collision_run.png"
    )
    with tempfile.TemporaryDirectory() as directory:
        recording = record(Path(directory))
        plots = Path(directory) / "plots"
        plotted = _cli("plot", str(recording), "--out", str(plots), "--title", "collision_run")
        print(plotted.stdout + plotted.stderr, file=sys.stderr)
        shutil.copy(plots / "collision.png", target)
    print(target)
    return 0


if __name__ == "__main__":
    sys.exit(main())
