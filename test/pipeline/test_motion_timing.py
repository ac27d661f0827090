"""When a motion ended and when the controller settled (issue 29: "line converged in 9.42 s" for a
2.5 s line hid the exponential tail): the supervisors' times and the CLI's words, without ROS."""

from types import SimpleNamespace

import numpy as np
import pytest

from manip_kin.control.generator_supervisor import GeneratorSupervisor
from manip_kin.control.state_machines import (
    ControllerState,
    ControllerSupervisor,
    ControllerSupervisorConfig,
    GoalKind,
)
from manip_kin.pipeline.outcome import motion_timing, seconds_between

MS = 1_000_000


def _pose_output(position_error: float):
    return SimpleNamespace(
        orientation_error=np.zeros(3),
        position_error=np.array([position_error, 0.0, 0.0]),
        manipulability=0.5,
        damping=0.0,
        limited_joints=(),
        singular=False,
    )


def test_the_controller_keeps_the_first_time_a_goal_was_within_tolerance():
    supervisor = ControllerSupervisor(ControllerSupervisorConfig(position_tolerance=1e-4), ["a", "b", "c"], 100 * MS)
    supervisor.joint_state_received(0)
    supervisor.goal_received(0, GoalKind.POSE)
    supervisor.pose_step_done(_pose_output(1e-3), False, 10 * MS)
    assert supervisor.converged_ns is None
    supervisor.pose_step_done(_pose_output(5e-5), False, 20 * MS)
    assert supervisor.state is ControllerState.CONVERGED and supervisor.converged_ns == 20 * MS
    supervisor.pose_step_done(_pose_output(2e-4), False, 30 * MS)  # pushed away
    supervisor.pose_step_done(_pose_output(1e-5), False, 40 * MS)  # and back: still the first time
    assert supervisor.converged_ns == 20 * MS
    supervisor.goal_received(50 * MS, GoalKind.JOINT)  # a new goal starts over
    assert supervisor.converged_ns is None
    supervisor.joint_step_done(SimpleNamespace(joint_error=np.zeros(3), limited_joints=()), False, 60 * MS)
    assert supervisor.converged_ns == 60 * MS


def test_the_generator_says_when_its_motion_started():
    supervisor = GeneratorSupervisor(200 * MS)
    assert supervisor.started_ns is None
    supervisor.start(SimpleNamespace(duration=2.5, progress_at=lambda t: t / 2.5), "line", 1234 * MS, "5.0", "")
    assert supervisor.started_ns == 1234 * MS


def test_seconds_between_stamp_keys_and_unknown_ones():
    assert seconds_between("10.000000000", "12.500000000") == pytest.approx(2.5)
    assert seconds_between("9.999999999", "10.000000001") == pytest.approx(2e-9)
    assert seconds_between("", "12.500000000") is None
    assert seconds_between("10.000000000", "soon") is None


def test_a_line_reports_when_it_ended_and_when_it_settled_apart():
    generator = {"started_stamp": "100.250000000", "final_goal_stamp": "102.750000000"}
    controller = {
        "converged_stamp": "103.350000000",
        "goal_kind": "pose",
        "task": "full",
        "position_tolerance": "0.001",
        "orientation_tolerance": "0.01",
    }
    timing = motion_timing("100.000000000", controller, generator)
    assert timing.motion_s == pytest.approx(2.5) and timing.settled_s == pytest.approx(3.1)
    assert timing.text("line") == "line ended after 2.50 s; settled within 0.001 m / 0.01 rad after 3.10 s"


def test_a_goal_is_timed_from_its_stamp_and_a_joint_move_by_its_joint_tolerance():
    goal = motion_timing("50.000000000", {"converged_stamp": "51.250000000", "position_tolerance": "0.0001"})
    assert goal.motion_s is None and goal.settled_s == pytest.approx(1.25)
    assert goal.text() == "settled within 0.0001 m / ? rad after 1.25 s"
    move = motion_timing(
        "1.000000000",
        {"converged_stamp": "4.000000000", "goal_kind": "joint", "joint_tolerance": "0.001"},
        {"started_stamp": "1.500000000", "final_goal_stamp": "3.500000000"},
    )
    assert (move.motion_s, move.settled_s) == (pytest.approx(2.0), pytest.approx(2.5))
    assert move.text("move") == "move ended after 2.00 s; settled within 0.001 rad or m per joint after 2.50 s"
    position_only = motion_timing("1.000000000", {"task": "position", "position_tolerance": "0.001"})
    assert position_only.settled_s is None and position_only.tolerance == "0.001 m"
    assert position_only.text() == ""  # not settled, no motion: nothing to say


def test_the_verdict_and_json_fields_say_the_end_and_settling_where_known():
    from manip_kin.pipeline.outcome import MotionTiming

    known = MotionTiming(motion_s=2.5, settled_s=3.125, tolerance="0.0001 m / 0.001 rad")
    assert known.converged_verdict("line", 9.42) == (
        "converged (line ended after 2.50 s; settled within 0.0001 m / 0.001 rad after 3.12 s)"
    )
    assert known.fields(True) == {"motion_time": 2.5, "settle_time": 3.125, "settle_tolerance": "0.0001 m / 0.001 rad"}
    assert known.fields(False)["settle_time"] is None
    unknown = MotionTiming(motion_s=None, settled_s=None, tolerance="")
    assert unknown.converged_verdict("move", 9.424) == "converged in 9.42 s"
