"""The collision and posture parameters of ``cartesian_controller`` and ``trajectory_generator``.

One table for both nodes where they share a name (the geometry, the safety distance), so the
generator's path check keeps the same clearance the controller keeps.
"""

from __future__ import annotations

from manip_kin.collision.pairs import DEFAULT_SAMPLES
from manip_kin.ros.runtime.params import ParamSpec

# A cell's clearances are centimetres; half a metre of safety distance or a metre of influence
# would keep any arm away from everything. 1 mm of influence is below a useful damper band.
SAFETY_DISTANCE = ParamSpec(
    "collision_safety_distance",
    "float",
    0.02,
    "closest allowed approach of any checked pair, link-link or link-obstacle (on the controller: below collision_influence_distance)",
    "m",
    minimum=0.0,
    maximum=0.5,
    tunable=True,
)
SRDF = ParamSpec("srdf", "str", "", "SRDF whose disable_collisions pairs are not checked ('' = pairs by sampling)")
MESH_SEARCH_PATH = ParamSpec(
    "mesh_search_path",
    "str",
    "",
    "':'-separated directories holding packages, for the URDF's package:// collision meshes (<dir>/P/...); "
    "then the ament index",
)

#: The controller's: collision avoidance, the posture task and the QP's position-limit margin.
COLLISION_PARAMETERS = (
    ParamSpec(
        "collision_avoidance",
        "bool",
        False,
        "keep the arm off itself and off collision_objects under every kind of command (the URDF's <collision> geometry; the QP law)",
    ),
    SAFETY_DISTANCE,
    ParamSpec(
        "collision_influence_distance",
        "float",
        0.10,
        "pairs nearer than this are slowed (velocity dampers); above collision_safety_distance",
        "m",
        minimum=1e-3,
        maximum=1.0,
        tunable=True,
    ),
    # 10 m/s of closing speed at the influence distance is beyond any arm; 1 mm/s barely moves.
    ParamSpec(
        "collision_gain",
        "float",
        0.5,
        "closing speed allowed at collision_influence_distance, falling to 0 at collision_safety_distance",
        "m/s",
        minimum=1e-3,
        maximum=10.0,
        tunable=True,
    ),
    SRDF,
    MESH_SEARCH_PATH,
    # Below 10 samples the 'never in contact' choice is a guess; 100000 takes minutes at start.
    ParamSpec(
        "collision_pair_samples",
        "int",
        DEFAULT_SAMPLES,
        "random configurations for choosing the checked pairs without an SRDF (seed 0)",
        minimum=10,
        maximum=100000,
    ),
    ParamSpec(
        "posture_reference",
        "float_list",
        None,
        "posture pursued in the null space of a redundant arm, model joint order (the QP law)",
        "rad | m",
        minimum=-1e4,  # as initial_positions: far beyond any joint's range, keeps the rates finite
        maximum=1e4,
        default_text="none: no posture task",
        tunable=True,
    ),
    # As the cartesian gains: K dt < 2 up to 2 kHz.
    ParamSpec(
        "posture_gain",
        "float",
        1.0,
        "how fast the self-motion pulls towards posture_reference",
        "1/s",
        minimum=0.0,
        maximum=1e3,
        tunable=True,
    ),
    # A weight scales the gain per joint; 100 x the gain is still within its bound's reach.
    ParamSpec(
        "posture_weight",
        "float",
        1.0,
        "weight of every joint in the posture task",
        minimum=0.0,
        maximum=100.0,
        tunable=True,
    ),
    # A metre or radian of margin leaves little range on most joints; a joint narrower than
    # twice the margin is held in its middle (manip_kin.control.qp.limits.PositionLimit).
    ParamSpec(
        "position_limit_margin",
        "float",
        0.02,
        "the QP law keeps this far from each joint's position limits (with collision_avoidance or a posture)",
        "rad | m",
        minimum=0.0,
        maximum=1.0,
        tunable=True,
    ),
)

#: The generator's: check lines and joint trajectories against the arm itself and collision_objects.
PATH_CHECK_PARAMETERS = (
    ParamSpec(
        "collision_check",
        "bool",
        False,
        "refuse a line or joint trajectory that passes through the arm itself or collision_objects "
        "(nearer than collision_safety_distance), saying where and which pair",
    ),
    SAFETY_DISTANCE,
    SRDF,
    MESH_SEARCH_PATH,
)
