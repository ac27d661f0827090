"""cartesian_controller dropped into a ros2_control-style system with one remap.

The fake hardware (test/fake_hardware.py) stands for robot_state_publisher + ros2_control: a
UR5 URDF from example-robot-data on ``robot_description``, ``joint_states`` with an extra
gripper joint in its own order, and a JointGroupVelocityController's
``/forward_velocity_controller/commands``. The controller gets no ``robot`` parameter: it
waits for the URDF, takes the arm chain from it, and drives the hardware to a goal pose.
"""

import numpy as np
import pytest
from fake_hardware import COMMAND_TOPIC, FakeHardware, urdf_arm_joints
from robot_data_files import UR5, example_robot_data_urdf

from manip_kin.kinematics import frame_pose
from manip_kin.pipeline import NodeProcess, Pipeline
from manip_kin.urdf import load_urdf_string

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
    pipeline = Pipeline([controller], log_dir=tmp_path)
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
    finally:
        codes = pipeline.stop()
        if hardware is not None:
            hardware.close()
    assert codes == {"cartesian_controller": 0}
