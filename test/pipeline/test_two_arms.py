"""Two arms on one ROS domain, each pipeline in its own namespace, recorded by one recorder.

genova7 runs under ``/left`` and irb120 under ``/right`` (``-r __ns:=...``); the recorder runs
in the root namespace with an explicit topic list naming both. Each arm reaches its own goal,
the other one does not move, and the recording holds each namespace's topics apart.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import matrix_to_quat
from manip_kin.pipeline import NodeProcess, Pipeline, PipelineClient, pipeline_processes
from manip_kin.recording import read_info, read_messages
from manip_kin.viz.run_data import load_run

MANIP_KIN = str(Path(sys.executable).parent / "manip_kin")

RATE_HZ = 200.0
GAINS = {"gain_linear": 3.0, "gain_angular": 3.0}
ARMS = {
    # namespace: (robot, start configuration or None, joint offset of the goal configuration)
    "/left": ("genova7", None, [0.15, 0.1, 0.1, -0.1, 0.1, 0.02, 0.1]),
    "/right": ("irb120", [0.0, 0.3, 0.0, 0.0, 0.5, 0.0], [0.2, -0.1, 0.15, 0.1, 0.2, 0.2]),
}
RECORDED = ("joint_states", "goal_pose", "tool_pose", "joint_velocity_commands", "robot_description")


def _start_and_goal(robot, start, offset):
    model = load_robot(robot)
    q_start = model.start_configuration() if start is None else np.array(start)
    q_goal = model.clip_to_limits(q_start + np.array(offset))
    return model, q_start, frame_pose(model, q_goal)


@pytest.fixture(scope="module")
def two_arms(tmp_path_factory):
    logs = tmp_path_factory.mktemp("two_arm_logs")
    out = tmp_path_factory.mktemp("two_arm_recording") / "two_arms.mcap"
    topics = [f"{namespace}/{name}" for namespace in ARMS for name in RECORDED]
    # One recorder names both arms' topics; a second one, in /left, records its namespace by default.
    left_out = out.with_name("left_default.mcap")
    recorders = [
        NodeProcess("recorder", "recorder", {"output": str(out), "topics": topics}),
        NodeProcess("recorder", "left_recorder", {"output": str(left_out)}, namespace="/left"),
    ]
    recorder = Pipeline(recorders, log_dir=logs)
    pipelines = {}
    try:
        recorder.start()
        for namespace, (robot, start, _) in ARMS.items():
            processes = pipeline_processes(robot, rate_hz=RATE_HZ, controller=GAINS, initial_positions=start)
            pipelines[namespace] = Pipeline(
                processes, env=recorder.env, log_dir=logs / namespace[1:], namespace=namespace
            )
            pipelines[namespace].start()
        yield pipelines, recorder, out
    finally:
        for pipeline in pipelines.values():
            pipeline.stop()
        recorder.stop(timeout=10.0)


def test_each_arm_reaches_its_own_goal_without_moving_the_other(two_arms):
    pipelines, recorder, out = two_arms
    arms = {namespace: _start_and_goal(*spec) for namespace, spec in ARMS.items()}
    sent = {}
    for namespace, (model, _q_start, goal) in arms.items():
        client = pipelines[namespace].client()
        assert client.namespace == namespace
        others = {other: pipelines[other].client().current_positions() for other in arms if other != namespace}
        stamp = client.send_goal(goal)
        sent[namespace] = (stamp, goal)
        converged, status = client.wait_converged(stamp, timeout=60.0)
        assert converged, (namespace, status)
        # The status came from this namespace's controller, about this goal.
        assert status.name == f"{namespace[1:]}/cartesian_controller" and status.values["goal_stamp"] == stamp
        q = client.current_positions()
        tool = frame_pose(model, q)
        np.testing.assert_allclose(tool[:3, 3], goal[:3, 3], atol=3e-4)
        np.testing.assert_allclose(tool[:3, :3], goal[:3, :3], atol=3e-3)
        for other, q_before in others.items():
            q_other = pipelines[other].client().current_positions()
            if other in sent:  # holds its own goal, not this one
                other_goal = sent[other][1]
                np.testing.assert_allclose(frame_pose(arms[other][0], q_other)[:3, 3], other_goal[:3, 3], atol=3e-4)
            else:  # no goal of its own yet: it did not move at all
                np.testing.assert_allclose(q_other, q_before, atol=1e-12)
    # Each controller still reports its own goal, never the other arm's.
    for namespace, (stamp, _) in sent.items():
        status = pipelines[namespace].client().wait_status("cartesian_controller")
        assert status.values["goal_stamp"] == stamp

    assert recorder.stop_process("recorder", timeout=10.0) == 0
    assert recorder.stop_process("left_recorder", timeout=10.0) == 0
    left_only = {topic.name for topic in read_info(out.with_name("left_default.mcap")).topics}
    assert {"/left/joint_states", "/left/goal_pose", "/left/robot_description", "/diagnostics"} <= left_only
    assert not any(name.startswith("/right") for name in left_only)
    info = read_info(out)
    names = {topic.name for topic in info.topics}
    for namespace in ARMS:
        assert {f"{namespace}/{name}" for name in RECORDED} <= names
    assert "/joint_states" not in names and "/goal_pose" not in names
    goals = {}
    for message in read_messages(out, topics=[f"{namespace}/goal_pose" for namespace in ARMS]):
        goals.setdefault(message.topic, []).append(message.message)
    for namespace, (_, goal) in sent.items():
        # Exactly one goal per arm, and it is that arm's goal.
        assert len(goals[f"{namespace}/goal_pose"]) == 1
        position = goals[f"{namespace}/goal_pose"][0].pose.position
        np.testing.assert_allclose([position.x, position.y, position.z], goal[:3, 3], atol=1e-12)
        run = load_run(out, namespace=namespace)
        model = arms[namespace][0]
        assert run.joint_names == model.joint_names
        np.testing.assert_allclose(run.tool.position[-1], goal[:3, 3], atol=3e-4)


def test_cli_goal_reaches_the_arm_of_its_namespace(two_arms):
    pipelines, _, _ = two_arms
    model, q_start, goal = _start_and_goal(*ARMS["/right"])
    # Where the right arm is not: its goal (an earlier test sent it there) or its start.
    right_now = frame_pose(model, pipelines["/right"].client().current_positions())
    target = goal if np.linalg.norm(right_now[:3, 3] - goal[:3, 3]) > 0.01 else frame_pose(model, q_start)
    assert np.linalg.norm(right_now[:3, 3] - target[:3, 3]) > 0.01
    left_before = pipelines["/left"].client().current_positions()
    xyz = [f"{v:.9f}" for v in target[:3, 3]]
    quat = [f"{v:.12f}" for v in matrix_to_quat(target[:3, :3])]
    result = subprocess.run(
        [MANIP_KIN, "goal", "--namespace", "right", "--xyz", *xyz, "--quat", *quat, "--wait", "--json"],
        env=pipelines["/right"].env,
        capture_output=True,
        text=True,
        timeout=90,
    )
    assert result.returncode == 0, result.stderr
    payload = json.loads(result.stdout)
    assert payload["topic"] == "/right/goal_pose" and payload["converged"] is True
    q = pipelines["/right"].client().current_positions()
    np.testing.assert_allclose(frame_pose(model, q)[:3, 3], target[:3, 3], atol=3e-4)
    # The left arm stays where it was: at rest, or holding the goal an earlier test gave it
    # (settling within its own tolerance). This test does not rely on which.
    left_now = pipelines["/left"].client().current_positions()
    assert np.max(np.abs(left_now - left_before)) < 1e-3


@pytest.mark.parametrize(
    ("namespace", "message"),
    [("1left", "not a valid ROS namespace"), ("/nobody_here", "no subscriber on /nobody_here/goal_pose")],
)
def test_cli_goal_namespace_errors_are_one_line_exit_2(two_arms, namespace, message):
    pipelines, _, _ = two_arms
    result = subprocess.run(
        [MANIP_KIN, "goal", "--namespace", namespace, "--xyz", "0.3", "0", "0.4", "--timeout", "1"],
        env=pipelines["/right"].env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_replay_moves_one_arms_recorded_topics_into_another_namespace(two_arms):
    pipelines, recorder, out = two_arms
    recorder.stop_process("recorder", timeout=10.0)  # the recording is complete (idempotent)
    env = pipelines["/right"].env
    mixed = subprocess.run(
        [MANIP_KIN, "replay", str(out), "--namespace", "/mirror", "--quiet"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert mixed.returncode == 2 and "/left, /right" in mixed.stderr and "--topics" in mixed.stderr
    irb120 = load_robot("irb120")
    client = PipelineClient(env=env, namespace="/mirror", watch_state=True)
    try:
        replay = subprocess.Popen(
            [MANIP_KIN, "replay", str(out), "--namespace", "mirror", "--topics", "/right/joint_states", "--quiet"],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        heard = client.spin_until(lambda: client.joint_state, 30)
        assert heard is not None and list(heard.name) == irb120.joint_names
        replay.terminate()
        replay.communicate(timeout=30)
    finally:
        client.close()
