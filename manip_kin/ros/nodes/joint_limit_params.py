"""``joint_limits.<joint>.<field>`` parameters: ros2_control's joint_limits layout on a node.

Declared once the model is known (one group per model joint), with the defaults of
:func:`manip_kin.control.joint_limits.default_joint_limits`, and tunable, so the limits can be changed
on the running node as the gains can. A MoveIt or ros2_control ``joint_limits.yaml`` under the
node's ``ros__parameters`` loads with ``--params-file``; its other keys (``has_position_limits``,
``max_position``, ``default_velocity_scaling_factor``, …) are not declared and are ignored.
"""

from __future__ import annotations

from manip_kin.control.joint_limits import LIMIT_FIELDS, MAX_LIMIT_VALUE, JointLimit, JointLimits, default_joint_limits
from manip_kin.core.model import RobotModel
from manip_kin.ros.runtime.param_struct import ParamStruct
from manip_kin.ros.runtime.params import ParamSpec

_UNITS = {"velocity": "/s", "acceleration": "/s²", "deceleration": "/s²", "jerk": "/s³"}

#: How ``--help`` shows the group (the joints are known only once the model is).
HELP_LINE = (
    "  joint_limits.<joint>.{has_velocity_limits, max_velocity, has_acceleration_limits, max_acceleration,\n"
    "      has_deceleration_limits, max_deceleration, has_jerk_limits, max_jerk}  (tunable)\n"
    "      ros2_control's joint_limits layout [rad | m per s, s², s³]; defaults: the URDF's velocity,\n"
    "      the maker's acceleration and jerk where published (Panda), else full speed in 0.2 s and\n"
    "      full acceleration in 20 ms"
)


def parameter_name(joint: str, field: str) -> str:
    """``joint_limits.<joint>.<field>``."""
    return f"joint_limits.{joint}.{field}"


def joint_limit_parameters(model: RobotModel) -> tuple[ParamSpec, ...]:
    """The parameter specs of every joint of ``model`` (tunable, defaults filled in)."""
    specs = []
    for joint, limit in default_joint_limits(model).items():
        unit_base = "m" if model.is_prismatic[model.joint_names.index(joint)] else "rad"
        for field in LIMIT_FIELDS:
            name = parameter_name(joint, field)
            default = getattr(limit, field)
            if field.startswith("has_"):
                specs.append(ParamSpec(name, "bool", default, f"{joint}: {field.replace('_', ' ')}", tunable=True))
            else:
                quantity = field.removeprefix("max_")
                specs.append(
                    ParamSpec(
                        name,
                        "float",
                        float(default),
                        f"{joint}: {quantity} limit (a magnitude, at most {MAX_LIMIT_VALUE:g})",
                        unit_base + _UNITS[quantity],
                        positive=True,
                        tunable=True,
                    )
                )
    return tuple(specs)


def joint_limits_from_params(model: RobotModel, params: ParamStruct) -> JointLimits:
    """The :class:`JointLimits` the ``joint_limits.*`` values of ``params`` give (declared as a group:
    they are in ``params.dynamic``, see :func:`~manip_kin.ros.runtime.declared_params.declare_group`)."""
    per_joint = {
        joint: JointLimit(**{field: params.dynamic[parameter_name(joint, field)] for field in LIMIT_FIELDS})
        for joint in model.joint_names
    }
    return JointLimits.of(model, per_joint)
