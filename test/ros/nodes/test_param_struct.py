"""Typed parameter structs generated from the ParamSpec tables (manip_kin.ros.runtime.param_struct):
the nodes' structs have their table's names and types, are frozen, refuse a value of the wrong
type by name, and a live change gives the node a new struct."""

import dataclasses

import pytest
import rclpy
from rclpy.parameter import Parameter

from manip_kin.errors import InvalidArgumentError
from manip_kin.ros.nodes.cartesian_controller_interface import ControllerParams
from manip_kin.ros.nodes.live_view import LiveViewParams
from manip_kin.ros.nodes.recorder_config import RecorderParams
from manip_kin.ros.nodes.robot_state_interface import RobotStateParams
from manip_kin.ros.nodes.trajectory_generator_interface import GeneratorParams
from manip_kin.ros.runtime.declared_params import LiveParameters, declare_group, declare_parameters
from manip_kin.ros.runtime.param_struct import DYNAMIC, param_struct
from manip_kin.ros.runtime.params import KINDS, ParamSpec

STRUCTS = [ControllerParams, GeneratorParams, RobotStateParams, RecorderParams, LiveViewParams]
#: The type each kind's field must have (lists as tuples: a struct is immutable).
PYTHON_TYPES = dict(zip(KINDS, (float, int, bool, str, tuple[float, ...], tuple[str, ...]), strict=True))

TABLE = (
    ParamSpec("rate_hz", "float", 500.0, "loop rate", "Hz", minimum=1.0, maximum=1e4),
    ParamSpec("gain", "float", 1.0, "a gain", "1/s", minimum=0.0, maximum=10.0, tunable=True),
    ParamSpec("samples", "int", 3, "how many", minimum=1, maximum=10),
    ParamSpec("verbose", "bool", False, "say more", tunable=True),
    ParamSpec("frame", "str", "", "a frame"),
    ParamSpec("start", "float_list", None, "joint positions", "rad"),
    ParamSpec("topics", "str_list", ["a"], "topics"),
)
Demo = param_struct("Demo", TABLE, "A table of every kind.")


def _defaults(struct):
    return {spec.name: spec.default for spec in struct.SPECS}


@pytest.mark.parametrize("struct", STRUCTS, ids=lambda s: s.__name__)
def test_a_node_struct_has_exactly_its_tables_names_and_types(struct):
    fields = dataclasses.fields(struct)
    assert [f.name for f in fields] == [spec.name for spec in struct.SPECS] + [DYNAMIC]
    for field, spec in zip(fields, struct.SPECS):
        expected = PYTHON_TYPES[spec.kind]
        assert field.type == (expected | None if spec.default is None else expected), spec.name
    for spec in struct.SPECS:  # the docstring lists every field with its unit
        assert f"    {spec.name} (" in struct.__doc__ and (not spec.unit or f"[{spec.unit}]" in struct.__doc__)


@pytest.mark.parametrize("struct", STRUCTS, ids=lambda s: s.__name__)
def test_a_node_struct_takes_its_defaults(struct):
    params = struct.from_values(_defaults(struct))
    for spec in struct.SPECS:
        value = getattr(params, spec.name)
        assert value == (tuple(spec.default) if isinstance(spec.default, list) else spec.default)


def test_the_struct_is_frozen_and_its_lists_are_tuples():
    params = Demo.from_values({**_defaults(Demo), "start": [0.5, 1.0], "joint_limits.j1.max_velocity": 2.0})
    with pytest.raises(dataclasses.FrozenInstanceError):
        params.gain = 2.0
    assert params.start == (0.5, 1.0) and params.topics == ("a",)
    assert params.dynamic == {"joint_limits.j1.max_velocity": 2.0}
    with pytest.raises(TypeError):
        params.dynamic["joint_limits.j1.max_velocity"] = 3.0
    assert (
        "rate_hz (float) [Hz]: loop rate." in Demo.__doc__ and "start (tuple[float, ...] | None) [rad]" in Demo.__doc__
    )


@pytest.mark.parametrize(
    ("name", "value"),
    [("gain", "fast"), ("gain", 2), ("gain", True), ("samples", 2.0), ("verbose", 1), ("frame", None)]
    + [("start", [0.0, "1"]), ("start", 0.5), ("topics", "a"), ("topics", None), ("rate_hz", None)],
)
def test_a_value_of_the_wrong_type_is_refused_with_its_name(name, value):
    with pytest.raises(InvalidArgumentError, match=rf"Demo\.{name} = .* has the wrong type; valid: "):
        Demo.from_values({**_defaults(Demo), name: value})
    good = Demo.from_values(_defaults(Demo))
    with pytest.raises(InvalidArgumentError, match=rf"Demo\.{name} = "):
        good.replace({name: value})


def test_a_missing_value_and_a_name_that_is_no_field_are_refused():
    values = _defaults(Demo)
    del values["gain"]
    with pytest.raises(InvalidArgumentError, match="Demo: no value for gain"):
        Demo.from_values(values)
    with pytest.raises(ValueError, match="joint_limits.j1.max_velocity"):
        param_struct("Bad", (ParamSpec("joint_limits.j1.max_velocity", "float", 1.0, "a limit"),))
    with pytest.raises(ValueError, match="gain"):
        param_struct("Twice", TABLE + (TABLE[1],))


@pytest.fixture
def node():
    context = rclpy.Context()
    rclpy.init(context=context)
    made = rclpy.create_node("param_struct_test", context=context)
    yield made
    made.destroy_node()
    context.try_shutdown()


def test_declared_parameters_come_as_a_struct_and_a_live_change_gives_a_new_one(node):
    group = (ParamSpec("joint_limits.j1.max_velocity", "float", 2.0, "j1: velocity limit", tunable=True),)
    params = declare_group(node, declare_parameters(node, Demo), group)
    assert isinstance(params, Demo) and params.gain == 1.0 and params.start is None
    assert params.dynamic == {"joint_limits.j1.max_velocity": 2.0}
    applied = []

    def apply(new):
        applied.append(new)
        return "too verbose" if new.verbose else None

    live = LiveParameters(node, params, apply, group)
    result = node.set_parameters([Parameter("gain", value=3), Parameter("joint_limits.j1.max_velocity", value=1.5)])
    assert all(r.successful for r in result), result
    new = applied[-1]
    assert isinstance(new, Demo) and new is not params and live.params is new
    assert new.gain == 3.0 and isinstance(new.gain, float) and new.dynamic["joint_limits.j1.max_velocity"] == 1.5
    assert params.gain == 1.0 and params.dynamic["joint_limits.j1.max_velocity"] == 2.0  # the old one is as it was
    # Refused by the node: nothing changes; a read-only one is refused before the node sees it.
    assert not node.set_parameters([Parameter("verbose", value=True)])[0].successful
    assert live.params is new
    count = len(applied)
    refused = node.set_parameters([Parameter("samples", value=5)])[0]
    assert not refused.successful and "read-only" in refused.reason and len(applied) == count
