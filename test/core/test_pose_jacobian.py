"""Named access to a compiled chain's flat values (manip_kin.core.pose_jacobian)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.core.kinematics import compiled_kinematics, frame_pose, jacobian
from manip_kin.core.pose_jacobian import jacobian_entry, jacobian_of, jacobian_row, pose_of, zero_joint_column
from manip_kin.core.robots import load_robot

MODEL = load_robot("genova7")
INDEX = MODEL.frame_index(MODEL.default_frame)
CHAIN = compiled_kinematics(MODEL, INDEX, True)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7))
def test_the_values_are_the_pose_and_the_jacobian(fraction):
    q = MODEL.lower + (np.array(fraction) + 1.0) / 2.0 * (MODEL.upper - MODEL.lower)
    values = CHAIN(q.tolist())
    expected = jacobian(MODEL, q)
    matrix = np.vstack([expected.angular, expected.linear])  # rows [angular; linear]
    np.testing.assert_allclose(np.reshape(pose_of(values), (4, 4)), frame_pose(MODEL, q), atol=1e-12)
    np.testing.assert_allclose(jacobian_of(values, 7), matrix, atol=1e-12)
    for row in range(6):
        np.testing.assert_allclose(jacobian_row(values, 7, row), matrix[row], atol=1e-12)
        for joint in range(7):
            assert values[jacobian_entry(7, row, joint)] == jacobian_of(values, 7)[row, joint]
    held = list(values)
    zero_joint_column(held, 7, 3)
    changed = jacobian_of(held, 7)
    np.testing.assert_array_equal(changed[:, 3], 0.0)
    np.testing.assert_array_equal(np.delete(changed, 3, axis=1), np.delete(jacobian_of(values, 7), 3, axis=1))
    assert held[:16] == list(values[:16])
