"""The controller as a process, stopped mid-motion, on an arm that holds its last command.

SIGINT and SIGTERM (the node's own halt before its context goes down), and Ctrl-C of
``manip_kin goal --wait`` (the CLI calls ``~/stop``): each time the arm must come to rest
within the limits, the last command it received an exact zero, and the arm still afterwards.
The arm is test/support/fake_hardware.py with ``command_timeout=inf`` (JointGroupVelocityController).
"""

import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fake_hardware import FakeHardware
from held_arm import assert_stream_within

from manip_kin.control.joint_limits import JointLimits
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.urdf import model_to_urdf
from manip_kin.pipeline import NodeProcess, Pipeline

MANIP_KIN = str(Path(sys.executable).parent / "manip_kin")
MODEL = load_robot("genova7")
RATE = 250.0


def _moving_arm(tmp_path):
    hardware = FakeHardware(
        model_to_urdf(MODEL),
        MODEL.start_configuration(),
        rate_hz=2 * RATE,
        command_timeout=math.inf,
        command_topic="joint_velocity_commands",
    )
    controller = NodeProcess(
        "cartesian_controller",
        "cartesian_controller",
        {"robot": "genova7", "rate_hz": RATE, "joint_state_timeout": 0.5},
        ready_status="cartesian_controller",
    )
    # The test process's domain: the fake arm lives in this process.
    pipeline = Pipeline([controller], log_dir=tmp_path)
    pipeline.start()
    # The arm hears the controller before anything moves (a late match would miss a ramp's start).
    client = pipeline.client()
    assert client.spin_until(lambda: hardware.commands_received > 0, 20), pipeline.log_tail("cartesian_controller")
    return hardware, pipeline


def _far_goal():
    goal = frame_pose(MODEL, MODEL.start_configuration())
    goal[:3, 3] += [0.0, 0.15, 0.1]
    return goal


def _wait_moving(client, hardware, speed=0.05):
    moving = lambda: (c := hardware.held_command()) is not None and np.abs(c).max() > speed  # noqa: E731
    if not client.spin_until(moving, 10):
        status = client.latest_status("cartesian_controller")
        raise AssertionError((hardware.held_command(), status and status.values))


def _assert_brought_to_rest(client, hardware):
    assert client.spin_until(lambda: not np.any(hardware.held_command()), 5), hardware.held_command()
    q = hardware.positions()
    client.spin_for(0.3)
    np.testing.assert_array_equal(hardware.positions(), q)  # the held command is an exact zero
    commands = np.array([values for _, values in hardware.commands])
    assert not np.any(commands[-1])
    assert_stream_within(commands, JointLimits.of(MODEL), 1.0 / RATE)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_mid_motion_halts_the_arm_within_the_limits(tmp_path, sig):
    hardware, pipeline = _moving_arm(tmp_path)
    try:
        client = pipeline.client()
        # Taken, not just acknowledged (a goal lost on the way is sent again), then moving.
        client.wait_taken(client.send_goal(_far_goal()))
        _wait_moving(client, hardware)
        signalled = time.monotonic()
        code = pipeline.stop_process("cartesian_controller", timeout=5.0, sig=sig)
        assert code == 0, pipeline.log_tail("cartesian_controller")
        # The zero came before the process ended, within stop_time (1 s) of the signal.
        last_time = hardware.commands[-1][0]
        assert last_time - signalled < 1.0 + 0.5
        _assert_brought_to_rest(client, hardware)
        # It did not just cut the command: the halt took several cycles of deceleration.
        since = [values for t, values in hardware.commands if t >= signalled]
        assert len(since) > 3 and np.abs(since[0]).max() > 0.0
    finally:
        pipeline.stop()
        hardware.close()


def test_ctrl_c_of_goal_wait_stops_the_motion(tmp_path):
    hardware, pipeline = _moving_arm(tmp_path)
    try:
        client = pipeline.client()
        goal = _far_goal()
        xyz = [f"{v:.6f}" for v in goal[:3, 3]]
        cli = subprocess.Popen(
            [MANIP_KIN, "goal", "--xyz", *xyz, "--rpy", "0", "0", "0", "--wait", "--timeout", "30"],
            env=pipeline.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            _wait_moving(client, hardware, speed=0.02)
        except AssertionError:
            cli.kill()
            raise AssertionError((cli.communicate(timeout=5), pipeline.log_tail("cartesian_controller"))) from None
        moving = hardware.held_command()
        cli.send_signal(signal.SIGINT)
        stdout, stderr = cli.communicate(timeout=20)
        assert cli.returncode == 130, (stdout, stderr, moving, hardware.commands_received)
        assert "stopped the motion" in stderr
        status = client.wait_status("cartesian_controller", 5, after_ns=client.now_ns())
        assert client.spin_until(lambda: client.latest_status("cartesian_controller").message == "stopped", 5), status
        _assert_brought_to_rest(client, hardware)
        assert pipeline.stop() == {"cartesian_controller": 0}
    finally:
        pipeline.stop()
        hardware.close()
