"""irb120 scenario (b) as posed: position only, orientation free, at 500 Hz.

From q = 0 the end effector goes to [0.4, 0.1, 0.6], then along a straight line to
[-0.4, 0.3, 0.5] at a constant 0.4 m/s. Controller and generator run with task:=position:
the generator checks the reach over the position only (the full-pose check refuses this
line part way) and the controller's convergence ignores the orientation.
"""

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from pipeline_checks import loops_lateness_s, realtime_measurement

from manip_kin.motion.lines import distance_to_segment
from manip_kin.pipeline import IRB120_LINE_GENERATOR, Pipeline, fresh_domain_env, pipeline_processes
from manip_kin.ros.wire.messages import stamp_key_to_ns, stamp_to_ns

MANIP_KIN = str(Path(sys.executable).parent / "manip_kin")
START, END = np.array([0.4, 0.1, 0.6]), np.array([-0.4, 0.3, 0.5])
SPEED = 0.4


@pytest.fixture(scope="module")
def irb120(tmp_path_factory):
    processes = pipeline_processes(
        "irb120",
        rate_hz=500.0,
        initial_positions=[0.0] * 6,
        controller={"task": "position", "gain_linear": 6.0, "gain_angular": 6.0},
        generator={**IRB120_LINE_GENERATOR, "task": "position", "max_linear_velocity": SPEED},
        realtime_priority=10,
    )
    pipeline = Pipeline(processes, env=fresh_domain_env(), log_dir=tmp_path_factory.mktemp("irb120_position_logs"))
    pipeline.start()
    yield pipeline
    codes = pipeline.stop()
    assert all(code == 0 for code in codes.values()), codes


def run_cli(pipeline, *args, timeout=60):
    return subprocess.run([MANIP_KIN, *args], env=pipeline.env, capture_output=True, text=True, timeout=timeout)


def test_position_only_line_at_constant_speed(irb120):
    # Position-only goal (--xyz alone): converged counts the position only.
    first = run_cli(irb120, "goal", "--xyz", *map(str, START), "--wait", "--json", "--timeout", "30")
    assert first.returncode == 0, first.stderr
    report = json.loads(first.stdout)
    assert report["position_only"] and report["converged"] and report["final_error"]["position"] <= 1e-4
    client = irb120.client()
    samples = []
    # Deep: a loaded client can fall seconds behind 500 poses a second.
    subscription = client.node.create_subscription(PoseStamped, "tool_pose", samples.append, 20000)
    with realtime_measurement():
        client.spin_for(0.2)
        line = subprocess.Popen(
            [MANIP_KIN, "line", "--xyz", *map(str, END), "--wait", "--json", "--timeout", "30"],
            env=irb120.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        client.spin_until(lambda: line.poll() is not None, 60)
        stdout, stderr = line.communicate(timeout=5)
        # The client takes one message a spin: under load its queue still holds the line's end
        # when the CLI is done (the last pose taken was once 13 cm short). Take it up to there.
        client.spin_until(lambda: samples and np.linalg.norm(_xyz(samples[-1]) - END) < 2e-4, 60)
    client.node.destroy_subscription(subscription)
    assert line.returncode == 0, stderr
    report = json.loads(stdout)
    length = float(np.linalg.norm(END - START))
    assert report["position_only"] and report["converged"]
    assert report["line_duration"] == pytest.approx(
        length / SPEED + SPEED / IRB120_LINE_GENERATOR["max_linear_acceleration"], abs=1e-3
    )
    # The time reported runs from the target's stamp to the stamp of the controller's first
    # status that said converged (this client has it too): not until the CLI got round to it,
    # nor until it heard it (a starved CLI heard it 0.47 s after this client; at Fast DDS's
    # default 3 s heartbeat the report once said 3.07 s for this 2.08 s line).
    final_stamp = client.wait_status("trajectory_generator").values["final_goal_stamp"]
    converged, first = client.wait_converged(final_stamp, 5)
    assert converged and first.stamp_ns, first
    said = (first.stamp_ns - stamp_key_to_ns(report["stamp"])) * 1e-9
    assert report["time"] == pytest.approx(said, abs=1e-6), (report["time"], said)
    # That status was heard after it went out (this client's receive time, its own clock).
    sent_ago = time.time() - stamp_key_to_ns(report["stamp"]) * 1e-9
    heard = (first.received_ns - time.monotonic_ns()) * 1e-9 + sent_ago
    assert said <= heard + 0.01, (said, heard)
    # When the line's last sample went out and when the arm settled, both from the line's start
    # (the generator's and the controller's own times): the tail after the line is apart.
    assert report["motion_time"] == pytest.approx(report["line_duration"], abs=0.05), report
    assert report["motion_time"] < report["settle_time"] <= report["time"], report
    assert report["settle_tolerance"] == "0.0001 m"  # task position: the orientation is free
    stamps_ns = np.array([stamp_to_ns(m.header.stamp) for m in samples])
    stamps = (stamps_ns - stamps_ns[0]) * 1e-9  # integer ns first: 1e9 s in float is ±0.2 µs
    positions = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for m in samples])
    progress = (positions - START) @ (END - START) / length  # distance along the line [m]
    # The cruise at SPEED, between the trapezoid's ramps (v²/2a each) and 1 cm more.
    ramp = SPEED**2 / (2.0 * IRB120_LINE_GENERATOR["max_linear_acceleration"]) + 0.01
    moving = (progress > ramp) & (progress < length - ramp)
    moving_time = (length - 2 * ramp) / SPEED
    # tool_pose comes at 500 Hz; a loaded test process may drop some, so ask for a third.
    assert moving.sum() > 0.3 * 500 * moving_time
    # Deviation from the segment while moving: the feed-forward carries the tool along the
    # line; across it remains the lag of the control loop: the command is computed from a
    # joint state one pipeline latency d old, so with joint 1 turning at ω ≈ 2 rad/s the
    # commanded velocity points ω·d off the line, which the position gain K = 6 /s holds at
    # v·ω·d / K ≈ 0.4 · 2 · 0.005 / 6 ≈ 0.7 mm (measured 0.2-0.5 mm). 2 mm allows d = 15 ms;
    # a path bent by the reach check or the controller would show centimetres. A loop that
    # ran late carries the previous command on for that long: the nodes' own worst lateness
    # (their loop statistics) times the speed is added, as a loaded machine makes them late.
    lateness_s = loops_lateness_s(client)
    deviation = distance_to_segment(positions, START, END)
    assert deviation[moving].max() < 2e-3 + SPEED * lateness_s, (deviation[moving].max(), lateness_s)
    # At the ends the line ramps (within the joint acceleration limits); the loop's lag there
    # is bounded as while moving, with the acceleration's part added: 4 mm allows d = 10 ms.
    assert deviation.max() < 4e-3 + SPEED * lateness_s, (deviation.max(), lateness_s)
    # Speed: a least-squares fit of progress over time over the cruise. On time
    # it is within 0.5 % of 0.4 m/s. A late loop delays the tool by at most its lateness, which
    # can pile up over the moving time T: the fit may be off by lateness / T more (measured
    # 0.376 m/s with the loops up to 90 ms late on a machine loaded by other test runs).
    speed = np.polyfit(stamps[moving], progress[moving], 1)[0]
    assert speed == pytest.approx(SPEED, rel=0.03 + lateness_s / moving_time), (speed, lateness_s)
    # Speed over 20 ms windows stays near 0.4 m/s too (no stalls, no jumps; ±25 % for loops
    # that run a few ms late). A loop more than 5 ms late stalls a 20 ms window by itself, so
    # this holds only where the loops kept time; the output says when it was not checked.
    window = stamps[moving]
    chunk_speeds = [
        (progress[moving][j] - progress[moving][i]) / (window[j] - window[i])
        for i, j in zip(range(0, len(window) - 10, 10), range(10, len(window), 10))
        if window[j] - window[i] > 0.01
    ]
    if lateness_s < 5e-3:
        assert min(chunk_speeds) > 0.75 * SPEED and max(chunk_speeds) < 1.25 * SPEED, (
            min(chunk_speeds),
            max(chunk_speeds),
        )
    else:
        print(f"20 ms window speeds not checked: the loops ran up to {lateness_s * 1e3:.1f} ms late")
    np.testing.assert_allclose(positions[-1], END, atol=2e-4)
    print(
        f"irb120 position-only line at 500 Hz: deviation while moving max {deviation[moving].max() * 1e3:.3f} mm, "
        f"median {np.median(deviation[moving]) * 1e3:.3f} mm, overall max (stop overshoot) "
        f"{deviation.max() * 1e3:.3f} mm; fitted speed {speed:.4f} m/s, "
        f"20 ms window speeds {min(chunk_speeds):.3f}..{max(chunk_speeds):.3f} m/s; "
        f"loops' worst lateness {lateness_s * 1e3:.1f} ms"
    )


def test_line_out_of_reach_says_where_and_why(irb120):
    result = run_cli(irb120, "line", "--xyz", "1.2", "0.0", "0.5", "--wait", "--timeout", "20")
    assert result.returncode == 1, result.stderr
    assert "leaves the arm's reach at" in result.stderr and "task position" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def _xyz(msg) -> np.ndarray:
    return np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
