"""cartesian_controller and trajectory_generator dropped into a ros2_control-style system with one remap.

The fake hardware (test/support/fake_hardware.py) stands for robot_state_publisher + ros2_control: a
UR5 URDF from example-robot-data on ``robot_description``, ``joint_states`` with an extra
gripper joint in its own order (no ``tool_pose``: there is no robot_state), and a
JointGroupVelocityController's ``/forward_velocity_controller/commands``. The nodes get no
``robot`` parameter: they wait for the URDF and take the arm chain from it; the controller
drives the hardware to a goal pose, then the generator runs a line from where the hardware
says the arm is.
"""

import re

import numpy as np
import pytest
from fake_hardware import COMMAND_TOPIC, FakeHardware, urdf_arm_joints
from pipeline_checks import loops_lateness_s
from robot_data_files import UR5, example_robot_data_urdf

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.urdf import load_urdf_string
from manip_kin.motion.lines import distance_to_segment
from manip_kin.pipeline import NodeProcess, Pipeline

Q0 = [0.3, -1.2, 1.5, -0.9, 1.3, 0.2]
Q_GOAL = [0.55, -1.0, 1.3, -1.2, 1.1, 0.5]


@pytest.fixture
def ur5_text():
    return example_robot_data_urdf(UR5).read_text()


def test_controller_drives_a_ros2_control_arm_from_robot_description(ur5_text, tmp_path):
    controller = NodeProcess(
        "cartesian_controller",
        "cartesian_controller",
        {"rate_hz": 200.0, "gain_linear": 3.0, "gain_angular": 3.0},
        remaps={"joint_velocity_commands": COMMAND_TOPIC},
        ready_status="cartesian_controller",
    )
    generator = NodeProcess(
        "trajectory_generator",
        "trajectory_generator",
        {"rate_hz": 200.0, "time_scaling": "trapezoidal", "max_linear_velocity": 0.05},
        ready_status="trajectory_generator",
    )
    pipeline = Pipeline([controller, generator], log_dir=tmp_path)
    hardware = None
    try:
        # The controller starts first: it must wait for the description, and say so.
        pipeline.start_process("cartesian_controller")
        client = pipeline.client()
        assert client.spin_until(lambda: "waiting for the robot model" in pipeline.log_text("cartesian_controller"), 30)
        assert "/robot_description" in pipeline.log_text("cartesian_controller")
        hardware = FakeHardware(ur5_text, Q0)
        pipeline.wait_ready(["cartesian_controller"], timeout=30)
        log = pipeline.log_text("cartesian_controller")
        assert "from the URDF on /robot_description" in log and "6 joints" in log

        # The model the controller uses is the URDF's default chain: base 'world', the six arm joints.
        model = load_urdf_string(ur5_text)
        assert model.joint_names == urdf_arm_joints(ur5_text)
        goal = frame_pose(model, Q_GOAL)
        stamp = client.send_goal(goal, frame_id=model.base_frame)
        converged, status = client.wait_converged(stamp, timeout=60)
        assert converged, (status, pipeline.log_tail("cartesian_controller"))
        assert hardware.commands_received > 0 and hardware.rejected_commands == 0
        tool = frame_pose(model, hardware.positions())
        np.testing.assert_allclose(tool[:3, 3], goal[:3, 3], atol=2e-4)
        np.testing.assert_allclose(tool[:3, :3], goal[:3, :3], atol=2e-3)
        # The gripper joint in joint_states did not disturb it, and was never commanded.
        assert hardware.gripper == 0.02
        assert status.values["rejected_joint_states"] == "0"

        # A line from where the hardware's joint states put the tool: 4 cm along x and down.
        pipeline.start_process("trajectory_generator")
        pipeline.wait_ready(["trajectory_generator"], timeout=30)
        start = frame_pose(model, hardware.positions())
        target = start.copy()
        target[:3, 3] += [0.04, 0.0, -0.02]
        # The tool's path: the hardware's own positions at each of its steps from the line's start
        # until the arm has settled on the target. (Until the line was done only, the hardware in
        # this busy process twice recorded 11-12 steps: its steps can pause for most of a 1 s line,
        # and the arm then finishes the motion after it.)
        first_step = len(hardware.history)
        done = client.wait_line_done(client.send_line(target, frame_id=model.base_frame), 60)
        assert done.message == "holding", (done.message, pipeline.log_tail("trajectory_generator"))
        converged, status = client.wait_converged(done.values["final_goal_stamp"], timeout=60)
        assert converged, (status, pipeline.log_tail("cartesian_controller"))
        # The arm settles on the target (the controller holds it): convergence is judged on a
        # joint state that can be a few ms old, and the hardware runs in this busy process.
        settled = lambda: np.abs(frame_pose(model, hardware.positions())[:3, 3] - target[:3, 3]).max() < 2e-4  # noqa: E731
        assert client.spin_until(settled, 10), frame_pose(model, hardware.positions())[:3, 3] - target[:3, 3]
        path = np.array([frame_pose(model, q)[:3, 3] for q in hardware.history[first_step:]])
        # The planned line started at the tool pose of the joint states (the arm was at rest).
        log = pipeline.log_text("trajectory_generator")
        match = re.search(r"streaming a trapezoidal line from \[([^\]]*)\] to", log)
        assert match, log[-500:]
        np.testing.assert_allclose([float(v) for v in match.group(1).split(",")], start[:3, 3], atol=2e-4)
        # It went along the line: 1 mm is 50x what the delay of a 200 Hz loop explains (an offline
        # estimate), and far below a line planned from a wrong start (a jump of centimetres); it
        # got from the start to the target. A loop that ran late, or this busy process's
        # hardware taking a command late, holds the previous command on for that long: the
        # nodes' worst lateness and the hardware's longest step, times the line's speed, are
        # added (1.2 mm seen on a loaded machine).
        lateness_s = loops_lateness_s(client, ("cartesian_controller", "trajectory_generator"))
        lateness_s += float(np.max(np.diff(hardware.history_times[first_step:])))
        bound = 1e-3 + 0.05 * lateness_s
        deviation = distance_to_segment(np.array(path), start[:3, 3], target[:3, 3]).max()
        assert len(path) > 50 and deviation < bound, (deviation, bound)
        assert np.linalg.norm(path[0] - start[:3, 3]) < 2e-4 and np.linalg.norm(path[-1] - target[:3, 3]) < 2e-4
    finally:
        codes = pipeline.stop()
        if hardware is not None:
            hardware.close()
    assert codes == {"cartesian_controller": 0, "trajectory_generator": 0}
