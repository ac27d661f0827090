"""irb120 scenario (b) through the launch-free pipeline: a constant-speed line, and one out of reach.

Its own module so that its pipeline never shares the machine with test_pipeline.py's.
"""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped

from manip_kin.nodes import conversions as conv
from manip_kin.pipeline import Pipeline, fresh_domain_env, pipeline_processes
from manip_kin.rotations import make_transform, rpy_to_matrix
from manip_kin.trajectory import distance_to_segment

MANIP_KIN = str(Path(sys.executable).parent / "manip_kin")
DOWN = rpy_to_matrix(0.0, math.pi / 2, 0.0)


def run_cli(pipeline, *args, timeout=60):
    return subprocess.run([MANIP_KIN, *args], env=pipeline.env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def irb120(tmp_path_factory):
    """irb120 from q = 0, constant-speed lines at 0.4 m/s (scenario (b))."""
    processes = pipeline_processes(
        "irb120",
        initial_positions=[0.0] * 6,
        controller={"gain_linear": 6.0, "gain_angular": 6.0},
        generator={"time_scaling": "constant", "max_linear_velocity": 0.4, "max_angular_velocity": 1.0},
        # Tracking accuracy depends on the loops running on time; other jobs share these cores.
        realtime_priority=10,
    )
    pipeline = Pipeline(processes, env=fresh_domain_env(), log_dir=tmp_path_factory.mktemp("irb120_logs"))
    pipeline.start()
    yield pipeline
    pipeline.stop()


def test_irb120_line_tracked_along_the_segment(irb120):
    start, end = [0.4, 0.1, 0.6], [-0.4, 0.3, 0.5]
    first = run_cli(
        irb120, "goal", "--xyz", *map(str, start), "--rpy", "0", str(math.pi / 2), "0", "--wait", "--timeout", "30"
    )
    assert first.returncode == 0, first.stderr
    client = irb120.client()
    samples = []
    client.node.create_subscription(
        PoseStamped, "/tool_pose", lambda m: samples.append(conv.pose_stamped_to_matrix(m)), 1000
    )
    client.spin_for(0.2)
    target = client.send_line(make_transform(DOWN, end))
    done = client.wait_line_done(target, 15)
    assert done.message == "holding", done.values
    assert abs(done.number("duration") - np.linalg.norm(np.subtract(end, start)) / 0.4) < 0.02
    converged, status = client.wait_converged(done.values["final_goal_stamp"], 15)
    assert converged, status.values if status else None
    poses = np.array(samples)
    deviation = distance_to_segment(poses[:, :3, 3], start, end)
    assert len(poses) > 500
    # 500 Hz pipeline on a shared machine in tests; the 1 kHz figure (target 0.5 mm) is in bench_nodes.
    # (bound for a loaded 2-core CI machine: dropping the feed-forward or a bent path gives cm)
    assert deviation.max() < 4e-3, deviation.max()
    np.testing.assert_allclose(poses[-1][:3, 3], end, atol=2e-4)
    # Orientation held pointing down all along.
    assert max(np.abs(p[:3, :3] - DOWN).max() for p in poses) < 0.02


def test_irb120_line_out_of_reach_rejected_by_cli(irb120):
    result = run_cli(
        irb120, "line", "--xyz", "1.2", "0.0", "0.5", "--rpy", "0", str(math.pi / 2), "0", "--wait", "--timeout", "10"
    )
    assert result.returncode == 2
    assert "target rejected" in result.stderr and "reach" in result.stderr
