"""One import for the node plumbing's message helpers, which live in a module per job.

* :mod:`manip_kin.nodes.messages`: ROS messages <-> numpy (stamps, poses, twists, joints);
* :mod:`manip_kin.nodes.validation`: the checks applied to every input, with reasons;
* :mod:`manip_kin.nodes.diagnostics`: ``/diagnostics`` status builders;
* :mod:`manip_kin.nodes.cdr`: pre-serialised outputs and byte decoders of the 1 kHz loops.

``from manip_kin.nodes import conversions as conv`` then ``conv.pose_problem(...)`` keeps
working; new code may import from the job modules directly.
"""

from manip_kin.nodes.cdr import (
    DecodedPoseStamped,
    Float64ArrayCdr,
    JointStateCdr,
    JointStateDecoder,
    PoseStampedCdr,
    TwistStampedCdr,
    decode_float64_array,
    decode_pose_stamped,
    quaternion_of_pose_values,
)
from manip_kin.nodes.diagnostics import (
    DIAGNOSTIC_LEVELS,
    diagnostic_values,
    make_diagnostic_array,
    make_diagnostic_status,
)
from manip_kin.nodes.messages import (
    array_to_multiarray,
    fill_joint_state,
    fill_pose,
    fill_pose_stamped,
    fill_twist_stamped,
    make_joint_state,
    make_pose_stamped,
    make_twist_stamped,
    multiarray_to_array,
    ns_to_stamp,
    pose_stamped_to_matrix,
    pose_to_matrix,
    quaternion_to_matrix,
    stamp_key,
    stamp_key_to_ns,
    stamp_to_ns,
    stamp_to_seconds,
    to_double_array,
    twist_to_arrays,
)
from manip_kin.nodes.validation import (
    QUATERNION_TOLERANCE,
    InvalidMessageError,
    JointStateMapper,
    check_command,
    check_pose_stamped,
    command_problem,
    frame_problem,
    pose_problem,
    problem_kind,
    twist_problem,
)

__all__ = [
    "DIAGNOSTIC_LEVELS",
    "DecodedPoseStamped",
    "QUATERNION_TOLERANCE",
    "Float64ArrayCdr",
    "InvalidMessageError",
    "JointStateCdr",
    "JointStateDecoder",
    "JointStateMapper",
    "PoseStampedCdr",
    "TwistStampedCdr",
    "array_to_multiarray",
    "check_command",
    "check_pose_stamped",
    "command_problem",
    "decode_float64_array",
    "decode_pose_stamped",
    "diagnostic_values",
    "fill_joint_state",
    "fill_pose",
    "fill_pose_stamped",
    "fill_twist_stamped",
    "frame_problem",
    "make_diagnostic_array",
    "make_diagnostic_status",
    "make_joint_state",
    "make_pose_stamped",
    "make_twist_stamped",
    "multiarray_to_array",
    "ns_to_stamp",
    "pose_problem",
    "pose_stamped_to_matrix",
    "pose_to_matrix",
    "problem_kind",
    "quaternion_of_pose_values",
    "quaternion_to_matrix",
    "stamp_key",
    "stamp_key_to_ns",
    "stamp_to_ns",
    "stamp_to_seconds",
    "to_double_array",
    "twist_problem",
    "twist_to_arrays",
]
