"""Tasks: what the QP's cost asks of the joint rates.

The cost is ``½ (q̇ - q̇*)ᵀ H (q̇ - q̇*)``: the distance, in the pose task's metric, to the
rates ``q̇*`` the tasks ask for with no limit in the way.

* :class:`PoseTask` gives ``q̇* = Jᵀ(J Jᵀ + λ² I)⁻¹ v*`` exactly as today's law
  (:meth:`manip_kin.control.resolved_rate.CartesianController.step` without its limit handling: same
  gains, task rows, feed-forward and damping rule) and ``H = JᵀJ + μ I``, ``μ = max(λ², μ_min)``.
  With μ = λ² the cost is ``½‖J q̇ − v*‖² + ½ λ²‖q̇‖²`` up to a constant, so with no limit
  active the QP's answer *is* today's law.
* :class:`PostureTask` adds ``N z`` to ``q̇*``, with ``z = K w ⊙ (q_ref − q)`` and
  ``N = I − Jᵀ(J Jᵀ + λ² I)⁻¹ J`` (the null-space projector of the damped pseudo-inverse):
  the minimiser of ``‖J q̇ − v*‖² + λ²‖q̇ − z‖²``, so the posture moves only the joints' self-motion
  and never disturbs the pose task. For arms with no redundancy (n <= task rows) it does nothing.
* :class:`JointTask`, for joint references and jogs instead of a pose goal: ``q̇* = q̇_ref + K (q_ref − q)``,
  the joint tracking law (:func:`manip_kin.control.joint_tracking.joint_tracking_step` without its
  limit handling), and ``H = I``: the QP finds the rates nearest to it in joint space, so with
  no limit active its answer *is* the joint tracking law.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from manip_kin.control.joint_tracking import JointTrackingOutput, joint_tracking_step
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig, ControlOutput
from manip_kin.core.kinematics import compiled_kinematics
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_jacobian import jacobian_of
from manip_kin.errors import InvalidArgumentError


@dataclass(frozen=True)
class PoseTask:
    """The pose of the controlled frame, through today's law (see the module docstring).

    Attributes:
        model: the robot.
        config: gains, frame, task rows, damping (its limit switches are ignored: limits are
            the QP's :mod:`~manip_kin.control.qp.limits`).
    """

    model: RobotModel
    config: ControllerConfig = ControllerConfig()
    law: CartesianController = field(init=False, repr=False, compare=False)
    _row_index: np.ndarray | None = field(init=False, repr=False, compare=False)
    _chain: object = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        unlimited = replace(self.config, respect_position_limits=False, respect_velocity_limits=False)
        object.__setattr__(self, "law", CartesianController(self.model, unlimited))
        rows = list(self.law.task.rows)
        # All six rows: the Jacobian as it is (a fancy index would copy it).
        object.__setattr__(self, "_row_index", None if rows == list(range(6)) else np.array(rows))
        object.__setattr__(self, "_chain", compiled_kinematics(self.model, self.law.frame_index, True))

    @property
    def rows(self) -> tuple[int, ...]:
        """The task rows of ``[rx, ry, rz, x, y, z]``."""
        return self.law.task.rows

    def desired(self, q: np.ndarray, goal_pose: np.ndarray, goal_twist, dt: float) -> ControlOutput:
        """Today's law without limits at ``q``: ``qdot`` is ``q̇*``, ``damping`` λ."""
        return self.law.step(q, goal_pose, goal_twist, dt)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """The task rows of the controlled frame's geometric Jacobian, shape (m, n)."""
        jacobian = jacobian_of(self._chain(q.tolist()), self.model.dof)
        return jacobian if self._row_index is None else jacobian[self._row_index]


@dataclass(frozen=True)
class PostureTask:
    """A joint reference pursued in the pose task's null space.

    Attributes:
        reference: the posture q_ref, shape (n,) [rad | m].
        gain: K [1/s], >= 0: how fast the self-motion pulls towards it.
        weight: per joint, >= 0 [1], shape (n,) (a scalar for all joints).
    """

    reference: np.ndarray
    gain: float = 1.0
    weight: np.ndarray | float = 1.0

    def __post_init__(self):
        reference = np.array(self.reference, dtype=float).reshape(-1)
        if not np.all(np.isfinite(reference)):
            raise InvalidArgumentError(f"posture reference {reference.tolist()}; valid: finite joint values")
        weight = np.broadcast_to(np.array(self.weight, dtype=float), reference.shape).copy()
        if not np.all(np.isfinite(weight)) or np.any(weight < 0):
            raise InvalidArgumentError(f"posture weight {weight.tolist()}; valid: values >= 0, one per joint")
        if not (math.isfinite(self.gain) and self.gain >= 0):
            raise InvalidArgumentError(f"posture gain {self.gain!r}; valid: a finite rate >= 0 [1/s]")
        for array in (reference, weight):
            array.setflags(write=False)
        object.__setattr__(self, "reference", reference)
        object.__setattr__(self, "weight", weight)

    def velocity(self, q: np.ndarray) -> np.ndarray:
        """``z = K w ⊙ (q_ref − q)``, shape (n,)."""
        return self.gain * self.weight * (self.reference - q)

    def null_space_rates(self, q: np.ndarray, jacobian: np.ndarray, damping: float) -> np.ndarray:
        """``N z``: the posture rates with their effect on the pose task removed, shape (n,)."""
        z = self.velocity(q)
        m, n = jacobian.shape
        if n <= m:
            return np.zeros(n)
        gram = jacobian @ jacobian.T + damping * damping * np.eye(m)
        return z - jacobian.T @ np.linalg.solve(gram, jacobian @ z)


@dataclass(frozen=True)
class JointTask:
    """A joint reference followed directly (no pose goal): the joint tracking law as the cost.

    Attributes:
        model: the robot.
        gain: K [1/s], >= 0 (``gain_joint``): a constant offset decays as ``exp(−K t)``.
    """

    model: RobotModel
    gain: float = 1.0

    def __post_init__(self):
        if not (isinstance(self.gain, (int, float)) and math.isfinite(self.gain) and self.gain >= 0):
            raise InvalidArgumentError(f"joint gain {self.gain!r}; valid: a finite rate >= 0 [1/s]")

    def desired(
        self, q: np.ndarray, q_reference: np.ndarray, qdot_reference: np.ndarray | None, dt: float
    ) -> JointTrackingOutput:
        """The joint tracking law without limits at ``q``: ``qdot`` is ``q̇*``, shape (n,) [rad/s | m/s].

        Args:
            q, q_reference: joint positions and their reference, shapes (n,) [rad | m].
            qdot_reference: the reference's velocity (feed-forward), shape (n,), or None (zero).
            dt: control period [s], > 0.

        Raises:
            InputError: as :func:`~manip_kin.control.joint_tracking.joint_tracking_step` for bad input.
        """
        # The limits are the QP's: the law's own clipping and scaling stay off.
        return joint_tracking_step(self.model, q, q_reference, qdot_reference, self.gain, dt, False, False)
