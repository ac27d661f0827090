"""``manip_kin plot`` draws a collision run: the arm, the recorded obstacles and the nearest pair.

The recording is written here (joint states, robot_description, collision_objects and the
controller's /diagnostics with its nearest pair), so every value the figure must show is known.
"""

import numpy as np
import pytest
from collision_robots import BALL_ARM_URDF
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.cli import main
from manip_kin.recording import RecordingWriter
from manip_kin.ros.wire.topics import PIPELINE_TOPIC_TYPES
from manip_kin.viz.collision_plot import FIGURE, load_nearest

T0 = 1_700_000_000_000_000_000
POINTS = np.array([[0.30, -0.05, 0.65], [0.30, -0.04, 0.65]])
BOX_CENTRE, BOX_EXTENTS = (0.3, 0.0, 0.65), (0.08, 0.08, 0.08)


def _status(k: int, pair: str) -> DiagnosticArray:
    values = {
        "state": "tracking",
        "nearest_pair": pair,
        "nearest_distance": f"{0.05 - 0.001 * k:.6f}",
        "nearest_points": " ".join(f"{v:.5f}" for v in POINTS.reshape(-1)) if pair else "",
        "collision_safety_distance": "0.02",
    }
    status = DiagnosticStatus(name="cartesian_controller", message="tracking")
    status.values = [KeyValue(key=key, value=value) for key, value in values.items()]
    return DiagnosticArray(status=[status])


def _record(path, with_pair: bool = True):
    marker = Marker(ns="cell", id=1, type=Marker.CUBE, action=Marker.ADD)
    marker.header.frame_id = "base_link"
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = BOX_CENTRE
    marker.pose.orientation.w = 1.0
    marker.scale.x, marker.scale.y, marker.scale.z = BOX_EXTENTS
    with RecordingWriter(path) as writer:
        writer.write("/robot_description", String(data=BALL_ARM_URDF), T0)
        writer.write("/collision_objects", MarkerArray(markers=[marker]), T0 + 1)
        for k in range(20):
            q = [-0.6 + 0.03 * k, 0.4, 0.8]
            writer.write("/joint_states", JointState(name=["j1", "j2", "j3"], position=q), T0 + 10**7 * (k + 1))
            writer.write("/diagnostics", _status(k, "link3-obstacle:cell/1" if with_pair else ""), T0 + 10**7 * (k + 1))
    return path


def test_the_recorder_records_collision_objects_by_default():
    from manip_kin.ros.nodes.recorder_config import DEFAULT_TOPICS

    assert "collision_objects" in DEFAULT_TOPICS and "collision_objects" in PIPELINE_TOPIC_TYPES


def test_plot_draws_the_arm_the_obstacle_and_the_nearest_pair(tmp_path, monkeypatch):
    recording = _record(tmp_path / "run.mcap")
    nearest = load_nearest(recording)
    assert nearest.pair[-1] == "link3-obstacle:cell/1" and len(nearest.time) == 20
    np.testing.assert_allclose(nearest.points[-1], POINTS)
    assert nearest.distance.min() == pytest.approx(0.031) and nearest.safety_distance == 0.02
    import matplotlib.figure

    drawn = {}
    original = matplotlib.figure.Figure.savefig

    def capture(figure, out, *args, **kwargs):
        drawn[str(out).rsplit("/", 1)[-1]] = [line for axis in figure.axes for line in axis.get_lines()]
        return original(figure, out, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", capture)
    assert main(["plot", str(recording), "--out", str(tmp_path / "plots")]) == 0
    assert (tmp_path / "plots" / FIGURE).stat().st_size > 10_000
    lines = drawn[FIGURE]
    pair = [line for line in lines if (line.get_label() or "").startswith("nearest: link3-obstacle:cell/1 0.031")]
    assert pair and np.allclose(np.array(pair[0].get_data_3d()).T, POINTS)
    box = [l for l in lines if hasattr(l, "get_data_3d") and l.get_color() == "tab:red" and len(l.get_xdata()) == 2]
    corners = np.unique(np.round(np.vstack([np.array(line.get_data_3d()).T for line in box]), 6), axis=0)
    expected = np.array(BOX_CENTRE) + 0.5 * np.array(BOX_EXTENTS) * np.array(
        [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    )
    assert len(box) == 12 and np.allclose(np.sort(corners, axis=0), np.sort(expected, axis=0))
    arms = [line for line in lines if (line.get_label() or "").startswith("arm at t")]
    assert len(arms) == 2  # the start and the nearest approach


def test_a_run_without_a_nearest_pair_gets_no_collision_figure(tmp_path):
    recording = _record(tmp_path / "run.mcap", with_pair=False)
    assert main(["plot", str(recording), "--out", str(tmp_path / "plots")]) == 0
    assert not (tmp_path / "plots" / FIGURE).exists()
