"""irb120 scenario (b) through the launch-free pipeline: a constant-speed line, and one out of reach.

Its own module so that its pipeline never shares the machine with test_pipeline.py's.
"""

import math
import os
import subprocess
import sysconfig
import time
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from pipeline_checks import (
    fast_dds_receive_threads,
    loops_lateness_s,
    realtime_measurement,
    realtime_scheduling_error,
    stop_checked,
)

from manip_kin.core.rotations import make_transform, rpy_to_matrix
from manip_kin.motion.lines import distance_to_segment
from manip_kin.pipeline import IRB120_LINE_GENERATOR, Pipeline, fresh_domain_env, pipeline_processes
from manip_kin.ros.wire.messages import pose_stamped_to_matrix

MANIP_KIN = str(Path(sysconfig.get_path("scripts")) / "manip_kin")
# Tracking accuracy depends on the loops running on time and other jobs share these cores:
# SCHED_FIFO where this machine permits it (CAP_SYS_NICE or an RLIMIT_RTPRIO), else normal
# scheduling, said in the test output. The bounds below hold either way (measured under load).
REALTIME_ERROR = realtime_scheduling_error(10)
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
        generator=IRB120_LINE_GENERATOR,
        realtime_priority=0 if REALTIME_ERROR else 10,
    )
    if REALTIME_ERROR:
        print(f"irb120 pipeline at normal scheduling: {REALTIME_ERROR}")
    pipeline = Pipeline(processes, env=fresh_domain_env(), log_dir=tmp_path_factory.mktemp("irb120_logs"))
    pipeline.start()
    yield pipeline
    stop_checked(pipeline)


def test_realtime_priority_is_applied_where_permitted(irb120):
    """Each node's loop thread really runs SCHED_FIFO 10 (read from the kernel, not from a log),
    and so do the middleware's receive threads it waits on and its executor (main) thread."""
    if REALTIME_ERROR:
        pytest.skip(f"this machine refuses SCHED_FIFO ({REALTIME_ERROR}); the pipeline ran at normal scheduling")
    for name in ("robot_state", "cartesian_controller", "trajectory_generator"):
        pid = irb120.pid(name)
        threads = {}
        for task in Path(f"/proc/{pid}/task").iterdir():
            scheduling = os.sched_getscheduler(int(task.name)), os.sched_getparam(int(task.name)).sched_priority
            threads[int(task.name)] = ((task / "comm").read_text().strip(), scheduling)
        receive = [threads[thread_id][1] for thread_id in fast_dds_receive_threads(pid)]
        assert len(receive) >= 2 and set(receive) == {(os.SCHED_FIFO, 10)}, (name, threads)
        assert threads[pid][1] == (os.SCHED_FIFO, 10), (name, threads)  # the main thread: the executor
        at_priority = sum(scheduling == (os.SCHED_FIFO, 10) for _, scheduling in threads.values())
        assert at_priority >= 2 + len(receive), (name, threads)  # with the loop thread


def test_irb120_line_tracked_along_the_segment(irb120):
    start, end = [0.4, 0.1, 0.6], [-0.4, 0.3, 0.5]
    first = run_cli(
        irb120, "goal", "--xyz", *map(str, start), "--rpy", "0", str(math.pi / 2), "0", "--wait", "--timeout", "30"
    )
    assert first.returncode == 0, first.stderr
    client = irb120.client()
    # Matched now, while the line has not begun: a reader first created for the settle check
    # at the end was once not matched within 5 s beside the SCHED_FIFO nodes.
    client.watch_state()
    samples = []
    subscription = client.node.create_subscription(
        PoseStamped,
        "/tool_pose",
        lambda m: samples.append(pose_stamped_to_matrix(m)),
        # Deep: send_line waits for the acknowledgement (a DDS heartbeat: 20 ms for this client,
        # seconds at Fast DDS's default) while 500 poses a second queue up; a 1000-deep queue
        # lost the line's start.
        20000,
    )
    try:
        with realtime_measurement():
            poses = _check_the_line(irb120, client, samples, start, end)
    finally:
        # Left on the shared client, its queue filled while later tests ran their CLI, and
        # draining thousands of poses held off the next test's fresh tool_pose past 5 s.
        client.node.destroy_subscription(subscription)
    # Converged: the tool is on the end point (fresh poses: the samples above can lag behind).
    _assert_settles_on(client, end)
    # Orientation held pointing down all along.
    assert max(np.abs(p[:3, :3] - DOWN).max() for p in poses) < 0.02


def _check_the_line(irb120, client, samples, start, end):
    # The subscription is matched before the line starts: a sample arrives.
    assert client.spin_until(lambda: samples, 10), "no /tool_pose"
    samples.clear()
    target = client.send_line(make_transform(DOWN, end))
    done = client.wait_line_done(target, 15)
    assert done.message == "holding", done.values
    # The trapezoid: the line at its speed, plus one ramp's time (v/a).
    speed, acceleration = IRB120_LINE_GENERATOR["max_linear_velocity"], IRB120_LINE_GENERATOR["max_linear_acceleration"]
    expected = np.linalg.norm(np.subtract(end, start)) / speed + speed / acceleration
    assert abs(done.number("duration") - expected) < 0.02
    converged, status = client.wait_converged(done.values["final_goal_stamp"], 15)
    assert converged, status.values if status else None
    # The statuses can be handled ahead of a backlog of queued poses (one callback per spin):
    # take the queued poses until one at the end point has been handled. (A wait, not a bound:
    # beside the SCHED_FIFO nodes this client had not taken its queue to the end in 20 s once.)
    assert client.spin_until(lambda: np.linalg.norm(samples[-1][:3, 3] - end) < 5e-4, 60), samples[-1][:3, 3]
    poses = np.array(samples)
    deviation = distance_to_segment(poses[:, :3, 3], start, end)
    # The samples cover the whole segment: tool positions in each tenth of it. (Not a count:
    # that is the loop rate, which a loaded machine lowers.)
    direction = np.subtract(end, start) / np.linalg.norm(np.subtract(end, start))
    along = (poses[:, :3, 3] - start) @ direction / np.linalg.norm(np.subtract(end, start))
    covered = np.unique(np.clip((along * 10).astype(int), 0, 9))
    assert covered.tolist() == list(range(10)), along
    # Cross-track deviation. On time (bench_nodes, 1 kHz) it is ~0.5 mm; this 500 Hz pipeline
    # on a loaded 2-core machine measured up to 4.2 mm even at SCHED_FIFO (the loops run on time,
    # DDS delivery between the three processes does not). 6 mm still fails what the test is for:
    # a path bent by joint-space interpolation or a missing feed-forward gives centimetres.
    # A loop that ran late (no SCHED_FIFO) carries the previous command on for that long: its
    # worst lateness times the line speed is added, read from the nodes' own loop statistics.
    lateness_s = loops_lateness_s(client)
    bound = 6e-3 + 0.4 * lateness_s
    assert deviation.max() < bound, (deviation.max(), bound, REALTIME_ERROR or "SCHED_FIFO")
    return poses


def test_irb120_line_out_of_reach_rejected_by_cli(irb120):
    result = run_cli(
        irb120, "line", "--xyz", "1.2", "0.0", "0.5", "--rpy", "0", str(math.pi / 2), "0", "--wait", "--timeout", "10"
    )
    # A valid target the arm cannot follow: not achieved (1), with where the line leaves the reach.
    assert result.returncode == 1, result.stderr
    assert "target rejected" in result.stderr and "leaves the arm's reach at" in result.stderr


def test_cli_line_wait_succeeds_and_ends_on_the_target(irb120):
    end = [0.35, -0.15, 0.55]
    result = run_cli(
        irb120, "line", "--xyz", *map(str, end), "--rpy", "0", str(math.pi / 2), "0", "--wait", "--timeout", "30"
    )
    assert result.returncode == 0, result.stderr + result.stdout
    tool = _assert_settles_on(irb120.client(), end)
    np.testing.assert_allclose(tool[:3, :3], DOWN, atol=2e-3)


def _assert_settles_on(client, end, atol=2e-4, timeout=3.0):
    """The tool settles within ``atol`` [m] of ``end`` within ``timeout`` s of fresh poses and
    stays there; returns the last pose. Convergence is judged on the controller's estimate of
    a state a few ms old; under load the tool was once 0.26 mm off in the first pose taken
    after it (not traced further), and the controller holding the goal takes it onto the end."""
    deadline = time.monotonic() + timeout
    while np.abs((tool := client.current_tool_pose())[:3, 3] - end).max() >= atol and time.monotonic() < deadline:
        client.spin_for(0.02)
    np.testing.assert_allclose(tool[:3, 3], end, atol=atol)
    client.spin_for(0.2)
    np.testing.assert_allclose(client.current_tool_pose()[:3, 3], end, atol=atol)  # held there
    return tool
