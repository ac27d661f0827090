"""What ``cartesian_controller`` controls with, from its parameters: the law (the resolved-rate
controller, or the QP with collision avoidance), its supervisor's configuration, the joint limits
of the command filter, the singularity scaling of servoing and the limit horizon.

:func:`controller_setup` builds and checks all of it before the node replaces anything, so a
refused live change leaves the node as it was.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manip_kin.control.joint_limits import JointLimits
from manip_kin.control.resolved_rate import CartesianController, ControllerConfig
from manip_kin.control.servo import SingularityScaling
from manip_kin.control.state_machines import ControllerSupervisorConfig
from manip_kin.core.model import RobotModel
from manip_kin.ros.nodes.joint_limit_params import joint_limits_from_params
from manip_kin.ros.runtime.param_struct import ParamStruct
from manip_kin.ros.runtime.params import period_ns


@dataclass(frozen=True)
class ControllerSetup:
    """The controller's core objects for one set of parameters.

    Attributes:
        controller: the resolved-rate controller (its task, frame and gains).
        law: what steps a pose goal or a twist: the QP law with collision avoidance, else ``controller``.
        supervisor_config: the supervisor's timeouts and tolerances.
        diagnostics_period_ns: the status period [ns] (0: off).
        limits: the joint limits of the command filter.
        singularity: the servo commands' slowdown near a singularity.
        limit_horizon: [s] the law keeps ``q + q̇·horizon`` within the position limits.
    """

    controller: CartesianController
    law: object
    supervisor_config: ControllerSupervisorConfig
    diagnostics_period_ns: int
    limits: JointLimits
    singularity: SingularityScaling
    limit_horizon: float


def controller_setup(model: RobotModel, params: ParamStruct, collision, dt: float) -> ControllerSetup:
    """The setup ``params`` give for ``model`` at a period ``dt`` [s]; ``collision`` (the node's
    :class:`~manip_kin.ros.nodes.collision_inputs.CollisionInputs`) makes the QP law when asked for.

    Raises:
        ManipKinError: a configuration the controller or its supervisor cannot use.
    """
    config = ControllerConfig(
        gain_angular=params.gain_angular,
        gain_linear=params.gain_linear,
        frame=params.frame or None,
        task=params.task or None,
        damping_max=params.damping_max,
        singular_threshold=params.singular_threshold,
        respect_velocity_limits=params.respect_velocity_limits,
        respect_position_limits=params.respect_position_limits,
    )
    controller = CartesianController(model, config)
    limits = joint_limits_from_params(model, params)
    # The law keeps q + q̇·horizon within the position limits: with the horizon of a stop
    # from full speed, a joint nears a limit as slowly as the filter lets it stop, so the
    # law (not only the filter's braking) knows the joint is held and redistributes the task.
    full_stop = limits.stopping_time(np.where(np.isfinite(limits.velocity), limits.velocity, 0.0))
    law = collision.configure(model, params, controller, dt, limits)  # the QP, or controller
    supervisor_config = controller_supervisor_config(params, controller)
    diagnostics_period_ns = period_ns(params.diagnostics_rate_hz)
    return ControllerSetup(
        controller=controller,
        law=law,
        supervisor_config=supervisor_config,
        diagnostics_period_ns=diagnostics_period_ns,
        limits=limits,
        singularity=SingularityScaling(params.singularity_slowdown_start, params.singularity_hard_stop),
        limit_horizon=max(dt, full_stop),
    )


def controller_supervisor_config(params: ParamStruct, controller: CartesianController) -> ControllerSupervisorConfig:
    """The supervisor's configuration from ``params``, for ``controller``'s task."""
    return ControllerSupervisorConfig(
        joint_state_timeout=params.joint_state_timeout,
        goal_timeout=params.goal_timeout,
        goal_twist_timeout=params.goal_twist_timeout,
        position_tolerance=params.position_tolerance,
        orientation_tolerance=params.orientation_tolerance,
        joint_tolerance=params.joint_tolerance,
        task=controller.task,
        progress_window=params.progress_window,
        command_timeout=params.command_timeout,
    )
