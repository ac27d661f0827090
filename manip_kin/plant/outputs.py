"""What every plant reports after a step: poses and twists of the end effector and the tool.

Both plants (:class:`~manip_kin.plant.kinematic.KinematicPlant`,
:class:`~manip_kin.plant.mujoco_plant.MujocoPlant`) hold joint positions and velocities and
derive the same outputs from them with the model's unrolled kinematics (plain Python floats:
at this size a numpy call costs more than the arithmetic it saves). Arrays are offered as
properties for callers outside the loop.
"""

from __future__ import annotations

from operator import mul

import numpy as np

from manip_kin.core.kinematics import compiled_kinematics
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_jacobian import jacobian_row, pose_of


class ChainOutputs:
    """Poses and twists of a chain from its joint positions and velocities.

    Args:
        model: the robot.
        q0: start positions, shape (n,).

    Attributes:
        q_values: current positions [rad | m], n floats.
        qdot_values: current velocities [rad/s | m/s], n floats.
        effort_values: joint torques/forces [N·m | N], n floats; None for a plant without
            dynamics (the kinematic one).
        ee_values, tool_values: end-effector and tool poses in base, 16 row-major floats.
        ee_twist_values, tool_twist_values: ``(wx, wy, wz, vx, vy, vz)`` w.r.t. base in base
            [rad/s, m/s].
        velocity_scale: factor (<= 1) the last command was scaled by to respect the velocity limits.
    """

    effort_values: list[float] | None = None

    def __init__(self, model: RobotModel, q0: np.ndarray):
        self.model = model
        n = model.dof
        self._n = n
        self.q_values = [float(v) for v in q0]
        self.qdot_values = [0.0] * n
        self._lower = model.lower.tolist()
        self._upper = model.upper.tolist()
        self._inverse_velocity_limits = (1.0 / model.velocity_limits).tolist()
        self._tool_chain = compiled_kinematics(model, model.frame_index(model.default_frame), True)
        self._ee_chain = compiled_kinematics(model, model.dof + 1, False) if model.has_tool else None
        self.velocity_scale = 1.0
        self._update_kinematics()

    def _update_kinematics(self) -> None:
        n = self._n
        values = self._tool_chain(self.q_values)
        tool = pose_of(values)
        qdot = self.qdot_values
        # Twist of the tool (ee when no tool) = J q̇, J rows [angular; linear] after the pose.
        twist = [sum(map(mul, jacobian_row(values, n, r), qdot)) for r in range(6)]
        self.tool_values = tool
        self.tool_twist_values = twist
        if self._ee_chain is None:
            self.ee_values = tool
            self.ee_twist_values = twist
            return
        ee = self._ee_chain(self.q_values)
        self.ee_values = ee
        # Same rigid body: v_ee = v_tool + ω × (p_ee - p_tool).
        wx, wy, wz, vx, vy, vz = twist
        rx, ry, rz = ee[3] - tool[3], ee[7] - tool[7], ee[11] - tool[11]
        self.ee_twist_values = [wx, wy, wz, vx + wy * rz - wz * ry, vy + wz * rx - wx * rz, vz + wx * ry - wy * rx]

    # --- arrays for callers outside the loop ---------------------------------------------------

    @property
    def q(self) -> np.ndarray:
        """Current positions, shape (n,)."""
        return np.array(self.q_values)

    @property
    def qdot(self) -> np.ndarray:
        """Current velocities, shape (n,)."""
        return np.array(self.qdot_values)

    @property
    def ee(self) -> np.ndarray:
        """End-effector pose in base, shape (4, 4)."""
        return np.array(self.ee_values).reshape(4, 4)

    @property
    def tool(self) -> np.ndarray:
        """Tool pose in base (the end effector when there is no tool), shape (4, 4)."""
        return np.array(self.tool_values).reshape(4, 4)

    @property
    def ee_twist(self) -> tuple[np.ndarray, np.ndarray]:
        """``(angular, linear)`` of the end effector, each shape (3,)."""
        return np.array(self.ee_twist_values[:3]), np.array(self.ee_twist_values[3:])

    @property
    def tool_twist(self) -> tuple[np.ndarray, np.ndarray]:
        """``(angular, linear)`` of the tool, each shape (3,)."""
        return np.array(self.tool_twist_values[:3]), np.array(self.tool_twist_values[3:])

    @property
    def at_limit(self) -> np.ndarray:
        """Joints on a position limit, shape (n,) bool."""
        q = self.q_values
        return np.array([q[i] <= self._lower[i] or q[i] >= self._upper[i] for i in range(self._n)])
