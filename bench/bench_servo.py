"""Servoing benchmark rows: twist_command to the first command that moves, at 1 kHz.

Each trial starts from rest: the previous twist has timed out (command_timeout) and the
controller's commands are exact zeros again. A twist (±1 cm/s along z, alternating) is
published and the time until the first non-zero joint_velocity_commands arrives here is taken.
That is the reaction through the command filter: its first sample after a step is J·dt²/2 of
speed, non-zero at once.
"""

from __future__ import annotations

import os
import struct
import tempfile
import time

import numpy as np
from bench_nodes import _samples


def _twist_latency_row(rate_hz: float, priority: int, trials: int) -> dict:
    from geometry_msgs.msg import TwistStamped
    from rclpy.qos import QoSProfile
    from std_msgs.msg import Float64MultiArray

    from manip_kin.pipeline import Pipeline, pipeline_processes
    from manip_kin.ros.runtime.polling import RawSubscription
    from manip_kin.ros.runtime.scheduling import TIMER_SLACK_NS, set_timer_slack
    from manip_kin.ros.wire.messages import make_twist_stamped

    processes = pipeline_processes(
        "genova7", rate_hz=rate_hz, controller={"command_timeout": 0.05}, realtime_priority=priority
    )
    latencies = []
    with Pipeline(processes, log_dir=tempfile.mkdtemp(prefix="bench_twist_")) as pipeline:
        client = pipeline.client()
        client.current_positions()
        client.unwatch_state()
        commands = RawSubscription(client.node, Float64MultiArray, "joint_velocity_commands", QoSProfile(depth=100))
        publisher = client.publisher(TwistStamped, "twist_command")
        client.wait_subscribers(TwistStamped, "twist_command")
        set_timer_slack(TIMER_SLACK_NS)
        tail = struct.Struct("<7d")

        def at_rest() -> bool:
            newest = None
            while (taken := commands.take()) is not None:
                newest = taken
            return newest is not None and not any(tail.unpack_from(newest[0], len(newest[0]) - tail.size))

        for trial in range(trials):
            if not client.spin_until(at_rest, 5.0):
                raise RuntimeError("the commands did not come back to exact zeros after a twist timed out")
            while commands.take() is not None:
                pass
            sign = 1.0 if trial % 2 == 0 else -1.0
            msg = make_twist_stamped([0.0, 0.0, 0.0], [0.0, 0.0, 0.01 * sign], "base_link")
            sent = time.monotonic_ns()
            publisher.publish(msg)
            deadline = sent + 500_000_000
            while time.monotonic_ns() < deadline:
                taken = commands.take()
                if taken is None:
                    time.sleep(20e-6)
                    continue
                if any(tail.unpack_from(taken[0], len(taken[0]) - tail.size)):
                    latencies.append((time.monotonic_ns() - sent) * 1e-6)
                    break
    values = _samples(latencies)
    scheduling = f"SCHED_FIFO {priority}" if priority else "normal scheduling"
    return {
        "metric": f"twist-to-first-moving-command latency, genova7 at {rate_hz:g} Hz, {scheduling}",
        "p50_ms": float(np.percentile(values, 50)),
        "p99_ms": float(np.percentile(values, 99)),
        "max_ms": float(values.max()),
        "trials": len(latencies),
    }


def run_servo_benchmarks(trials: int = 200) -> list[dict]:
    """The servo rows: at normal scheduling, and at SCHED_FIFO 20 where the machine allows it."""
    rows = [_twist_latency_row(1000.0, 0, trials)]
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        rows.append(_twist_latency_row(1000.0, 20, trials))
    except OSError as error:
        rows.append({"metric": "twist-to-first-moving-command latency, SCHED_FIFO 20", "skipped": str(error)})
    return rows
