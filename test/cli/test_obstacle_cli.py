"""``manip_kin obstacle``: markers delivered on collision_objects, read back into a Scene."""

import json
import os
import threading

import numpy as np
import pytest
from node_harness import Harness
from visualization_msgs.msg import MarkerArray

from manip_kin.cli import main
from manip_kin.core.scene import Scene, ShapeKind
from manip_kin.ros.wire.scene_messages import apply_marker_array


@pytest.fixture
def harness():
    harness = Harness()
    yield harness
    harness.close()


def _run_cli(harness, argv) -> int:
    """Run ``manip_kin`` in a thread while the harness spins its subscriber (it must ack)."""
    result = {}
    thread = threading.Thread(target=lambda: result.update(code=main(argv)))
    thread.start()
    harness.spin_until(lambda: not thread.is_alive(), timeout=20.0)
    thread.join(timeout=5.0)
    return result["code"]


def test_add_delete_clear_reach_a_subscriber_as_scene_changes(harness, capsys):
    received = harness.collect(MarkerArray, "collision_objects")
    scene = Scene()
    add = ["obstacle", "add", "--id", "3", "--shape", "cylinder", "--size", "0.1", "0.4", "--xyz", "0.5", "0", "0.2"]
    assert _run_cli(harness, [*add, "--rpy", "0", "0", "1.0", "--timeout", "10"]) == 0
    assert harness.spin_until(lambda: len(received) == 1)
    assert apply_marker_array(scene, received[0], "base_link") == []
    (obstacle,) = scene.obstacles
    assert obstacle.key == ("manip_kin", 3) and obstacle.shape is ShapeKind.CYLINDER
    assert obstacle.radius == pytest.approx(0.05) and obstacle.height == pytest.approx(0.4)
    assert np.allclose(obstacle.pose_in_base[:3, 3], [0.5, 0.0, 0.2])
    assert obstacle.pose_in_base[1, 0] == pytest.approx(np.sin(1.0))
    assert "delivered on /collision_objects to 1 subscriber" in capsys.readouterr().out
    assert _run_cli(harness, ["obstacle", "add", "--id", "4", "--shape", "sphere", "--size", "0.2"]) == 0
    assert _run_cli(harness, ["obstacle", "delete", "--id", "3"]) == 0
    assert harness.spin_until(lambda: len(received) == 3)
    for msg in received[1:]:
        apply_marker_array(scene, msg, "base_link")
    assert [o.key for o in scene.obstacles] == [("manip_kin", 4)]
    assert _run_cli(harness, ["obstacle", "clear", "--json"]) == 0
    assert harness.spin_until(lambda: len(received) == 4)
    apply_marker_array(scene, received[3], "base_link")
    assert len(scene) == 0


def test_bad_sizes_and_no_subscriber_are_exit_2(capsys):
    assert main(["obstacle", "add", "--id", "1", "--shape", "sphere", "--size", "0.1", "0.2"]) == 2
    assert "--size 0.1 0.2 for a sphere; valid: DIAMETER" in capsys.readouterr().err
    assert main(["obstacle", "clear", "--namespace", "/nobody_here", "--timeout", "0.3"]) == 2
    assert "no subscriber" in capsys.readouterr().err


def test_a_controller_takes_an_obstacle_in_its_base_frame_and_its_refusal_is_exit_2(harness, tmp_path, capsys):
    """``--frame`` defaults to the base frame the controller reports (here ``arm_base``, not
    base_link), and the controller's verdict is the command's: taken, or refused with why."""
    from collision_robots import BALL_ARM_URDF
    from fake_hardware import FakeHardware

    from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode

    urdf_text = BALL_ARM_URDF.replace('"base_link"', '"arm_base"')
    assert "arm_base" in urdf_text and "base_link" not in urdf_text
    path = tmp_path / "ball_arm.urdf"
    path.write_text(urdf_text)
    namespace = f"/obstacle_cli_{os.getpid()}"
    hardware = FakeHardware(urdf_text, [0.0, 0.4, 0.8], rate_hz=200.0, namespace=namespace)
    try:
        node = harness.start(
            CartesianControllerNode,
            namespace=namespace,
            robot=str(path),
            rate_hz=100.0,
            collision_avoidance=True,
            collision_pair_samples=100,
        )
        harness.executor.add_node(node)
        add = [
            "obstacle",
            "add",
            "--namespace",
            namespace,
            "--shape",
            "sphere",
            "--size",
            "0.1",
            "--xyz",
            "0.5",
            "0",
            "0.2",
        ]
        capsys.readouterr()
        assert _run_cli(harness, [*add, "--id", "1"]) == 0
        out = capsys.readouterr().out
        assert "taken by the controller (1 obstacles)" in out, out
        assert [o.key for o in node.collision.scene.obstacles] == [("manip_kin", 1)]
        assert _run_cli(harness, [*add, "--id", "2", "--frame", "base_link", "--json"]) == 2
        captured = capsys.readouterr()
        assert json.loads(captured.out)["controller"] == "refused"
        (line,) = captured.err.strip().splitlines()
        assert "obstacle manip_kin/2" in line and "refused by the controller" in line and "'base_link'" in line, line
        assert "arm_base" in line, line
        assert [o.key for o in node.collision.scene.obstacles] == [("manip_kin", 1)]
    finally:
        hardware.close()


def test_without_a_collision_aware_controller_the_command_says_so(harness, capsys):
    harness.collect(MarkerArray, "collision_objects")  # a recorder, a viewer: not a controller
    assert _run_cli(harness, ["obstacle", "clear", "--timeout", "10"]) == 0
    assert "no controller with collision_avoidance listens" in capsys.readouterr().out
