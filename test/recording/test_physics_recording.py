"""A physics run recorded: a box on collision_objects, the arm driven into it, the contact in the file.

robot_state (plant mujoco) and the recorder run as processes; this test publishes the box and the
commands. The recording must hold the box (collision_objects) and robot_state's /diagnostics with
the contact force and pair while the arm pushed against it.
"""

import numpy as np
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.pipeline import NodeProcess, Pipeline
from manip_kin.recording import read_messages

MODEL = load_robot("genova7")


def test_a_contact_with_a_box_is_in_the_recording(tmp_path):
    output = tmp_path / "contact.mcap"
    q0 = MODEL.start_configuration()
    turned = q0.copy()
    turned[0] += 0.4
    box = Marker(ns="cell", id=7, type=Marker.CUBE, action=Marker.ADD)
    box.header.frame_id = "base_link"
    box.pose.position.x, box.pose.position.y, box.pose.position.z = (
        float(v) for v in frame_pose(MODEL, turned, MODEL.dof)[:3, 3]
    )
    box.pose.orientation.w = 1.0
    box.scale.x = box.scale.y = box.scale.z = 0.1
    processes = [
        NodeProcess("recorder", "recorder", {"output": str(output)}),
        NodeProcess(
            "robot_state",
            "robot_state",
            {"robot": "genova7", "rate_hz": 250.0, "plant": "mujoco", "diagnostics_rate_hz": 20.0},
            ready_status="robot_state",
        ),
    ]
    pipeline = Pipeline(processes, log_dir=tmp_path)
    pipeline.start()
    try:
        client = pipeline.client()
        client.wait_subscribers(MarkerArray, "collision_objects", timeout=20, subscribers=2)
        client.publish_delivered("collision_objects", MarkerArray(markers=[box]), subscribers=2)
        command = np.zeros(MODEL.dof)
        command[0] = 0.5
        publisher = client.publisher(Float64MultiArray, "joint_velocity_commands")

        def touching():
            publisher.publish(Float64MultiArray(data=command.tolist()))
            status = client.latest_status("robot_state")
            return status is not None and float(status.values.get("contact_force_max", 0)) > 1.0

        assert client.spin_until(touching, 20), pipeline.log_tail("robot_state")
        client.spin_for(0.5)
        assert pipeline.stop_process("recorder") == 0
    finally:
        pipeline.stop()
    recorded = list(read_messages(output, topics=["/collision_objects", "/diagnostics"]))
    boxes = [m for m in recorded if m.topic == "/collision_objects"]
    assert boxes and boxes[0].message.markers[0].ns == "cell" and boxes[0].message.markers[0].id == 7
    contacts = [
        {kv.key: kv.value for kv in status.values}
        for m in recorded
        if m.topic == "/diagnostics"
        for status in m.message.status
        if status.name == "robot_state"
    ]
    touching = [values for values in contacts if float(values.get("contact_force_max", 0)) > 1.0]
    assert touching, contacts[-1:]
    assert touching[-1]["contact_pair"].endswith("| cell/7") and int(touching[-1]["contact_events"]) >= 1
