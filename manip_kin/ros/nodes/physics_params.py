"""robot_state's plant parameters (``plant`` and the MuJoCo plant's settings) and the plant they make."""

from __future__ import annotations

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.plant import PLANT_NAMES, KinematicPlant
from manip_kin.ros.runtime.param_struct import ParamStruct
from manip_kin.ros.runtime.params import ParamSpec

PHYSICS_PARAMETERS = (
    ParamSpec(
        "plant",
        "str",
        "kinematic",
        "what the command drives: a perfect integrator, or MuJoCo physics (gravity, servos, contact)",
        choices=PLANT_NAMES,
    ),
    # MuJoCo's stability wants a step of a millisecond or so; 20 kHz is more than any arm needs.
    ParamSpec("physics_rate_hz", "float", 1000.0, "MuJoCo step rate (plant mujoco)", "Hz", minimum=100.0, maximum=2e4),
    ParamSpec(
        "servo_velocity_gain",
        "float",
        200.0,
        "velocity servo's proportional gain per unit joint inertia (plant mujoco; 1/time constant)",
        "1/s",
        minimum=1e-3,
        maximum=1e5,  # a 10 µs time constant: beyond any drive, and beyond what a 1 kHz step resolves
    ),
    ParamSpec(
        "servo_integral_gain",
        "float",
        10000.0,
        "velocity servo's integral gain per unit joint inertia (plant mujoco; gain²/4: critically damped)",
        "1/s^2",
        minimum=0.0,
        maximum=1e10,  # the critical value of the largest proportional gain
    ),
    # Physical magnitudes of a robot's joints, with room: beyond these the numbers mean nothing.
    ParamSpec(
        "joint_damping",
        "float",
        0.0,
        "viscous joint damping (plant mujoco)",
        "N·m·s/rad | N·s/m",
        minimum=0.0,
        maximum=1e6,
    ),
    ParamSpec(
        "joint_armature",
        "float",
        0.0,
        "reflected rotor inertia per joint (plant mujoco)",
        "kg·m² | kg",
        minimum=0.0,
        maximum=1e3,
    ),
    ParamSpec(
        "joint_friction",
        "float",
        0.0,
        "dry friction loss per joint (plant mujoco)",
        "N·m | N",
        minimum=0.0,
        maximum=1e6,
    ),
    ParamSpec(
        "effort_limits",
        "float_list",
        None,
        "servo torque/force limit per joint, model joint order (plant mujoco)",
        "N·m | N",
        minimum=1e-3,
        maximum=1e6,
        default_text="the URDF's <limit effort>; unlimited where none is given",
    ),
    ParamSpec(
        "mesh_search_path",
        "str",
        "",
        "':'-separated directories holding packages, for package:// meshes (<dir>/P/...); "
        "then the ament index (plant mujoco)",
    ),
)


def make_plant(model: RobotModel, q0: np.ndarray, params: ParamStruct, urdf_text: str | None):
    """The plant ``params.plant`` names, at ``q0``; ``urdf_text``: the URDF the model came from, or None.

    Raises:
        ModelFileError: the URDF's inertials or collision shapes (plant mujoco).
        InputError: bad effort limits.
    """
    if params.plant == "kinematic":
        return KinematicPlant(model, q0)
    from manip_kin.plant.mujoco_model import JointDynamics
    from manip_kin.plant.mujoco_plant import MujocoPlant, PhysicsConfig, ServoGains

    efforts = params.effort_limits
    config = PhysicsConfig(
        rate_hz=params.physics_rate_hz,
        dynamics=JointDynamics(params.joint_damping, params.joint_armature, params.joint_friction),
        servo=ServoGains(params.servo_velocity_gain, params.servo_integral_gain),
        effort_limits=tuple(efforts) if efforts else None,
        mesh_search_path=params.mesh_search_path,
    )
    return MujocoPlant(model, q0, config, urdf_text)
