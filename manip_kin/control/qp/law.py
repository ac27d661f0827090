"""The collision-aware law: tasks and limits solved as one small QP per cycle.

Per cycle (:meth:`QpController.step` for a pose goal, :meth:`QpController.joint_step` for a
joint reference or a jog):

1. the tasks give the rates ``q̇*`` they ask for and the metric ``H``
   (:mod:`manip_kin.control.qp.tasks`): today's cartesian law, plus the null-space posture if
   any, in the pose task's metric; or the joint tracking law, in the joint-space metric ``H = I``;
2. the box limits give ``lower <= q̇ <= upper`` and the collision limit its damper rows
   ``A q̇ <= b`` (:mod:`manip_kin.control.qp.limits`);
3. if ``q̇*`` satisfies them all, it is the answer (no solve: the usual case away from
   limits and obstacles, and the reason the QP equals today's law there); otherwise daqp
   solves ``min ½ (q̇ − q̇*)ᵀ H (q̇ − q̇*)`` under them: the arm slows as it approaches an
   obstacle and slides along it where the task allows;
4. if the QP is infeasible or the solver fails, today's law
   (:meth:`manip_kin.control.resolved_rate.CartesianController.step`, or
   :func:`manip_kin.control.joint_tracking.joint_tracking_step`, with its own position and velocity
   limits) is the fallback, scaled down so it does not close any damped pair faster than the
   damper allows (not at all on a pair already inside the safety distance). Fallbacks are
   counted (:attr:`QpController.fallback_count`) and flagged in the output.

The controller keeps one piece of state: the previous command, for the acceleration limit
(:meth:`QpController.reset` sets it, e.g. to zero when the arm is known to be at rest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from manip_kin.collision.distances import CollisionChecker
from manip_kin.collision.pair_distance import DamperRows
from manip_kin.control.command_filter import FilterState
from manip_kin.control.joint_limits import JointLimits
from manip_kin.control.joint_tracking import JointTrackingOutput, joint_tracking_step
from manip_kin.control.qp.limits import (
    AccelerationLimit,
    Box,
    CollisionLimit,
    PositionLimit,
    VelocityLimit,
    merge_boxes,
)
from manip_kin.control.qp.solver import SolveStatus, solve_qp
from manip_kin.control.qp.tasks import JointTask, PoseTask, PostureTask
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig, ControlOutput
from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError

#: A constraint counts as active within this of its bound [rad/s | m/s].
ACTIVE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class QpConfig:
    """Parameters of :class:`QpController`.

    Attributes:
        controller: gains, frame, task rows and damping of the pose task (today's law; its
            limit switches also select the position and velocity limits here).
        position_margin: kept from each position limit [rad | m].
        position_gain: how fast a joint may approach its (shrunk) limit [1/s].
        max_acceleration: per joint (or one value) [rad/s² | m/s²], or None for no limit.
        posture: the null-space posture task, or None.
        collision_safety_distance: d_s, the closest allowed approach [m].
        influence_distance: d_i, pairs nearer than this are damped [m].
        collision_gain: ξ, the closing speed allowed at d_i [m/s].
        regularization: μ_min, the least weight on joint-rate changes in the QP's metric
            (H = JᵀJ + max(λ², μ_min) I) [same units as JᵀJ], > 0.
        braking: the limits of the command filter the rates pass through, or None: the
            dampers then count each pair's closing while the filter stops (see
            :class:`~manip_kin.control.qp.limits.CollisionLimit`).
    """

    controller: ControllerConfig = ControllerConfig()
    position_margin: float = 0.02
    position_gain: float = 5.0
    max_acceleration: float | tuple[float, ...] | None = None
    posture: PostureTask | None = None
    collision_safety_distance: float = 0.02
    influence_distance: float = 0.10
    collision_gain: float = 0.5
    regularization: float = 1e-4
    braking: JointLimits | None = None

    def __post_init__(self):
        if not (math.isfinite(self.regularization) and self.regularization > 0):
            raise InvalidArgumentError(f"regularization = {self.regularization!r}; valid: a finite number > 0")


@dataclass(frozen=True, kw_only=True)
class QpReport:
    """What the QP saw in one cycle (the part of :class:`QpOutput` and :class:`QpJointOutput` they share).

    Attributes:
        nearest_pair: the nearest pair within the influence distance, or None.
        nearest_distance: its distance [m] (inf when none).
        active_constraints: the binding constraints, e.g. ``collision:panda_hand-obstacle:cell/1``,
            ``position:panda_joint4``, ``velocity:panda_joint1``, ``acceleration:panda_joint2``.
        fallback: True when today's law was used because the QP was infeasible or failed.
        fallback_count: fallbacks of this controller so far.
        status: how the rates were found (see :class:`~manip_kin.control.qp.solver.SolveStatus`).
    """

    nearest_pair: tuple[str, str] | None = None
    nearest_distance: float = math.inf
    active_constraints: tuple[str, ...] = ()
    fallback: bool = False
    fallback_count: int = 0
    status: SolveStatus = SolveStatus.UNCONSTRAINED

    @property
    def active_collision_pairs(self) -> tuple[str, ...]:
        """The ``first-second`` labels of the binding collision constraints."""
        return tuple(name.partition(":")[2] for name in self.active_constraints if name.startswith("collision:"))


@dataclass(frozen=True)
class QpOutput(ControlOutput, QpReport):
    """A pose step: a :class:`~manip_kin.control.resolved_rate.ControlOutput` with what the QP saw
    (:class:`QpReport`)."""


@dataclass(frozen=True)
class QpJointOutput(JointTrackingOutput, QpReport):
    """A joint step: a :class:`~manip_kin.control.joint_tracking.JointTrackingOutput` with what the QP
    saw (:class:`QpReport`); ``limited_joints`` are those held by the QP's position limit."""

    @property
    def joint_error_norm(self) -> float:
        """``‖q_ref − q‖``, the distance to the reference in joint space [rad | m]."""
        return float(math.sqrt(float(self.joint_error @ self.joint_error)))


@dataclass(frozen=True)
class _Bounds:
    """One cycle's limits: the merged box, the acceleration box in it (or None), the damper rows."""

    box: Box
    acceleration: Box | None
    rows: DamperRows | None


class QpController:
    """Tasks and limits as one QP per cycle (see the module docstring).

    Args:
        model: the robot.
        config: the parameters.
        checker: the robot's :class:`~manip_kin.collision.distances.CollisionChecker`, or None
            for no collision avoidance (then only the joint limits and posture differ from
            today's law).
    """

    def __init__(self, model: RobotModel, config: QpConfig = QpConfig(), checker: CollisionChecker | None = None):
        self.model = model
        self.config = config
        self.pose_task = PoseTask(model, config.controller)
        self.posture = config.posture
        if self.posture is not None and self.posture.reference.shape != (model.dof,):
            raise InvalidArgumentError(
                f"posture reference has {self.posture.reference.shape[0]} values; the robot has {model.dof} joints"
            )
        # Velocity first: on a conflict it wins over the position limit, both over acceleration.
        self.safety_limits = []
        if config.controller.respect_velocity_limits:
            self.safety_limits.append(VelocityLimit.of(model))
        if config.controller.respect_position_limits:
            self.safety_limits.append(PositionLimit.of(model, config.position_margin, config.position_gain))
        self.acceleration_limit = (
            AccelerationLimit.of(model, config.max_acceleration) if config.max_acceleration is not None else None
        )
        self.collision_limit = (
            CollisionLimit(
                checker,
                config.collision_safety_distance,
                config.influence_distance,
                config.collision_gain,
                config.braking,
            )
            if checker is not None
            else None
        )
        self.fallback_law = CartesianController(model, config.controller)
        self.fallback_count = 0
        self._previous = np.zeros(model.dof)
        self._names = model.joint_names
        self._unbounded = Box(np.full(model.dof, -math.inf), np.full(model.dof, math.inf))
        self._identity = np.eye(model.dof)
        self._joint_task: JointTask | None = None

    def reset(self, qdot: np.ndarray | None = None) -> None:
        """Set the previous command the acceleration limit starts from (default: at rest)."""
        self._previous = np.zeros(self.model.dof) if qdot is None else np.array(qdot, dtype=float)

    def limits_box(self, q: np.ndarray, dt: float) -> tuple[Box, Box | None]:
        """The merged box of the safety limits (velocity, position) and the acceleration box."""
        box = self._unbounded
        for limit in self.safety_limits:
            # Within the unbounded box a limit's box is itself: no merge for the first.
            bounds = limit.box(q, dt, self._previous)
            box = bounds if box is self._unbounded else merge_boxes(box, bounds)
        acceleration = None
        if self.acceleration_limit is not None:
            acceleration = self.acceleration_limit.box(q, dt, self._previous)
            box = merge_boxes(box, acceleration)
        return box, acceleration

    def step(
        self,
        q: np.ndarray,
        goal_pose: np.ndarray,
        goal_twist=None,
        dt: float = 0.002,
        command: FilterState | None = None,
    ) -> QpOutput:
        """Joint rates towards ``goal_pose`` within every limit.

        Args:
            q: joint positions, shape (n,) [rad | m].
            goal_pose: goal of the controlled frame in base, shape (4, 4).
            goal_twist: optional feed-forward ``(angular [rad/s], linear [m/s])``.
            dt: control period [s], > 0.
            command: the command filter's command in force (with ``config.braking``), or None.

        Raises:
            InputError: as :meth:`manip_kin.control.resolved_rate.CartesianController.step` for bad input.
        """
        task = self.pose_task.desired(q, goal_pose, goal_twist, dt)  # checks q, goal, twist and dt
        q = np.asarray(q, dtype=float)
        desired = task.qdot
        jacobian = None
        if self.posture is not None:
            jacobian = self.pose_task.jacobian(q)
            desired = desired + self.posture.null_space_rates(q, jacobian, task.damping)

        def metric() -> np.ndarray:
            task_jacobian = self.pose_task.jacobian(q) if jacobian is None else jacobian
            mu = max(task.damping * task.damping, self.config.regularization)
            return task_jacobian.T @ task_jacobian + mu * self._identity

        qdot, status, bounds = self._solve(q, dt, desired, metric, command)
        extra = {}
        if qdot is None:
            task = self.fallback_law.step(q, goal_pose, goal_twist, dt)  # today's law, with its limits
            qdot, extra = self._damped(task.qdot, bounds.rows), self._fallen_back(task)
            bounds = _Bounds(self._unbounded, None, bounds.rows)
        report = self._report(qdot, status, bounds, **extra)
        return QpOutput(
            qdot=qdot,
            orientation_error=task.orientation_error,
            position_error=task.position_error,
            manipulability=task.manipulability,
            damping=task.damping,
            singular=task.singular,
            **report,
        )

    def joint_step(
        self,
        q: np.ndarray,
        q_reference: np.ndarray,
        qdot_reference: np.ndarray | None = None,
        gain: float = 1.0,
        dt: float = 0.002,
        command: FilterState | None = None,
    ) -> QpJointOutput:
        """Joint rates towards a joint reference within every limit: ``min ‖q̇ − q̇*‖²`` with
        ``q̇* = q̇_ref + K (q_ref − q)`` (:class:`~manip_kin.control.qp.tasks.JointTask`); the
        posture task, if any, does not apply (the reference fixes every joint).

        Args:
            q, q_reference: joint positions and the reference, shapes (n,) [rad | m].
            qdot_reference: the reference's velocity (feed-forward), shape (n,), or None (zero).
            gain: K [1/s], >= 0.
            dt: control period [s], > 0.
            command: as for :meth:`step`.

        Raises:
            InputError: as :func:`~manip_kin.control.joint_tracking.joint_tracking_step` for bad input,
                or a gain that is not a finite rate >= 0.
        """
        if self._joint_task is None or self._joint_task.gain != gain:
            self._joint_task = JointTask(self.model, gain)
        task = self._joint_task.desired(q, q_reference, qdot_reference, dt)  # checks q, the reference, dt
        q = np.asarray(q, dtype=float)
        qdot, status, bounds = self._solve(q, dt, task.qdot, lambda: self._identity, command)
        extra = {}
        if qdot is None:
            config = self.config.controller
            law = joint_tracking_step(  # today's joint law, with its limits
                self.model,
                q,
                q_reference,
                qdot_reference,
                gain,
                dt,
                config.respect_position_limits,
                config.respect_velocity_limits,
            )
            qdot, extra = self._damped(law.qdot, bounds.rows), self._fallen_back(law)
            bounds = _Bounds(self._unbounded, None, bounds.rows)
        return QpJointOutput(qdot=qdot, joint_error=task.joint_error, **self._report(qdot, status, bounds, **extra))

    def _solve(
        self, q: np.ndarray, dt: float, desired: np.ndarray, metric, command: FilterState | None
    ) -> tuple[np.ndarray | None, SolveStatus, _Bounds]:
        """The rates nearest ``desired`` in the metric ``metric()`` (called only when a limit
        binds) within this cycle's limits; None when the QP is infeasible or the solver fails."""
        box, acceleration = self.limits_box(q, dt)
        rows = self.collision_limit.rows(q, command) if self.collision_limit is not None else None
        bounds = _Bounds(box, acceleration, rows)
        matrix = rows.matrix if rows is not None else None
        bound = rows.bound if rows is not None else None
        if self._satisfies(desired, box, matrix, bound):
            return desired, SolveStatus.UNCONSTRAINED, bounds
        hessian = metric()
        solution = solve_qp(hessian, -hessian @ desired, box.lower, box.upper, matrix, bound)
        return solution.x, solution.status, bounds

    @staticmethod
    def _satisfies(qdot: np.ndarray, box: Box, matrix, bound) -> bool:
        # The ufunc's own reduce: ndarray.min's Python wrapper costs as much again on 7 values.
        # A NaN fails every comparison, so it never passes.
        smallest = np.minimum.reduce
        if not (smallest(qdot - box.lower) >= -ACTIVE_TOLERANCE and smallest(box.upper - qdot) >= -ACTIVE_TOLERANCE):
            return False
        return matrix is None or not len(matrix) or bool(smallest(bound - matrix @ qdot) >= -ACTIVE_TOLERANCE)

    def _active(self, qdot: np.ndarray, bounds: _Bounds) -> tuple[tuple[str, ...], tuple[int, ...]]:
        """Names of the binding constraints, and the joints held by a position limit."""
        box, acceleration, rows = bounds.box, bounds.acceleration, bounds.rows
        names: list[str] = []
        at_bound = (qdot <= box.lower + ACTIVE_TOLERANCE) | (qdot >= box.upper - ACTIVE_TOLERANCE)
        held: list[int] = []
        for j in np.flatnonzero(at_bound).tolist():
            value = qdot[j]
            if acceleration is not None and (
                abs(value - acceleration.lower[j]) <= ACTIVE_TOLERANCE
                or abs(value - acceleration.upper[j]) <= ACTIVE_TOLERANCE
            ):
                names.append(f"acceleration:{self._names[j]}")
            elif abs(abs(value) - self.model.velocity_limits[j]) <= ACTIVE_TOLERANCE:
                names.append(f"velocity:{self._names[j]}")
            else:
                names.append(f"position:{self._names[j]}")
                held.append(j)
        if rows is not None and len(rows.labels):
            binding = (rows.matrix @ qdot >= rows.bound - 1e-7).tolist()
            names += [f"collision:{label}" for label, on in zip(rows.labels, binding) if on]
        return tuple(names), tuple(held)

    def _report(self, qdot: np.ndarray, status: SolveStatus, bounds: _Bounds, **extra) -> dict:
        """The fields an output shares (:class:`QpReport`, ``velocity_scale``, ``limited_joints``);
        keeps ``qdot`` as the previous command."""
        # Unconstrained: the tasks' own rates satisfied every limit, so none binds.
        active, held = ((), ()) if status is SolveStatus.UNCONSTRAINED else self._active(qdot, bounds)
        self._previous = qdot
        nearest = bounds.rows.nearest if bounds.rows is not None else None
        return {
            "velocity_scale": 1.0,
            "limited_joints": held,
            "nearest_pair": nearest.pair if nearest is not None else None,
            "nearest_distance": nearest.distance if nearest is not None else math.inf,
            "active_constraints": active,
            "fallback_count": self.fallback_count,
            "status": status,
            **extra,
        }

    def _fallen_back(self, law) -> dict:
        """Count a fallback to today's ``law`` output; the fields it sets in the output."""
        self.fallback_count += 1
        return {"fallback": True, "velocity_scale": law.velocity_scale, "limited_joints": law.limited_joints}

    @staticmethod
    def _damped(qdot: np.ndarray, rows: DamperRows | None) -> np.ndarray:
        """``qdot`` scaled so no damped pair closes faster than its damper allows."""
        if rows is not None and len(rows.labels):
            speeds = rows.matrix @ qdot
            allowed = np.maximum(rows.bound, 0.0)
            closing = speeds > allowed
            if np.any(closing):
                qdot = qdot * float(np.min(allowed[closing] / speeds[closing]))
        return qdot
