"""What ``trajectory_generator`` plans with, from its parameters: the line limits (checked
against what the arm can do), the joint limits, the task, the time scalings and the checks; built
at start and again on a live change (:func:`generator_settings`), before anything is replaced.
"""

from __future__ import annotations

from dataclasses import dataclass

from manip_kin.control.joint_limits import JointLimits
from manip_kin.core.bounds import UNBOUNDED, InputBounds
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_rows import Task, parse_task
from manip_kin.errors import InvalidArgumentError
from manip_kin.motion.lines import MotionLimits
from manip_kin.ros.nodes.joint_limit_params import joint_limits_from_params
from manip_kin.ros.runtime.param_struct import ParamStruct
from manip_kin.ros.runtime.params import period_ns


@dataclass(frozen=True)
class GeneratorSettings:
    """The generator's settings (units as in its parameter table)."""

    limits: MotionLimits
    joint_limits: JointLimits
    task: Task
    time_scaling: str
    joint_time_scaling: str
    check_reach: bool
    joint_state_timeout_ns: int
    quaternion_tolerance: float
    path_points: int
    collision_safety_distance: float
    diagnostics_period_ns: int


def generator_settings(model: RobotModel, bounds: InputBounds, params: ParamStruct) -> GeneratorSettings:
    """The settings ``params`` give for ``model``.

    Raises:
        ManipKinError: limits the planner cannot use, or a task the model cannot have.
    """
    limits = MotionLimits(
        max_linear_velocity=params.max_linear_velocity,
        max_linear_acceleration=params.max_linear_acceleration,
        max_angular_velocity=params.max_angular_velocity,
        max_angular_acceleration=params.max_angular_acceleration,
        max_linear_jerk=params.max_linear_jerk,
        max_angular_jerk=params.max_angular_jerk,
    )
    check_limits(limits, bounds)
    return GeneratorSettings(
        limits=limits,
        joint_limits=joint_limits_from_params(model, params),
        task=parse_task(params.task or None, model),
        time_scaling=params.time_scaling,
        joint_time_scaling=params.joint_time_scaling,
        check_reach=params.check_reach,
        joint_state_timeout_ns=int(params.joint_state_timeout * 1e9),
        quaternion_tolerance=params.quaternion_tolerance,
        path_points=max(2, params.path_points),
        collision_safety_distance=params.collision_safety_distance,
        diagnostics_period_ns=period_ns(params.diagnostics_rate_hz),
    )


def check_limits(limits: MotionLimits, bounds: InputBounds) -> None:
    """Refuse speed limits far beyond what the arm can do (a typo such as 1e30 m/s)."""
    for name, value, valid in (
        ("max_linear_velocity", limits.max_linear_velocity, bounds.max_twist_linear),
        ("max_angular_velocity", limits.max_angular_velocity, bounds.max_twist_angular),
        ("max_linear_acceleration", limits.max_linear_acceleration, UNBOUNDED),
        ("max_angular_acceleration", limits.max_angular_acceleration, UNBOUNDED),
        ("max_linear_jerk", limits.max_linear_jerk, UNBOUNDED),
        ("max_angular_jerk", limits.max_angular_jerk, UNBOUNDED),
    ):
        if value > valid:
            raise InvalidArgumentError(
                f"parameter {name} = {value:g} is absurd for this arm; valid: <= {valid:.4g} (twice what it can do)"
            )
