"""The kinematic plant: a perfect integrator of joint-rate commands within the limits."""

from __future__ import annotations

import numpy as np

from manip_kin.control.integration import integrate_joint_rates
from manip_kin.plant.outputs import ChainOutputs


class KinematicPlant(ChainOutputs):
    """Joint positions integrated from velocity commands within the limits (plain Python floats).

    The command is the joint velocity, at once and exactly; a command above a velocity limit
    is scaled down as a whole, a joint on a position limit stops there. ``qdot_values`` is
    the velocity of the last step: the commanded rate after limiting, zero for a joint
    stopped at a position limit. See :class:`~manip_kin.plant.outputs.ChainOutputs` for the
    outputs.

    Args:
        model: the robot.
        q0: start positions, shape (n,), inside the limits.
    """

    name = "kinematic"

    def step(self, command: np.ndarray | None, dt: float) -> None:
        """Advance by ``dt`` seconds with joint rates ``command`` (None: zero), shape (n,)."""
        n = self._n
        if command is None or not dt >= 1e-9:  # below the clock's resolution: no step (1/dt would overflow)
            if self.velocity_scale == 1.0 and not any(self.qdot_values):
                return  # at rest and still at rest: poses unchanged, twists zero
            self.qdot_values = [0.0] * n
            self.velocity_scale = 1.0
        else:
            self.q_values, self.qdot_values, self.velocity_scale, _ = integrate_joint_rates(
                self.q_values, command.tolist(), dt, self._lower, self._upper, self._inverse_velocity_limits
            )
        self._update_kinematics()

    def set_scene(self, scene) -> None:
        """Obstacles do not touch a kinematic arm (nothing to do; see the mujoco plant)."""

    def take_contact(self):
        """No contact in a kinematic plant: always None."""
        return None
