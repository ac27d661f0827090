"""Tests for the changes a mutation round on the core found the suite did not catch (issue 25).

Each test fails with its mutant applied (checked by hand when written, and by ``make mutate``
where the mutant is among its operators):

* λ where λ² belongs in the plain IK iteration's ``dls`` step;
* the SCARA closed form's elbow labels swapped;
* the prismatic speeds dropped from the tool speed bound;
* salvage not checking the chunk CRCs;
* a single NaN passing the learned joint-state fast path;
* ``within_limits`` ignoring its tolerance;
* the recording writer ignoring the middleware's source timestamp.

The second part holds tests for survivors of the first ``make mutate`` round that were real
gaps (task names and masks, slerp's short way, the input bounds' tool and margins, the random
configuration's margin, the numpy damped least squares).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from manip_kin.control.resolved_rate import pose_error
from manip_kin.core.bounds import InputBounds, reach_radius
from manip_kin.core.damped_least_squares import damped_least_squares
from manip_kin.core.kinematics import frame_pose, jacobian
from manip_kin.core.model import Joint, JointType, RobotModel
from manip_kin.core.pose_rows import parse_task
from manip_kin.core.robots import load_robot
from manip_kin.core.rotations import make_transform
from manip_kin.errors import InvalidArgumentError
from manip_kin.ik.closed_form import closed_form_solutions
from manip_kin.ik.iteration import general_iteration
from manip_kin.ik.problem import problem_for
from manip_kin.recording import CorruptRecordingError, RecordingWriter, read_messages, salvage
from manip_kin.ros.wire.cdr import JointStateDecoder
from manip_kin.ros.wire.messages import make_joint_state
from manip_kin.ros.wire.validation import InvalidMessageError

T0 = 1_700_000_000_000_000_000  # ns since the epoch


@pytest.mark.parametrize("damping", [0.05, 0.3, 1.5])
def test_the_plain_dls_iteration_damps_with_lambda_squared(damping):
    model = load_robot("genova7")
    frame = model.frame_index(model.default_frame)
    problem = problem_for(model, frame, parse_task(None, model))
    q = model.start_configuration()
    target = frame_pose(model, q + np.array([0.01, -0.01, 0.01, 0.01, -0.01, 0.005, 0.01]))
    status, q_next, _, _ = general_iteration(problem, target.tolist(), q.tolist(), "dls", 1.0, damping, (1e-9, 1e-9))
    orientation, position = pose_error(frame_pose(model, q), target)
    expected = q + damped_least_squares(jacobian(model, q).matrix, np.concatenate([orientation, position]), damping)
    assert status == 0 and model.within_limits(expected, 0.0)
    np.testing.assert_allclose(q_next, expected, rtol=1e-9, atol=1e-12)
    # The generated iteration takes the same step.
    fused = problem.iterate(q.tolist(), target.tolist(), 0.0, damping * damping, 1.0, 1e-9, 1e-9)
    np.testing.assert_allclose(fused[1], expected, rtol=1e-9, atol=1e-12)


def test_the_scara_elbow_labels_say_which_side_the_elbow_is_on():
    """robots.md's SCARA: 0.5 m links about z through (0, 0) and (0.5, 0); the elbow is the
    second joint's axis. Seen from the shoulder towards the wrist, "right" is clockwise."""
    model = load_robot("scara")
    frame = model.frame_index(model.default_frame)
    target = make_transform(np.eye(3), [0.6, 0.3, 0.1])
    result = closed_form_solutions(model, target, frame, parse_task(None, model))
    assert sorted(s.branch for s in result.solutions) == ["elbow=left", "elbow=right"]
    for solution in result.solutions:
        q1, q2 = solution.q[0], solution.q[1]
        elbow = 0.5 * np.array([math.cos(q1), math.sin(q1)])
        wrist = elbow + 0.5 * np.array([math.cos(q1 + q2), math.sin(q1 + q2)])
        np.testing.assert_allclose(wrist, [0.6, 0.3], atol=1e-9)
        clockwise = wrist[0] * elbow[1] - wrist[1] * elbow[0] < 0.0  # elbow to the right of the line
        assert solution.branch == ("elbow=right" if clockwise else "elbow=left")


def test_the_tool_speed_bound_counts_the_prismatic_speeds():
    """A gantry (x, y, z slides and a slow wrist): the slides' speeds add to the tool speed."""
    slides = [np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])]
    joints = tuple(
        Joint(
            name=f"slide_{i}",
            type=JointType.PRISMATIC,
            origin=np.eye(4),
            axis=axis,
            lower=-0.5,
            upper=0.5,
            velocity_limit=v,
        )
        for i, (axis, v) in enumerate(zip(slides, (0.5, 0.4, 0.3)))
    ) + (Joint(name="wrist", type=JointType.REVOLUTE, origin=np.eye(4), velocity_limit=0.1),)
    tool = np.eye(4)
    tool[0, 3] = 0.2
    model = RobotModel(name="gantry", joints=joints, tool=tool)
    bound = InputBounds.of(model).max_linear_speed
    rng = np.random.default_rng(3)
    fastest = 0.0
    for _ in range(50):
        q = model.random_configuration(rng)
        corner = model.velocity_limits * rng.choice([-1.0, 1.0], size=model.dof)
        fastest = max(fastest, float(np.linalg.norm(jacobian(model, q).linear @ corner)))
    assert fastest > 0.7  # the slides alone move the tool at |(0.5, 0.4, 0.3)| = 0.71 m/s
    assert fastest <= bound


def _recording_with_one_damaged_chunk(tmp_path):
    written = [f"message {i:03d} " + "x" * 200 for i in range(60)]
    path = tmp_path / "run.mcap"
    with RecordingWriter(path, compression="none", chunk_size=1024) as writer:
        for i, text in enumerate(written):
            writer.write("/notes", String(data=text), log_time_ns=T0 + i)
    content = bytearray(path.read_bytes())
    damaged = content.index(b"message 030 ") + len(b"message 030 ") + 50
    content[damaged] = ord("y")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bytes(content[: content.index(b"message 055 ")]))  # killed: no footer either
    return written, cut


def test_salvage_drops_a_chunk_whose_crc_does_not_match(tmp_path):
    written, cut = _recording_with_one_damaged_chunk(tmp_path)
    try:
        report = salvage(cut, tmp_path / "saved.mcap")
    except CorruptRecordingError as error:
        pytest.fail(f"nothing salvaged: {error}")
    recovered = [m.message.data for m in read_messages(tmp_path / "saved.mcap")]
    assert recovered and report.message_count == len(recovered)
    assert set(recovered) <= set(written), "a damaged message was copied"
    assert written[30] not in recovered and written[0] in recovered


def test_a_single_nan_never_passes_the_learned_joint_state_fast_path():
    names = [f"j{i}" for i in range(6)]
    decoder = JointStateDecoder(names, np.full(6, -3.0), np.full(6, 3.0))
    good = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6]
    np.testing.assert_array_equal(decoder.positions(serialize_message(make_joint_state(names, good))), good)
    assert decoder._blob is not None  # the layout is learned: what follows takes the fast path
    for j in range(6):
        for bad in (math.nan, math.inf):
            values = list(good)
            values[j] = bad
            data = serialize_message(make_joint_state(names, values))
            with pytest.raises(InvalidMessageError, match="NaN or infinity"):
                decoder.positions(data)
    # Still learned (the same layout): a good state after the bad ones reads straight away.
    np.testing.assert_array_equal(decoder.positions(serialize_message(make_joint_state(names, good))), good)


def test_within_limits_honours_its_tolerance():
    model = load_robot("genova7")
    upper = model.upper.copy()
    lower = model.lower.copy()
    assert model.within_limits(upper) and model.within_limits(lower)
    assert model.within_limits(upper + 0.5e-9)  # the default tolerance is 1e-9
    assert not model.within_limits(upper + 2e-9) and not model.within_limits(lower - 2e-9)
    assert not model.within_limits(upper + 0.5e-9, tolerance=0.0)
    assert model.within_limits(upper + 1e-4, tolerance=1e-3) and model.within_limits(lower - 1e-4, tolerance=1e-3)
    assert not model.within_limits(upper + 2e-3, tolerance=1e-3)


def test_the_writer_stamps_a_headerless_message_with_its_source_time(tmp_path):
    with RecordingWriter(tmp_path / "run.mcap") as writer:
        writer.add_topic("/commands", "std_msgs/msg/Float64MultiArray")
        writer.add_topic("/states", "sensor_msgs/msg/JointState")
        command = serialize_message(Float64MultiArray(data=[1.0, 2.0]))
        writer.write_raw("/commands", command, log_time_ns=T0 + 900, source_time_ns=T0 + 100)
        writer.write_raw("/commands", command, log_time_ns=T0 + 901)  # no source time: the receive time
        unstamped = serialize_message(JointState(name=["a"], position=[0.0]))  # header stamp 0
        writer.write_raw("/states", unstamped, log_time_ns=T0 + 902, source_time_ns=T0 + 200)
    times = [(m.topic, m.log_time_ns, m.publish_time_ns) for m in read_messages(tmp_path / "run.mcap")]
    assert times == [
        ("/commands", T0 + 900, T0 + 100),
        ("/commands", T0 + 901, T0 + 901),
        ("/states", T0 + 902, T0 + 200),
    ]


# --- survivors of the first `make mutate` round (seed 25) that were missing tests ----------------


def test_task_names_masks_and_error_norms():
    from manip_kin.core.pose_rows import Task, parse_task

    assert parse_task("ry, x,y").name == "ry,x,y" and parse_task("rz,x,y,z").name == "position_yaw"
    for bad in ([1, 1, 1, 0, 0], [1, 1, 1, 0, 0, 2], [0] * 6):
        with pytest.raises(InvalidArgumentError, match="task mask"):
            parse_task(bad)
    orientation, position = Task((0, 1, 3, 4)).error_norms([3.0, 4.0, 7.0], [6.0, 8.0, 9.0])
    assert (orientation, position) == (5.0, 10.0)  # the rows' Euclidean norms, rz and z left out


def test_slerp_takes_the_short_way_and_reaches_a_nearby_end():
    from manip_kin.core.rotations import quat_slerp

    def about_z(angle):
        return np.array([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)])

    # -q is the same rotation as q: a quarter of the way to -(1 rad about z) is 0.25 rad about z.
    quarter = quat_slerp(about_z(0.0), -about_z(1.0), 0.25)
    assert abs(quarter @ about_z(0.25)) == pytest.approx(1.0, abs=1e-12)
    a = about_z(0.2)
    close = about_z(0.2 + 2e-7)
    np.testing.assert_allclose(quat_slerp(a, close, 1.0), close, atol=1e-12)


def test_input_bounds_contain_the_tool_and_widen_the_joint_ranges():
    model = load_robot("genova7")
    long_tool = np.eye(4)
    long_tool[0, 3] = 1.5
    with_tool = RobotModel(name="long tool", joints=model.joints, ee_offset=model.ee_offset, tool=long_tool)
    bounds = InputBounds.of(with_tool)
    rng = np.random.default_rng(4)
    farthest = max(np.linalg.norm(frame_pose(with_tool, with_tool.random_configuration(rng))[:3, 3]) for _ in range(50))
    assert farthest > 1.5 and farthest <= bounds.reach_radius
    assert reach_radius(with_tool) == bounds.reach_radius
    assert np.all(bounds.position_lower <= with_tool.lower - 0.01) and np.all(
        bounds.position_upper >= with_tool.upper + 0.01
    )
    assert bounds.max_twist_linear >= bounds.max_linear_speed > 0.0


def test_random_configurations_keep_their_margin():
    model = load_robot("genova7")
    rng = np.random.default_rng(5)
    span = model.upper - model.lower
    for _ in range(100):
        q = model.random_configuration(rng, margin=0.25)
        assert np.all(q >= model.lower + 0.25 * span - 1e-12) and np.all(q <= model.upper - 0.25 * span + 1e-12)


def test_the_numpy_damped_least_squares_is_the_textbook_formula():
    rng = np.random.default_rng(6)
    matrix, rhs = rng.normal(size=(3, 5)), rng.normal(size=3)
    expected = matrix.T @ np.linalg.inv(matrix @ matrix.T + 0.3**2 * np.eye(3)) @ rhs
    np.testing.assert_allclose(damped_least_squares(matrix, rhs, 0.3), expected, rtol=1e-12)


def test_the_identity_has_angle_zero_about_z():
    from manip_kin.core.rotations import matrix_to_angle_axis

    angle, axis = matrix_to_angle_axis(np.eye(3))
    assert angle == 0.0 and axis.tolist() == [0.0, 0.0, 1.0]


def test_an_absurd_goal_position_is_refused_with_its_coordinates():
    from manip_kin.control.resolved_rate import CartesianController

    model = load_robot("genova7")
    q = model.start_configuration()
    goal = frame_pose(model, q)
    goal[2, 3] = 1e200
    with pytest.raises(InvalidArgumentError, match=r"goal position \[.*1e\+200\]; valid: \|values\| < 1e\+100 m"):
        CartesianController(model).step(q, goal)
