"""The controller's collision and posture parameters: every value within their ranges gives a QP
law that is refused cleanly or steps finite, within the velocity limits (hypothesis over the
ranges declared in manip_kin/ros/nodes/collision_params.py)."""

import numpy as np
from collision_robots import BALL_ARM_URDF
from hypothesis import given, settings
from hypothesis import strategies as st
from test_parameter_ranges import in_range

from manip_kin.collision.collision_model import load_collision_model
from manip_kin.collision.distances import CollisionChecker
from manip_kin.control.qp.law import QpConfig, QpController
from manip_kin.control.qp.tasks import PostureTask
from manip_kin.control.resolved_rate import ControllerConfig
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.rotations import make_transform
from manip_kin.core.scene import Scene, make_obstacle
from manip_kin.core.urdf import load_urdf_string
from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.nodes.collision_params import COLLISION_PARAMETERS

SPECS = {spec.name: spec for spec in COLLISION_PARAMETERS}
MODEL = load_urdf_string(BALL_ARM_URDF)
CHECKER = CollisionChecker(MODEL, load_collision_model(MODEL, BALL_ARM_URDF, samples=100))
Q0 = np.array([-0.6, 0.4, 0.8])
GOAL = frame_pose(MODEL, [0.6, 0.4, 0.8])
SCENE = Scene()
SCENE.add(
    make_obstacle(
        ("cell", 1), "sphere", (0.1,) * 3, make_transform(None, 0.5 * (frame_pose(MODEL, Q0)[:3, 3] + GOAL[:3, 3]))
    )
)
CHECKER.update_scene(SCENE)


@given(
    safety=in_range(SPECS["collision_safety_distance"]),
    influence=in_range(SPECS["collision_influence_distance"]),
    gain=in_range(SPECS["collision_gain"]),
    margin=in_range(SPECS["position_limit_margin"]),
    posture_gain=in_range(SPECS["posture_gain"]),
    weight=in_range(SPECS["posture_weight"]),
    reference=st.lists(in_range(SPECS["posture_reference"]), min_size=3, max_size=3),
)
@settings(max_examples=40, deadline=None)
def test_every_valid_collision_configuration_is_refused_cleanly_or_steps_finite(
    safety, influence, gain, margin, posture_gain, weight, reference
):
    controller = ControllerConfig(task="position", gain_linear=3.0)
    try:
        config = QpConfig(
            controller=controller,
            position_margin=margin,
            posture=PostureTask(np.array(reference), posture_gain, weight),
            collision_safety_distance=safety,
            influence_distance=influence,
            collision_gain=gain,
        )
        law = QpController(MODEL, config, CHECKER)
    except InvalidArgumentError as error:
        assert influence <= safety and "valid" in str(error)  # the one refusal: d_i not above d_s
        return
    q = Q0.copy()
    for _ in range(20):
        output = law.step(q, GOAL, dt=0.002)
        assert np.all(np.isfinite(output.qdot)) and np.all(np.abs(output.qdot) <= MODEL.velocity_limits + 1e-9)
        q = q + output.qdot * 0.002
