"""The intermediate form of generated code: one name allocator, and the chain's structural constants.

Emitters take their locals from one :class:`manip_kin.codegen.ir.Names` per generated function,
so no two can clash; the chain emitter declares the outputs its structure fixes (0.0, ±1.0), and
the control step, the IK iteration and the damped solve fold exactly those in.
"""

from __future__ import annotations

import builtins
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from robot_data_files import example_robot_data_urdf

from manip_kin.codegen.chain import ChainSpec
from manip_kin.codegen.ir import Names
from manip_kin.core.kinematics import (
    KinematicsData,
    compiled_kinematics,
    forward_kinematics,
    frame_in_base,
    jacobian_from_data,
)
from manip_kin.core.model import Joint, JointType, RobotModel
from manip_kin.core.robots import load_robot
from manip_kin.core.urdf import load_urdf

# Prefixes and names that run into each other when spelled out: a1 + 0 is a10, a + 10 too.
_SPELLINGS = st.sampled_from(["a", "a1", "a1_", "a10", "a_", "b", "q", "q0", "x1_0_", "x1_", "x"])


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["fresh", "reserve"]), _SPELLINGS), max_size=40))
def test_a_fresh_name_never_repeats_a_taken_one(operations):
    names = Names(["q"])
    taken = {"q"}
    for operation, spelling in operations:
        if operation == "fresh":
            name = names.fresh(spelling)
            assert name not in taken and name.startswith(spelling) and name.isidentifier()
            assert name not in vars(builtins)
            taken.add(name)
        elif spelling in taken:
            with pytest.raises(ValueError, match="taken"):
                names.reserve(spelling)
        else:
            names.reserve(spelling)
            taken.add(spelling)
        assert all(name in names for name in taken)


def test_names_refuse_what_is_not_a_name():
    with pytest.raises(ValueError, match="not a Python name"):
        Names(["for"])
    with pytest.raises(ValueError, match="not a Python name"):
        Names().reserve("a-b")
    with pytest.raises(ValueError, match="cannot start"):
        Names().fresh("1")
    with pytest.raises(ValueError, match="taken"):
        Names(["abs"])  # a builtin the generated code calls


def _with_prismatic() -> RobotModel:
    origin = np.eye(4)
    origin[:3, 3] = [0.1, 0.0, 0.2]
    axes = [np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])]
    joints = tuple(
        Joint(
            name=f"j{i}",
            type=JointType.PRISMATIC if i == 1 else JointType.REVOLUTE,
            origin=origin if i != 3 else np.eye(4),  # joint 3 at joint 2's origin
            axis=axes[i % 3],
            lower=-1.0,
            upper=1.0,
        )
        for i in range(5)
    )
    return RobotModel(name="mixed", joints=joints)


def _models() -> list[RobotModel]:
    panda = load_urdf(example_robot_data_urdf("panda_description/urdf/panda.urdf"), tip_link="panda_hand")
    names = ("genova7", "irb120", "mocom7", "rpp", "scara")
    return [load_robot(name) for name in names] + [panda, _with_prismatic()]


def _frames(model: RobotModel) -> range:
    return range(model.dof + (3 if model.tool is not None else 2))


def _reference(model: RobotModel, q: np.ndarray, frame: int) -> np.ndarray:
    """Pose (16) and geometric Jacobian (6n) of ``frame`` by the numpy kinematics, not generated code."""
    data = KinematicsData(model)
    forward_kinematics(model, data, q)
    jacobian = jacobian_from_data(model, data, frame, "geometric")
    return np.concatenate(
        [frame_in_base(model, data, frame).ravel(), jacobian.angular.ravel(), jacobian.linear.ravel()]
    )


def _sampled_constants(chain, dof: int, samples: int = 3) -> set[int]:
    """The entries a chain returns equal at random configurations (what random sampling finds)."""
    generator = random.Random(0)
    outputs = [chain([generator.uniform(-4.0, 4.0) for _ in range(dof)]) for _ in range(samples)]
    return {k for k, value in enumerate(outputs[0]) if all(output[k] == value for output in outputs[1:])}


@pytest.mark.parametrize("model", _models(), ids=lambda model: model.name)
def test_the_chain_declares_exactly_its_structural_constants(model):
    """Each declared constant is the value the kinematics have at every q (checked against the
    numpy path), and every entry equal at random configurations is declared (none left for
    the consumers to rediscover)."""
    rng = np.random.default_rng(3)
    for frame in _frames(model):
        chain = compiled_kinematics(model, frame, True)
        declared = chain.spec.constants()
        assert declared, "a pose always has its constant last row"
        for _ in range(5):
            q = rng.uniform(-3.0, 3.0, model.dof)
            expected = _reference(model, q, frame)
            for index, value in declared.items():
                assert expected[index] == pytest.approx(value, abs=1e-12), (frame, index)
        assert _sampled_constants(chain, model.dof) <= set(declared), frame


def test_a_frame_at_its_joints_origin_has_a_structurally_zero_lever_arm():
    """The mixed arm's joint 3 sits at joint 2's origin, and frame 4 (joint 3's) at both: their
    linear columns there are zero by structure, declared as constants (the old code found them
    by random sampling), while joint 1's, a lever arm away, is not."""
    model = _with_prismatic()
    n = model.dof
    declared = compiled_kinematics(model, 4, True).spec.constants()

    def linear_column(j: int) -> list[float | None]:
        return [declared.get(16 + (3 + r) * n + j) for r in range(3)]

    assert linear_column(2) == linear_column(3) == [0.0, 0.0, 0.0]
    assert linear_column(0) == [None, None, 0.0]  # the first revolute joint: z × lever has no z part


def test_a_spec_is_its_key_and_emits_into_any_names():
    model = load_robot("genova7")
    chain = compiled_kinematics(model, model.dof + 1, True)
    spec = chain.spec
    again = ChainSpec.of(
        np.frombuffer(spec.fixed).reshape(spec.shape), spec.revolute, np.frombuffer(spec.tail).reshape(4, 4), 7, True
    )
    assert again == spec and hash(again) == hash(spec)
    # Emitted into names that already hold the chain's usual spellings, nothing is shadowed.
    names = Names(["q", "cos", "sin", *(f"v{k}" for k in range(50)), "c0", "s0"])
    joints = [names.fresh("q") for _ in range(7)]
    fragment = spec.emit(names, joints)
    assigned = {line.split(" = ")[0] for line in fragment.lines}
    assert not any(f"v{k}" in assigned for k in range(50)) and "c0 = cos" not in "\n".join(fragment.lines)
    source = "def chain(q):\n    {} = q\n{}\n    return ({},)\n".format(
        ", ".join(joints), "\n".join("    " + line for line in fragment.lines), ", ".join(map(str, fragment.outputs))
    )
    scope: dict = {"cos": np.cos, "sin": np.sin}
    exec(source, scope)  # noqa: S102 - generated in the test
    q = [0.1 * k for k in range(7)]
    assert scope["chain"](q) == chain(q)


def test_a_factor_bails_out_with_the_statement_it_is_given():
    """Two factorisations in one function: their locals are their own, and a pivot that is not
    positive runs each one's ``on_fail`` (no text is rewritten afterwards)."""
    from manip_kin.codegen.ir import indented
    from manip_kin.codegen.unrolled_linalg import cholesky_factor, cholesky_solve

    names = Names(["a", "b", "d", "sqrt"])
    a = [["a[0]"], ["a[1]", "a[2]"]]
    first = cholesky_factor(names, a, None, "return 'first'")
    second = cholesky_factor(names, a, "d", "return 'second'")
    x = cholesky_solve(names, second.outputs, ["b[0]", "b[1]"])
    assert not set(first.outputs.pivots + first.outputs.reciprocals) & set(
        second.outputs.pivots + second.outputs.reciprocals
    )
    body = first.lines + second.lines + x.lines + [f"return {', '.join(x.outputs)}"]
    scope = {"sqrt": np.sqrt}
    exec("def f(a, b, d):\n" + "\n".join(indented(body)) + "\n", scope)  # noqa: S102 - generated in the test
    assert scope["f"]([-1.0, 0.0, 1.0], [1.0, 1.0], 2.0) == "first"  # a₀₀ < 0
    assert scope["f"]([2.0, 0.0, 0.5], [1.0, 1.0], -1.0) == "second"  # positive, not with d = -1
    # [[2, 1], [1, 2]] x = [3, 3] -> x = [1, 1], with d = 0 and with [[1, 1], [1, 1]] + 1·I
    np.testing.assert_allclose(scope["f"]([2.0, 1.0, 2.0], [3.0, 3.0], 0.0), [1.0, 1.0])
    assert scope["f"]([1.0, 1.0, 1.0], [3.0, 3.0], 1.0) == "first"  # singular before the shift
