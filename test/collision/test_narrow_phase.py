"""The native narrow phase gives what the Python one gives, and what coal gives by itself.

Both backends of :mod:`manip_kin.collision.narrow_phase` are asked for every pair of the
Panda among random obstacles (box, sphere, cylinder and a mesh file), at random
configurations. The distances, witness points and normals must agree with each other and with
a plain ``coal.distance`` on freshly built coal objects (numpy forward kinematics, no checker),
and the damper features must be ``[p × n, n]`` computed here with numpy.
"""

import shutil

import coal
import numpy as np
import pytest
from collision_robots import fresh_coal_distance
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.collision.distances import CollisionChecker
from manip_kin.collision.geometry import obstacle_shape
from manip_kin.collision.narrow_phase import NativeNarrowPhase, native_problem
from manip_kin.collision.python_narrow_phase import PythonNarrowPhase
from manip_kin.core.kinematics import frame_poses
from manip_kin.core.rotations import angle_axis_to_matrix, make_transform
from manip_kin.core.scene import Scene, make_obstacle

pytestmark = pytest.mark.skipif(shutil.which("c++") is None, reason="no C++ compiler: the Python narrow phase runs")

KINDS = ("box", "sphere", "cylinder", "mesh")


def obstacle_lists(most: int):
    """One to ``most`` obstacles for :func:`_scene`: kind, size [m], centre [m], angle [rad]."""
    obstacle = st.tuples(
        st.sampled_from(KINDS),
        st.floats(0.03, 0.3),
        st.tuples(st.floats(-0.3, 0.8), st.floats(-0.6, 0.6), st.floats(-0.1, 1.0)),
        st.floats(-3.0, 3.0),
    )
    return st.lists(obstacle, min_size=1, max_size=most)


def _scene(panda, obstacles) -> tuple[Scene, list]:
    """The obstacles as a scene, and each as ``(coal shape, pose)`` built here."""
    _, collision = panda
    mesh_source = next(g.shape.source for g in collision.geometries if g.shape.source.endswith("link3.stl"))
    scene, truth = Scene(), []
    for k, (kind, size, centre, angle) in enumerate(obstacles):
        pose = make_transform(angle_axis_to_matrix(angle, np.array([0.3, -0.5, 0.8])), centre)
        if kind == "box":
            scale, shape = (size, 1.5 * size, 0.5 * size), coal.Box(size, 1.5 * size, 0.5 * size)
        elif kind == "sphere":
            scale, shape = (size,) * 3, coal.Sphere(0.5 * size)
        elif kind == "cylinder":
            scale, shape = (size, size, 2 * size), coal.Cylinder(0.5 * size, 2 * size)
        else:
            scale = (1.0, 1.0, 1.0)
            mesh = coal.MeshLoader().load(mesh_source, np.ones(3))
            mesh.buildConvexHull(True, "Qt")
            shape = mesh.convex
        scene.add(make_obstacle(("cell", k), kind, scale, pose, mesh_uri=f"file://{mesh_source}"))
        truth.append((shape, pose))
    return scene, truth


@given(
    fractions=st.lists(st.floats(0.0, 1.0), min_size=7, max_size=7),
    obstacles=obstacle_lists(4),
    cutoff=st.sampled_from([0.05, 0.1, 10.0]),
)
@settings(max_examples=30, deadline=None)
def test_native_and_python_narrow_phases_agree_with_coal(panda, fractions, obstacles, cutoff):
    assert native_problem() == ""  # a compiler is here: the native backend must build
    model, collision = panda
    scene, truth = _scene(panda, obstacles)
    checker = CollisionChecker(model, collision)
    checker.update_scene(scene)
    assert isinstance(checker.narrow_phase, NativeNarrowPhase)
    pairs = checker.shape_pairs
    python = PythonNarrowPhase([g.shape for g in collision.geometries])
    python.set_scene(
        [obstacle_shape(o) for o in scene.obstacles], np.array([o.pose_in_base for o in scene.obstacles]), pairs
    )
    q = model.lower + np.array(fractions) * (model.upper - model.lower)
    placed = checker._place(q)
    rows = list(range(len(pairs)))
    native_columns = checker.narrow_phase.compute(placed, rows, cutoff).copy()
    python_columns = python.compute(placed, rows, cutoff)

    frames = frame_poses(model, q)
    robot = [(g.shape.coal_shape, frames[g.frame] @ g.offset) for g in collision.geometries]
    shapes = robot + truth
    for row, (a, b) in enumerate(pairs.tolist()):
        expected, result = fresh_coal_distance(*shapes[a], *shapes[b])
        native, python_line = native_columns[row], python_columns[row]
        assert native[0] == pytest.approx(expected, abs=1e-9)
        assert python_line[0] == pytest.approx(expected, abs=1e-9)
        if expected >= cutoff:
            continue
        point_a, point_b, normal = result.getNearestPoint1(), result.getNearestPoint2(), result.normal
        for line in (native, python_line):
            np.testing.assert_allclose(line[1:4], point_a, atol=1e-9)
            np.testing.assert_allclose(line[4:7], point_b, atol=1e-9)
            np.testing.assert_allclose(line[7:10], normal, atol=1e-9)
            np.testing.assert_allclose(line[10:16], np.concatenate([np.cross(point_a, normal), normal]), atol=1e-9)
            np.testing.assert_allclose(line[16:22], np.concatenate([np.cross(point_b, normal), normal]), atol=1e-9)


@given(
    start=st.lists(st.floats(0.0, 1.0), min_size=7, max_size=7),
    steps=st.lists(st.tuples(st.integers(0, 6), st.floats(-0.05, 0.05)), min_size=5, max_size=40),
    obstacles=obstacle_lists(3),
    influence=st.sampled_from([0.05, 0.1, 0.3]),
    # Small steps stay within one band (the near rows only), large ones make full passes.
    scale=st.sampled_from([1.0, 0.02, 0.001]),
    # A command's stopping travel per joint (the filter's braking), or none.
    travel=st.one_of(st.none(), st.lists(st.floats(-0.1, 0.1), min_size=7, max_size=7)),
)
@settings(max_examples=25, deadline=None)
def test_the_native_broad_phase_and_damper_rows_are_the_python_checkers_along_a_walk(
    panda, start, steps, obstacles, influence, scale, travel
):
    """mk_narrow_near (placement, broad phase, narrow phase, damper rows and the braking's
    lessening in C++) against the checker's Python path, cycle after cycle: the same pairs
    computed, the same rows, the same numbers."""
    model, collision = panda
    scene, _ = _scene(panda, obstacles)
    native, python = CollisionChecker(model, collision), CollisionChecker(model, collision, native=False)
    for checker in (native, python):
        checker.update_scene(scene)
    assert isinstance(native.narrow_phase, NativeNarrowPhase) and isinstance(python.narrow_phase, PythonNarrowPhase)
    q = model.lower + np.array(start) * (model.upper - model.lower)
    for joint, move in steps:
        q = q.copy()
        q[joint] = np.clip(q[joint] + scale * move, model.lower[joint], model.upper[joint])
        travel_now = None if travel is None else np.array(travel) * (1.0 + joint)  # changes from cycle to cycle
        ours = native.evaluate(q, influence, 0.02, 0.5, travel_now)
        reference = python.evaluate(q, influence, 0.02, 0.5, travel_now)
        assert native.pairs_computed == python.pairs_computed
        assert ours.labels == reference.labels
        np.testing.assert_allclose(ours.distances, reference.distances, atol=1e-9)
        np.testing.assert_allclose(ours.matrix, reference.matrix, atol=1e-9)
        np.testing.assert_allclose(ours.bound, reference.bound, atol=1e-9)
        assert (ours.nearest is None) == (reference.nearest is None)
        if reference.nearest is not None:
            assert ours.nearest.pair == reference.nearest.pair
            np.testing.assert_allclose(ours.nearest.point_first, reference.nearest.point_first, atol=1e-9)
        # pair_distances shares the bounds evaluate carries: mixing the two keeps them equal.
        if travel is None:
            assert sorted(p.label for p in native.pair_distances(q, influence)) == sorted(ours.labels)
        else:
            native.pair_distances(q, influence)
        python.pair_distances(q, influence)


def test_the_python_narrow_phase_runs_where_native_is_off(panda, monkeypatch):
    monkeypatch.setenv("MANIP_KIN_NATIVE", "0")
    model, collision = panda
    checker = CollisionChecker(model, collision)
    assert isinstance(checker.narrow_phase, PythonNarrowPhase)
    assert "MANIP_KIN_NATIVE" in checker.narrow_phase_problem
    assert native_problem() == "MANIP_KIN_NATIVE turns native backends off"


def test_a_bad_pair_is_refused_and_the_scene_kept(panda):
    model, collision = panda
    checker = CollisionChecker(model, collision)
    native = checker.narrow_phase
    assert isinstance(native, NativeNarrowPhase)
    placed = checker._place(model.start_configuration())
    rows = list(range(len(checker.shape_pairs)))
    before = native.compute(placed, rows, 1.0).copy()
    with pytest.raises(ValueError, match=r"pair 0 \(0, 99\)"):
        native.set_scene([], np.zeros((0, 4, 4)), np.array([[0, 99]]))
    # The pairs of the last accepted scene still answer, as before.
    np.testing.assert_array_equal(native.compute(placed, rows, 1.0), before)
