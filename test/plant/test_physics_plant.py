"""The MuJoCo plant without ROS: gravity held by the servo, the servo's response, stiff tracking, contact, inertials.

Expected values come from the servo's closed-loop equation (see manip_kin.plant.mujoco_plant):
per joint, with e = v_ref - v, ``M ë + Kv ė + Ki e = 0`` and a load torque d held at a position
error d / Ki. Gravity torques of the default links are computed here from the documented rule
(capsule per link, 4 kg/m, at least 0.2 kg) by differentiating the potential energy over our
own forward kinematics, independently of MuJoCo.
"""

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from robot_data_files import PANDA, example_robot_data_urdf

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.core.scene import Scene, make_obstacle
from manip_kin.errors import ModelFileError
from manip_kin.plant.kinematic import KinematicPlant
from manip_kin.plant.mujoco_model import DEFAULT_LINEAR_DENSITY, MIN_LINK_MASS
from manip_kin.plant.mujoco_plant import MujocoPlant, PhysicsConfig, ServoGains

GENOVA7 = load_robot("genova7")
PANDA_PATH = example_robot_data_urdf(PANDA)
PANDA_TEXT = PANDA_PATH.read_text()
MESH_SEARCH_PATH = str(PANDA_PATH.parents[4])  # .../share, which holds the example-robot-data package
G = 9.81


def _run(plant, command, seconds, dt=0.001):
    for _ in range(round(seconds / dt)):
        plant.step(command, dt)


def _default_link_gravity_torque(model, q):
    """∂V/∂q of the default links (documented masses, centres at the middle of each segment), numerically."""

    def potential(x):
        energy = 0.0
        for i in range(model.dof):
            nxt = model.joints[i + 1].origin if i + 1 < model.dof else model.ee_offset
            end = nxt[:3, 3]
            mass = max(DEFAULT_LINEAR_DENSITY * np.linalg.norm(end), MIN_LINK_MASS)
            centre = frame_pose(model, x, i + 1) @ np.append(0.5 * end, 1.0)
            energy += mass * G * centre[2]
        return energy

    h = 1e-6
    return np.array([(potential(q + h * e) - potential(q - h * e)) / (2 * h) for e in np.eye(model.dof)])


def test_zero_command_holds_genova7_against_gravity_within_the_servo_steady_error():
    q0 = GENOVA7.start_configuration()
    plant = MujocoPlant(GENOVA7, q0, PhysicsConfig())
    _run(plant, None, 1.0)
    gravity = _default_link_gravity_torque(GENOVA7, q0)
    # Steady state: Ki (q_ref - q) = tau_g with q_ref = q0 (zero command), so the sag is tau_g / Ki;
    # linearised around q0 it moves tau_g by less than 5 % here (a few mrad), hence the 10 % margin.
    expected_sag = -gravity / plant.gains_ki
    assert np.all(np.abs(plant.q - q0) <= 1.1 * np.abs(expected_sag) + 1e-5)  # 1e-5: coupling of the joints
    loaded = np.abs(gravity) > 1.0
    assert loaded.any(), "genova7 at q0 should load some joints with gravity"
    np.testing.assert_allclose((plant.q - q0)[loaded], expected_sag[loaded], rtol=0.1)
    assert np.abs(plant.qdot).max() < 1e-3
    # The drive holds gravity: its torque is the gravity torque (documented default masses).
    np.testing.assert_allclose(plant.effort_values, gravity, rtol=0.05, atol=0.05)


def test_zero_command_holds_the_panda_with_its_urdf_inertials_meshes_and_efforts():
    q0 = np.array([0.0, -0.5, 0.0, -2.0, 0.0, 1.6, 0.8])
    plant = MujocoPlant(
        load_robot(str(PANDA_PATH)), q0, PhysicsConfig(mesh_search_path=MESH_SEARCH_PATH), urdf_text=PANDA_TEXT
    )
    assert plant.mj_model.nmesh == 9  # link0..7 and the hand: every collision mesh resolved (the fingers are boxes)
    masses = [float(m) for m in re.findall(r'<mass value="([^"]+)"', PANDA_TEXT)]
    assert abs(plant.mj_model.body_mass.sum() - (sum(masses) - masses[0])) < 1e-9  # every link but the base link0
    np.testing.assert_array_equal(plant.effort_limits, [87, 87, 87, 87, 12, 12, 12])
    _run(plant, None, 1.0)
    # Held within the steady error |tau| / Ki, tau bounded by the efforts (every |tau| < effort here).
    effort = np.abs(plant.effort_values)
    assert np.all(effort < plant.effort_limits)
    assert np.all(np.abs(plant.q - q0) <= 1.1 * effort / plant.gains_ki + 1e-6)
    assert effort[1] > 5.0  # the shoulder carries the arm
    assert np.abs(plant.qdot).max() < 1e-3


def test_a_constant_velocity_command_is_reached_within_the_servo_time_constant():
    k = 200.0  # servo_velocity_gain; integral gain k²/4: a double pole at -k/2
    model = load_robot("irb120")
    plant = MujocoPlant(model, model.start_configuration(), PhysicsConfig(servo=ServoGains(k, k * k / 4)))
    _run(plant, None, 0.3)  # settled against gravity first
    v = 0.5
    command = np.zeros(model.dof)
    command[0] = v  # joint 1: vertical axis, no gravity torque on it
    elapsed = 0.0
    for t in (1 / k, 3 / k, 10 / k, 20 / k):  # 5, 15, 50, 100 ms
        _run(plant, command, t - elapsed)
        elapsed = t
        # Error of the closed loop from e(0) = v, ė(0) = -k v: e(t) = v (1 - k t / 2) exp(-k t / 2).
        error = v * (1 - k * t / 2) * math.exp(-k * t / 2)
        assert abs(plant.qdot[0] - (v - error)) <= 0.05 * v, (t, plant.qdot[0], v - error)
    assert abs(plant.qdot[0] - v) <= 0.01 * v  # reached: within 1 % after twenty time constants


def test_with_a_very_stiff_servo_the_physics_plant_tracks_the_kinematic_plant():
    model = load_robot("irb120")  # YAML robot: default links, no effort limits (no anti-windup clamp)
    q0 = np.array([0.0, 0.3, -0.2, 0.0, 0.5, 0.0])
    kv, ki = 2000.0, 1e6
    physics = MujocoPlant(model, q0, PhysicsConfig(rate_hz=2000.0, servo=ServoGains(kv, ki)))
    kinematic = KinematicPlant(model, q0)
    amplitude, omega = np.array([0.8, 0.6, 0.6, 1.0, 0.8, 1.0]), 2 * math.pi * 2.0
    worst, sag, dt = 0.0, 0.0, 0.001
    for step in range(500):
        command = amplitude * math.sin(omega * step * dt)
        physics.step(command, dt)
        kinematic.step(command, dt)
        worst = max(worst, float(np.abs(physics.q - kinematic.q).max()))
        if step % 25 == 0:
            sag = max(sag, float(np.max(np.abs(_default_link_gravity_torque(model, kinematic.q)) / physics.gains_ki)))
    # q_ref is the kinematic plant's q (same command, same scaling, no limits reached), and E = q_ref - q
    # obeys M Ë + Kv Ė + Ki E = M q̈_ref + tau_g per joint, so |E_i| <= (|M| |a|)_i / Ki_i + |tau_g,i| / Ki_i
    # with |a| = A ω (the joints' inertia coupling, M from MuJoCo at q0) and the gravity sag along the
    # path (computed here from the default links); twice that for what the path changes in M. On top,
    # the discrete step: semi-implicit Euler moves q by the servo force of the step before, a lag of one
    # physics step h of motion, h · max|v| (measured: 5e-4 rad at h = 0.5 ms, 1e-4 at 0.1 ms).
    import mujoco  # after manip_kin.plant, which chooses its OpenGL backend (the render test needs EGL)

    data = mujoco.MjData(physics.mj_model)
    data.qpos[:] = q0
    mujoco.mj_forward(physics.mj_model, data)
    inertia = np.zeros((model.dof, model.dof))
    mujoco.mj_fullM(physics.mj_model, data, inertia)
    coupling = float(np.max(np.abs(inertia) @ (amplitude * omega) / physics.gains_ki))
    bound = 2 * (coupling + sag) + float(amplitude.max()) / 2000.0
    assert worst <= bound, (worst, bound)
    # The default servo (100 times softer) does not track within that bound: the stiffness is what tracks.
    soft = MujocoPlant(model, q0, PhysicsConfig())
    kinematic = KinematicPlant(model, q0)
    for step in range(500):
        command = amplitude * math.sin(omega * step * dt)
        soft.step(command, dt)
        kinematic.step(command, dt)
    assert np.abs(soft.q - kinematic.q).max() > 2 * bound


def _box_at(position, size=0.1):
    pose = np.eye(4)
    pose[:3, 3] = position
    return make_obstacle(("test", 1), "box", (size, size, size), pose)


def test_a_box_in_the_path_stops_the_arm_with_contact_force_and_names_the_pair():
    q0 = GENOVA7.start_configuration()
    turned = q0.copy()
    turned[0] += 0.4
    box_centre = frame_pose(GENOVA7, turned, GENOVA7.dof)[:3, 3]  # where joint 7's frame will be
    efforts = (40.0,) * GENOVA7.dof
    plant = MujocoPlant(GENOVA7, q0, PhysicsConfig(effort_limits=efforts))
    scene = Scene()
    scene.add(_box_at(box_centre))
    assert plant.set_scene(scene) and not plant.set_scene(scene)  # rebuilt once per scene version
    command = np.zeros(GENOVA7.dof)
    command[0] = 0.5
    _run(plant, command, 1.2)  # 0.6 rad commanded, the box is at 0.4 rad minus its half size
    report = plant.take_contact()
    assert report is not None and report.force > 1.0
    assert report.obstacle == "test/1" and report.link in {j.link_name or j.name for j in GENOVA7.joints}
    assert plant.q[0] < q0[0] + 0.4  # stopped at the box
    assert abs(plant.effort_values[0]) <= 40.0 + 1e-9
    assert plant.take_contact() is None  # reported once
    scene.clear()
    plant.set_scene(scene)
    _run(plant, command, 0.3)
    assert plant.take_contact() is None and plant.q[0] > q0[0] + 0.4  # the way is free again


def _without_inertials(text, links=None):
    pattern = r"<inertial>.*?</inertial>"
    if links is None:
        return re.sub(pattern, "", text, flags=re.S)
    for link in links:
        text = re.sub(rf'(<link name="{link}">.*?)<inertial>.*?</inertial>', r"\1", text, count=1, flags=re.S)
    return text


def test_a_urdf_without_inertials_gets_the_documented_default_links():
    model = load_robot(str(PANDA_PATH))
    plant = MujocoPlant(model, model.start_configuration(), PhysicsConfig(), urdf_text=_without_inertials(PANDA_TEXT))
    assert any("no <inertial>" in note and "docs/physics.md" in note for note in plant.notes)
    lengths = [np.linalg.norm((model.joints[i + 1].origin if i + 1 < 7 else model.ee_offset)[:3, 3]) for i in range(7)]
    expected = sorted(max(DEFAULT_LINEAR_DENSITY * length, MIN_LINK_MASS) for length in lengths)
    masses = sorted(m for m in plant.mj_model.body_mass if m > 0)
    np.testing.assert_allclose(masses, expected, rtol=1e-6)


def test_a_moving_link_without_mass_in_a_urdf_with_inertials_is_an_error_naming_it():
    model = load_robot(str(PANDA_PATH))
    with pytest.raises(ModelFileError, match=r"link\[panda_link3\]/inertial.*plant:=kinematic"):
        MujocoPlant(
            model, model.start_configuration(), PhysicsConfig(), _without_inertials(PANDA_TEXT, ["panda_link3"])
        )


@settings(max_examples=25, deadline=None)
@given(
    commands=st.lists(
        st.lists(st.floats(-50.0, 50.0, allow_nan=False), min_size=7, max_size=7), min_size=1, max_size=6
    ),
    seconds=st.floats(0.0, 0.05),
)
def test_any_finite_commands_keep_the_physics_plant_finite_within_its_limits(commands, seconds):
    # Commands far above the velocity limits, reversing at random, into the joint limits: the state
    # stays finite, inside the position limits (MuJoCo's limits are soft: within 0.05), the drive
    # torques within the effort limits and the speeds near the velocity limits.
    plant = MujocoPlant(GENOVA7, GENOVA7.start_configuration(), PhysicsConfig(effort_limits=(30.0,) * 7))
    for command in commands:
        _run(plant, np.array(command), seconds + 0.001)
        assert np.all(np.isfinite(plant.q)) and np.all(np.isfinite(plant.qdot))
        assert np.all(np.isfinite(plant.ee)) and np.all(np.isfinite(plant.tool))
        assert np.all(plant.q >= GENOVA7.lower - 0.05) and np.all(plant.q <= GENOVA7.upper + 0.05)
        assert np.all(np.abs(plant.effort_values) <= 30.0 + 1e-9)
        assert plant.velocity_scale <= 1.0


def test_joint_states_with_effort_encode_as_rclpy_serialises_them():
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    from manip_kin.ros.wire.cdr import JointStateCdr

    data = JointStateCdr(["a", "bb", "c"], with_effort=True).encode_values(
        7_000_000_003, [1, 2, 3], [4, 5, 6], [7, 8, 9]
    )
    message = deserialize_message(data, JointState)
    assert list(message.name) == ["a", "bb", "c"] and message.header.stamp.nanosec == 3
    assert list(message.position) == [1, 2, 3] and list(message.velocity) == [4, 5, 6]
    assert list(message.effort) == [7, 8, 9]


def test_a_malformed_inertial_names_the_file_and_the_field():
    text = PANDA_TEXT.replace('<mass value="0.646926"/>', '<mass value="heavy"/>')
    model = load_robot(str(PANDA_PATH))
    with pytest.raises(ModelFileError, match=r"link\[panda_link2\]/inertial/mass@value.*'heavy' is not numeric"):
        MujocoPlant(model, model.start_configuration(), PhysicsConfig(), urdf_text=text)
