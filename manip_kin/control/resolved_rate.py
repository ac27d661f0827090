"""The resolved-rate cartesian control law run every cycle by ``cartesian_controller``.

One step, from the joint positions ``q`` and a goal pose (plus an optional goal twist):

1. Cartesian error of the controlled frame (tool if any, else the end effector):
   orientation ``e_o`` = angle-axis of ``frame_R_goal`` expressed in base (equivalently the
   rotation vector of ``R_goal · Rᵀ``) [rad], position ``e_p = p_goal - p`` in base [m].
2. Reference twist ``v* = [K_o e_o + ω_ff; K_p e_p + v_ff]`` (separate gains, optional
   feed-forward). With ``ω = K_o e_o`` about the fixed axis of ``e_o``, the error decays as
   ``exp(-K t)``.
3. Joint rates ``q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ v*`` over the task rows of the geometric Jacobian
   ``J``. The damping is zero while the smallest singular value ``σ_min`` of ``J`` is above
   ``ε = singular_threshold`` and rises smoothly below it (Chiaverini's rule),
   ``λ² = λ_max² (1 - (σ_min / ε)²)``: exact tracking away from singularities, bounded rates
   at them, and motion in every non-singular direction so the arm never stops at one.
4. Position limits (SNS-style, after Flacco et al.): a joint whose rate, held to its
   velocity limit (step 5 brings it there), would carry it past a limit within the control
   period ``dt`` is saturated at the rate that lands it exactly on
   the limit (zero once it is there), its column is removed from ``J`` and the task minus
   its contribution is re-solved over the remaining joints; repeat until no joint violates.
   The task is thus redistributed instead of being distorted by a clamp.
5. Velocity limits: the whole ``q̇`` is scaled by one factor so every joint is within its
   limit; the direction of motion (and of the cartesian velocity) is kept.

The law runs as one generated function per model and configuration
(:func:`manip_kin.codegen.control_step.step_source`) on plain floats: the model's unrolled kinematics,
the pose error with the rotation vector of :mod:`manip_kin.codegen.inlined`, and the unrolled
damped solve; numpy only builds the output arrays. Near a singularity (ruled out cheaply by
``det`` and the angular and linear traces of ``J Jᵀ``, see
:func:`manip_kin.codegen.inlined.smallest_eigenvalue_bound`)
it calls the one damped least-squares solve (:class:`manip_kin.core.damped_least_squares.DampedSolver`),
which computes ``σ_min`` exactly; at a position limit it calls :meth:`CartesianController._redistribute`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from manip_kin.codegen.control_step import compile_step
from manip_kin.core.damped_least_squares import DampedSolver, symmetric_eigenvalues
from manip_kin.core.kinematics import compiled_kinematics
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_jacobian import jacobian_entry, zero_joint_column
from manip_kin.core.pose_rows import Task, parse_task
from manip_kin.core.rotations import matrix_to_rotvec, rotvec_from_entries
from manip_kin.errors import InvalidArgumentError, JointCountError, ManipKinError, NonFiniteError

#: q or goal coordinates beyond this [rad | m] are absurd (finite, but they overflow the step).
_ABSURD = 1e100


@dataclass(frozen=True)
class ControllerConfig:
    """Parameters of :class:`CartesianController`.

    Attributes:
        gain_angular: orientation gain K_o [1/s], >= 0.
        gain_linear: position gain K_p [1/s], >= 0.
        frame: controlled frame (``tool``, ``ee``, a joint frame number or link name);
            None = the tool if the robot has one, else the end effector.
        task: which error components are controlled (see :mod:`manip_kin.core.pose_rows`): a name
            (``full``, ``position``, ``position_yaw``, ``orientation``), a comma list such as
            ``"rz,x,y,z"`` or a six-value 0/1 mask over ``[rx, ry, rz, x, y, z]``;
            None = :func:`manip_kin.core.pose_rows.default_task` (full for six or more joints).
        damping_max: λ_max, the damping at an exact singularity [same unit as J's singular
            values: m/rad for the linear rows, 1 for the angular rows], >= 0.
        singular_threshold: ε, the smallest singular value of the task Jacobian below which
            damping rises, > 0.
        respect_velocity_limits: scale q̇ so every joint stays within its velocity limit.
        respect_position_limits: keep ``q + q̇·dt`` within the position limits by
            redistributing the task over the joints not at a limit.
    """

    gain_angular: float = 0.8
    gain_linear: float = 0.8
    frame: str | None = None
    task: str | Sequence[int] | Task | None = None
    damping_max: float = 0.04
    singular_threshold: float = 0.02
    respect_velocity_limits: bool = True
    respect_position_limits: bool = True

    def __post_init__(self):
        for name in ("gain_angular", "gain_linear", "damping_max"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise InvalidArgumentError(f"{name} = {value!r}; valid: a finite number >= 0")
        threshold = self.singular_threshold
        if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0.0):
            raise InvalidArgumentError(f"singular_threshold = {threshold!r}; valid: a finite number > 0")


@dataclass(frozen=True)
class ControlOutput:
    """Result of one :meth:`CartesianController.step`.

    Attributes:
        qdot: joint rates to command, shape (n,) [rad/s | m/s].
        orientation_error: rotation vector of ``frame_R_goal`` expressed in base, shape (3,) [rad].
        position_error: ``p_goal - p`` in base, shape (3,) [m].
        manipulability: Yoshikawa's ``sqrt(det(J Jᵀ))`` of the task Jacobian.
        damping: λ used in the damped pseudo-inverse (0 away from singularities).
        velocity_scale: factor applied to q̇ for the velocity limits (1.0 = not saturated).
        limited_joints: indices of joints held at (or stopped exactly on) a position limit.
        singular: True when the task Jacobian's σ_min is below the singular threshold.
    """

    qdot: np.ndarray
    orientation_error: np.ndarray
    position_error: np.ndarray
    manipulability: float
    damping: float
    velocity_scale: float
    limited_joints: tuple[int, ...]
    singular: bool

    @property
    def orientation_error_norm(self) -> float:
        """Rotation angle between the frame and the goal [rad]."""
        return float(math.sqrt(float(self.orientation_error @ self.orientation_error)))

    @property
    def position_error_norm(self) -> float:
        """Distance between the frame origin and the goal position [m]."""
        return float(math.sqrt(float(self.position_error @ self.position_error)))


def _pose_error_values(pose: Sequence[float], goal: Sequence[Sequence[float]]) -> tuple[float, ...]:
    """``(e_o, e_p)`` as six floats from a flat row-major 4x4 ``pose`` (>= 12 values) and goal rows."""
    r00, r01, r02, px, r10, r11, r12, py, r20, r21, r22, pz = pose[:12]
    (g00, g01, g02, gx), (g10, g11, g12, gy), (g20, g21, g22, gz) = goal[0], goal[1], goal[2]
    # E = R_goal · Rᵀ: E_ij = goal row i · current row j.
    rx, ry, rz = rotvec_from_entries(
        g00 * r00 + g01 * r01 + g02 * r02,
        g00 * r10 + g01 * r11 + g02 * r12,
        g00 * r20 + g01 * r21 + g02 * r22,
        g10 * r00 + g11 * r01 + g12 * r02,
        g10 * r10 + g11 * r11 + g12 * r12,
        g10 * r20 + g11 * r21 + g12 * r22,
        g20 * r00 + g21 * r01 + g22 * r02,
        g20 * r10 + g21 * r11 + g22 * r12,
        g20 * r20 + g21 * r21 + g22 * r22,
    )
    return rx, ry, rz, gx - px, gy - py, gz - pz


def pose_error(current_pose: np.ndarray, goal_pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cartesian error between a frame and its goal, both 4x4 poses in base.

    Returns:
        ``(orientation_error, position_error)``: the angle-axis of ``current_R_goal``
        expressed in base (= rotation vector of ``R_goal Rᵀ``), shape (3,) [rad], and
        ``goal - current`` position in base, shape (3,) [m].
    """
    current = np.asarray(current_pose, dtype=float)
    goal = np.asarray(goal_pose, dtype=float)
    if current.shape != (4, 4) or goal.shape != (4, 4):
        raise InvalidArgumentError(f"poses have shapes {current.shape} and {goal.shape}; valid: (4, 4) each")
    orientation = matrix_to_rotvec(goal[:3, :3] @ current[:3, :3].T)
    return orientation, goal[:3, 3] - current[:3, 3]


_NO_FEED_FORWARD = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_INFINITY = math.inf


def _feed_forward_values(goal_twist) -> list[float]:
    """``(angular, linear)`` as six floats ``[ω; v]``, validated."""
    try:
        angular, linear = goal_twist
        values = [float(v) for v in angular] + [float(v) for v in linear]
    except (TypeError, ValueError):
        values = []
    if len(values) != 6:
        raise InvalidArgumentError(
            f"goal_twist = {goal_twist!r}; valid: (angular, linear) with 3 values each [rad/s], [m/s]"
        )
    if not math.isfinite(sum(values)):
        raise NonFiniteError("goal_twist")
    return values


def _goal_rows(goal_pose) -> list[list[float]]:
    """The goal pose as 4 rows of 4 floats, validated cheaply."""
    try:
        rows = goal_pose.tolist() if isinstance(goal_pose, np.ndarray) else [list(map(float, r)) for r in goal_pose]
        ok = len(rows) == 4 and all(len(r) == 4 for r in rows)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        shape = getattr(goal_pose, "shape", None)
        raise InvalidArgumentError(f"goal_pose has shape {shape}; valid: a 4x4 homogeneous transform")
    return rows


class CartesianController:
    """Resolved-rate control of one frame towards a goal pose (see the module docstring).

    The controller keeps no state between steps (every step depends only on its arguments),
    so one instance may serve several loops. Building it generates and compiles the model's
    unrolled code (a few milliseconds, cached per structure: chain, task rows, limits present).

    Attributes:
        model: the robot.
        config: the parameters.
        frame_index: the controlled frame (see :meth:`RobotModel.frame_index`).
        task: the controlled error components.
    """

    def __init__(self, model: RobotModel, config: ControllerConfig = ControllerConfig()):
        self.model = model
        self.config = config
        self.frame_index = model.frame_index(config.frame if config.frame is not None else model.default_frame)
        self.task = parse_task(config.task, model)
        n = model.dof
        rows = self.task.rows
        self._n = n
        self._rows = rows
        self._chain = compiled_kinematics(model, self.frame_index, True)
        self._lower = model.lower.tolist()
        self._upper = model.upper.tolist()
        self._inverse_velocity_limits = (1.0 / model.velocity_limits).tolist()
        # The fastest a joint moves: the velocity scaling brings every rate within its limit,
        # so a joint further than this times dt from a limit cannot reach it within dt.
        self._top_speeds = model.velocity_limits.tolist() if config.respect_velocity_limits else [math.inf] * n
        self._epsilon_sq = config.singular_threshold**2
        self._damping_max_sq = config.damping_max**2
        # The one damped least-squares solve (exact σ_min, Chiaverini's damping) for the cases
        # the generated step's certificate does not clear, and for the SNS re-solves.
        self._solver = DampedSolver(self._chain, n, rows)
        self._step = compile_step(
            self._chain,
            n,
            rows,
            ControlOutput,
            solve=self._solve_uncertified,
            redistribute=self._redistribute,
            eigenvalues=symmetric_eigenvalues,
            gain_angular=float(config.gain_angular),
            gain_linear=float(config.gain_linear),
            epsilon_sq=self._epsilon_sq,
            damping_max_sq=self._damping_max_sq,
            lower=self._lower if config.respect_position_limits else None,
            upper=self._upper if config.respect_position_limits else None,
            inverse_velocity_limits=self._inverse_velocity_limits if config.respect_velocity_limits else None,
            absurd=_ABSURD,
        )

    def _solve_uncertified(self, values: Sequence[float], rhs: list) -> tuple[list, float, bool, float]:
        """The damped solve when the step's certificate failed: ``(qdot, λ, singular, manipulability)``."""
        return self._solver.solve(values, rhs, self._epsilon_sq, self._damping_max_sq, try_certificate=False)

    # --- the control step -----------------------------------------------------------------

    def step(
        self,
        q: np.ndarray,
        goal_pose: np.ndarray,
        goal_twist: tuple[np.ndarray, np.ndarray] | None = None,
        dt: float = 0.002,
    ) -> ControlOutput:
        """Joint rates that move the controlled frame towards ``goal_pose``.

        Args:
            q: joint positions, shape (n,) [rad | m].
            goal_pose: goal pose of the controlled frame in base, shape (4, 4). Its rotation is
                not re-validated every cycle: check it where it enters (see
                :func:`manip_kin.core.rotations.check_rotation`).
            goal_twist: optional feed-forward ``(angular [rad/s], linear [m/s])`` of the goal,
                w.r.t. base, in base, shapes (3,) and (3,).
            dt: control period [s], > 0: the horizon over which ``q + q̇·dt`` must stay within
                the position limits.
        """
        q_values = q.tolist() if type(q) is np.ndarray else [float(v) for v in q]
        if type(goal_pose) is np.ndarray and goal_pose.shape == (4, 4):
            goal = goal_pose.tolist()
        else:
            goal = _goal_rows(goal_pose)
        feed_forward = _NO_FEED_FORWARD if goal_twist is None else _feed_forward_values(goal_twist)
        try:
            output = self._step(q_values, goal, feed_forward, dt)
        except (ArithmeticError, ValueError):
            output = None  # the input is unusable (a wrong q length, a degenerate goal): say why
        if output is None:
            raise self._input_error(q_values, goal, feed_forward, dt)
        return output

    def _input_error(self, q_values: list, goal: list, feed_forward: Sequence[float], dt: float) -> ManipKinError:
        """What is wrong with an input the generated step refused."""
        if len(q_values) != self._n:
            return JointCountError("q", len(q_values), self._n)
        if not 0.0 < dt < _INFINITY:
            return InvalidArgumentError(f"dt = {dt!r}; valid: a finite period > 0 [s]")
        if not math.isfinite(sum(q_values)):
            return NonFiniteError("q")
        try:
            error = _pose_error_values(self._chain(q_values), goal)
        except ZeroDivisionError:
            return InvalidArgumentError("goal_pose rotation is not a rotation matrix; valid: orthonormal with det +1")
        if not math.isfinite(sum(error) + sum(feed_forward)):
            return NonFiniteError("the goal pose or the goal twist")
        if not (-_ABSURD < min(q_values) and max(q_values) < _ABSURD):
            return InvalidArgumentError(f"q = {q_values}; valid: |values| < {_ABSURD:g} (positions of an arm)")
        position = [goal[0][3], goal[1][3], goal[2][3]]
        if not abs(position[0]) + abs(position[1]) + abs(position[2]) < _ABSURD:
            return InvalidArgumentError(f"goal position {position}; valid: |values| < {_ABSURD:g} m")
        return NonFiniteError("the Jacobian (q or the model)")

    def _redistribute(
        self, q_values: list, values: Sequence[float], rhs: list, qdot: list, dt: float, damping: float, singular: bool
    ) -> tuple[list, tuple[int, ...], float, bool]:
        """SNS-style position-limit handling, called by the generated step when some joint would
        cross a limit within ``dt``: ``(qdot, held joints, λ, singular)``.

        Repeatedly saturates the joint that violates its bound the most (relative to its
        velocity limit) at the rate that lands it on the limit, removes its column and
        re-solves the remaining task over the other joints. A joint violates its bound when
        its rate, held to its velocity limit, crosses it within ``dt``: a rate above the limit
        is scaled down afterwards. Counted whole, the rates for a goal metres away held joints
        that could not reach a limit within the horizon (1.6 rad from one over 0.5 s), and a
        held joint's landing rate then set the velocity scale: the arm crawled.
        """
        n, rows = self._n, self._rows
        lower, upper = self._lower, self._upper
        inverse_limits, top_speeds = self._inverse_velocity_limits, self._top_speeds
        reduced = list(values)  # the chain output with the held joints' columns zeroed
        residual = list(rhs)
        held: dict[int, float] = {}
        qdot = list(qdot)
        for _ in range(n):
            worst_joint, worst_excess, worst_rate = -1, 0.0, 0.0
            for j in range(n):
                if j in held:
                    continue
                rate = qdot[j]
                reach = max(-top_speeds[j], min(rate, top_speeds[j])) * dt
                # The rate that lands exactly on the limit; 0 for a joint already at or past it.
                if rate < 0.0 and q_values[j] + reach < lower[j]:
                    bound = min((lower[j] - q_values[j]) / dt, 0.0)
                elif rate > 0.0 and q_values[j] + reach > upper[j]:
                    bound = max((upper[j] - q_values[j]) / dt, 0.0)
                else:
                    continue
                excess = abs(rate - bound) * inverse_limits[j]
                if excess > worst_excess or worst_joint < 0:
                    worst_joint, worst_excess, worst_rate = j, excess, bound
            if worst_joint < 0:
                break
            held[worst_joint] = worst_rate
            qdot[worst_joint] = worst_rate
            for i, r in enumerate(rows):
                residual[i] -= values[jacobian_entry(n, r, worst_joint)] * worst_rate
            zero_joint_column(reduced, n, worst_joint)
            if len(held) == n:
                break
            solved, damping, singular, _ = self._solver.solve(reduced, residual, self._epsilon_sq, self._damping_max_sq)
            for j in range(n):
                if j not in held:
                    qdot[j] = solved[j]
        return qdot, tuple(sorted(held)), damping, singular

    def error(self, q: np.ndarray, goal_pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(orientation_error [rad], position_error [m])`` of the controlled frame at ``q``, shapes (3,)."""
        q_values = self.model.check_q(q).tolist()
        error = _pose_error_values(self._chain(q_values), _goal_rows(goal_pose))
        return np.array(error[:3]), np.array(error[3:])
