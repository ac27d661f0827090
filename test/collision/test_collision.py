"""Collision geometry, pair selection, distances, the path check and ``manip_kin check``."""

import json

import numpy as np
import pytest
from collision_robots import (
    BALL_ARM_BASE_BOX,
    BALL_ARM_URDF,
    PANDA_FOLDED,
    PANDA_READY,
    ball_centres,
    ball_obstacle_distance,
    panda_files,
    point_box_distance,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.cli import main
from manip_kin.collision.collision_model import load_collision_model
from manip_kin.collision.distances import CollisionChecker
from manip_kin.collision.geometry import model_frames
from manip_kin.collision.path import first_collision_along
from manip_kin.collision.srdf import link_pair, read_disabled_pairs
from manip_kin.core.kinematics import frame_pose
from manip_kin.core.rotations import make_transform
from manip_kin.core.scene import Scene, make_obstacle
from manip_kin.core.urdf import load_urdf, load_urdf_string
from manip_kin.errors import ModelFileError

# --- geometry on frames -------------------------------------------------------------------------


def test_every_collision_element_rides_on_the_frame_that_moves_it(panda):
    model, collision = panda
    assert len(collision.geometries) == 17  # 10 meshes + 4 boxes per finger
    by_link = {g.link: g for g in collision.geometries}
    assert [by_link[f"panda_link{i}"].frame for i in range(8)] == list(range(8))
    assert by_link["panda_hand"].frame == 7 and by_link["panda_leftfinger"].frame == 7
    q = PANDA_READY
    frames = model_frames(model, q)
    # The hand (after the tip through fixed joints) is where the URDF chain to it puts it.
    hand = load_urdf(panda_files()[0], tip_link="panda_hand")
    assert np.allclose(frames[7] @ by_link["panda_hand"].offset, frame_pose(hand, q, "ee"), atol=1e-12)
    # A finger (below the tip through a prismatic joint not on the chain) sits at that joint's 0.
    fingers = load_urdf(panda_files()[0], tip_link="panda_leftfinger")
    first_box = next(g for g in collision.geometries if g.link == "panda_leftfinger")
    expected = frame_pose(fingers, np.append(q, 0.0), "ee") @ make_transform(None, [0.0, 18.5e-3, 11e-3])
    assert np.allclose(frames[7] @ first_box.offset, expected, atol=1e-12)


def test_primitive_shapes_and_frames_of_a_urdf_text(ball_arm):
    _, collision = ball_arm
    kinds = [(g.link, g.frame, g.shape.kind.value, g.shape.size) for g in collision.geometries]
    assert kinds == [
        ("base_link", 0, "box", (0.2, 0.2, 0.1)),
        ("link1", 1, "cylinder", (0.03, 0.2)),
        ("link2", 2, "sphere", (0.05,)),
        ("link3", 3, "sphere", (0.04,)),
    ]


@given(
    q=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    centre=st.tuples(st.floats(-0.8, 0.8), st.floats(-0.8, 0.8), st.floats(0.3, 1.0)),
    radius=st.floats(0.02, 0.1),
)
@settings(max_examples=40)
def test_distances_match_closed_forms(ball_arm, q, centre, radius):
    model, collision = ball_arm
    q = np.array(q)
    scene = Scene()
    scene.add(make_obstacle(("cell", 1), "sphere", (2 * radius,) * 3, make_transform(None, centre)))
    checker = CollisionChecker(model, collision)
    checker.update_scene(scene)
    found = {pair.pair: pair for pair in checker.link_distances(q)}
    for link, sphere_centre, sphere_radius in ball_centres(model, q):
        expected = np.linalg.norm(sphere_centre - np.array(centre)) - sphere_radius - radius
        pair = found[(link, "obstacle:cell/1")]
        assert pair.distance == pytest.approx(expected, abs=1e-6)
        if expected > 1e-4:  # witness points on the two spheres, facing each other
            assert np.linalg.norm(pair.point_first - sphere_centre) == pytest.approx(sphere_radius, abs=1e-6)
            assert np.linalg.norm(pair.point_second - np.array(centre)) == pytest.approx(radius, abs=1e-6)
    # Self pair: the last sphere against the base box (point-box distance minus the radius).
    _, tip_centre, tip_radius = ball_centres(model, q)[1]
    gap = point_box_distance(tip_centre, *BALL_ARM_BASE_BOX) - tip_radius
    if ("base_link", "link3") in found and gap > 1e-4:
        assert found[("base_link", "link3")].distance == pytest.approx(gap, abs=1e-6)


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_damper_rows_are_the_distance_gradient(panda, native):
    model, collision = panda
    scene = Scene()
    scene.add(make_obstacle(("cell", 1), "box", (0.2, 0.2, 0.2), make_transform(None, [0.55, 0.1, 0.45])))
    checker = CollisionChecker(model, collision, native=native)
    checker.update_scene(scene)
    assert checker.narrow_phase.name == ("native" if native else "python"), checker.narrow_phase_problem
    q = PANDA_READY
    rows = checker.evaluate(q, 0.3, 0.02, 0.5)
    assert len(rows.labels) >= 3
    step = 1e-6
    for row, label in enumerate(rows.labels[:4]):
        gradient = []
        for j in range(model.dof):
            dq = np.zeros(model.dof)
            dq[j] = step
            values = []
            for sign in (1, -1):
                fresh = CollisionChecker(model, collision, native=False)
                fresh.update_scene(scene)
                # A link of several shapes has a row per shape pair: follow this row's one.
                same = [p.distance for p in fresh.pair_distances(q + sign * dq) if p.label == label]
                values.append(min(same, key=lambda d: abs(d - rows.distances[row])))
            gradient.append((values[0] - values[1]) / (2 * step))
        # A q̇ <= b bounds the closing speed -ḋ: each row is -∂d/∂q.
        assert np.allclose(rows.matrix[row], -np.array(gradient), atol=2e-4), label
    assert np.allclose(rows.bound, 0.5 * (rows.distances - 0.02) / (0.3 - 0.02))


def test_scene_shapes_rebuilt_only_when_the_version_moves(ball_arm):
    model, collision = ball_arm
    checker = CollisionChecker(model, collision)
    scene = Scene()
    assert checker.update_scene(scene) and not checker.update_scene(scene)
    scene.add(make_obstacle(("cell", 1), "cylinder", (0.1, 0.1, 0.4), make_transform(None, [0.5, 0, 0.3])))
    assert checker.update_scene(scene) and checker.obstacle_count == 1
    assert not checker.update_scene(scene)
    scene.clear()
    assert checker.update_scene(scene) and checker.obstacle_count == 0
    # A mesh that cannot be found is left out with its reason; the other obstacles apply.
    scene.add(make_obstacle(("cell", 2), "mesh", (1, 1, 1), np.eye(4), "package://nowhere/part.stl"))
    scene.add(make_obstacle(("cell", 3), "sphere", (0.1, 0.1, 0.1), make_transform(None, [0.5, 0, 0.3])))
    assert checker.update_scene(scene) and checker.obstacle_count == 1
    (problem,) = checker.scene_problems
    assert "obstacle 'cell'/2" in problem and "package://nowhere/part.stl" in problem
    urdf = panda_files()[0]
    mesh = f"file://{urdf.parents[1] / 'meshes' / 'collision' / 'hand.stl'}"
    scene.add(make_obstacle(("cell", 2), "mesh", (1, 1, 1), make_transform(None, [0, 0.5, 0.3]), mesh))
    assert checker.update_scene(scene) and checker.obstacle_count == 2 and not checker.scene_problems


# --- pairs ------------------------------------------------------------------------------------------


def test_srdf_pairs_are_not_checked(panda):
    model, collision = panda
    srdf = read_disabled_pairs(panda_files()[1].read_bytes(), "panda.srdf")
    assert len(srdf) == 35
    checked = set(collision.pairs.checked)
    assert not checked & set(srdf)
    assert len(checked) == 55 - 35  # 11 links with geometry
    assert ("panda_hand", "panda_link1") in checked


def test_sampled_pairs_follow_the_setup_assistant(panda):
    model, with_srdf = panda
    urdf, srdf, share = panda_files()
    sampled = load_collision_model(model, srdf=None, mesh_search_path=share, samples=1000, seed=3)
    again = load_collision_model(model, srdf=None, mesh_search_path=share, samples=1000, seed=3)
    assert sampled.pairs == again.pairs  # seeded: deterministic
    reasons = sampled.pairs.disabled
    srdf_reasons = read_disabled_pairs(srdf.read_bytes(), str(srdf))
    adjacent = {pair for pair, reason in srdf_reasons.items() if reason == "Adjacent"}
    assert adjacent <= {pair for pair, reason in reasons.items() if reason == "Adjacent"}
    # In contact at rest (the start configuration): never checked.
    rest = CollisionChecker(model, load_collision_model(model, mesh_search_path=share, samples=1))
    for pair in rest.link_distances(model.start_configuration()):
        if pair.distance <= 0:
            assert link_pair(*pair.pair) in reasons
    # Never-in-contact pairs found by sampling match MoveIt's own list closely.
    assert set(sampled.pairs.checked) <= set(with_srdf.pairs.checked)
    assert len(sampled.pairs.checked) >= len(with_srdf.pairs.checked) - 4


def test_bad_srdf_and_urdf_name_the_file_and_field(panda, tmp_path):
    model, _ = panda
    urdf, _, share = panda_files()
    bad = tmp_path / "bad.srdf"
    bad.write_text('<robot name="x"><disable_collisions link1="panda_link0" link2="wheel" reason="Never"/></robot>')
    with pytest.raises(ModelFileError, match=r"bad\.srdf.*disable_collisions\[#1\]@link2.*'wheel'"):
        load_collision_model(model, srdf=bad, mesh_search_path=share)
    bad.write_text("<robot><disable_collisions")
    with pytest.raises(ModelFileError, match=r"bad\.srdf.*malformed XML"):
        load_collision_model(model, srdf=bad, mesh_search_path=share)
    with pytest.raises(
        ModelFileError, match=r"link\[panda_link0\]/collision\[1\]/geometry/mesh@filename.*set mesh_search_path"
    ):
        load_collision_model(model, srdf=panda_files()[1], mesh_search_path=str(tmp_path))
    text = BALL_ARM_URDF.replace('<sphere radius="0.05"/>', '<sphere radius="-1"/>')
    with pytest.raises(ModelFileError, match=r"link\[link2\]/collision\[1\]/geometry/sphere"):
        load_collision_model(load_urdf_string(text, tip_link="tip"), text)


# --- path check ----------------------------------------------------------------------------------


def test_first_collision_along_a_path_says_where_and_which_pair(ball_arm):
    model, collision = ball_arm
    path = np.linspace([-1.0, 0.4, 0.8], [1.0, 0.4, 0.8], 201)
    centre = ball_centres(model, path[150])[1][1] + np.array([0.0, 0.0, 0.05])
    scene = Scene()
    scene.add(make_obstacle(("cell", 4), "sphere", (0.06,) * 3, make_transform(None, centre)))
    found = first_collision_along(model, collision, scene, path)
    distances = [ball_obstacle_distance(model, q, centre, 0.03) for q in path]
    first = next(i for i, d in enumerate(distances) if d < 0)
    assert found.index == first and found.fraction == pytest.approx(first / 200)
    assert found.pair == ("link3", "obstacle:cell/4") and found.distance < 0
    assert "link3 and obstacle:cell/4 collide" in found.reason
    clear = first_collision_along(model, collision, scene, path[:first])
    assert clear is None
    margin = first_collision_along(model, collision, scene, path, clearance=0.05)
    assert margin.index < first


# --- manip_kin check --------------------------------------------------------------------------------


def test_check_cli_reports_the_closest_pairs(capsys):
    urdf, srdf, share = panda_files()
    common = ["check", "--robot", str(urdf), "--srdf", str(srdf), "--mesh-search-path", share, "--json"]
    assert main([*common, "--q", *map(str, PANDA_READY)]) == 0
    free = json.loads(capsys.readouterr().out)
    distances = [pair["distance"] for pair in free["pairs"]]
    assert not free["collides"] and distances == sorted(distances) and distances[0] > 0.1
    assert free["checked_pairs"] == 20 and free["disabled_pairs"] == 35
    assert main([*common, "--q", *map(str, PANDA_FOLDED), "--count", "2"]) == 1
    folded = json.loads(capsys.readouterr().out)
    assert folded["collides"] and len(folded["pairs"]) == 2
    assert (folded["pairs"][0]["first"], folded["pairs"][0]["second"]) == ("panda_link1", "panda_hand")
    assert folded["pairs"][0]["distance"] < -0.03


def test_check_cli_distance_is_the_closed_form_one(tmp_path, capsys):
    path = tmp_path / "ball_arm.urdf"
    path.write_text(BALL_ARM_URDF)
    model = load_urdf_string(BALL_ARM_URDF, tip_link="tip")
    q = [0.3, -0.9, 1.2]
    assert main(["check", "--robot", str(path), "--tip-link", "tip", "--q", *map(str, q), "--json"]) == 0
    pairs = json.loads(capsys.readouterr().out)["pairs"]
    _, centre, radius = ball_centres(model, q)[1]
    base = next(pair for pair in pairs if (pair["first"], pair["second"]) == ("base_link", "link3"))
    assert base["distance"] == pytest.approx(point_box_distance(centre, *BALL_ARM_BASE_BOX) - radius, abs=1e-6)


def test_check_cli_errors_are_one_line_exit_2(capsys):
    assert main(["check", "--robot", "genova7"]) == 2
    assert "needs the robot's URDF" in capsys.readouterr().err
    urdf, _, share = panda_files()
    assert main(["check", "--robot", str(urdf), "--mesh-search-path", share, "--srdf", "/nonexistent.srdf"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "/nonexistent.srdf" in error
