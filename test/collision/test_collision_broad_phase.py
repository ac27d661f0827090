"""The checker's skipping is conservative: no pair within the cutoff is ever left out.

The checker skips a pair when a lower bound on its distance is at the cutoff or beyond: the
gap between bounding spheres, or the distance last computed less a joint-rate bound on how
far the shapes moved since. Along random walks of the Panda among random obstacles, every
pair's true distance is computed here with coal directly (numpy forward kinematics, fresh
coal objects, no broad phase) and each pair nearer than the cutoff must be in the checker's
answer, at the same distance. Both broad phases: the checker's Python one, and the native
narrow phase's C++ one (``mk_narrow_near``).
"""

import coal
import numpy as np
import pytest
from collision_robots import fresh_coal_distance
from hypothesis import given, settings
from hypothesis import strategies as st

from manip_kin.collision.distances import BAND, CollisionChecker
from manip_kin.collision.geometry import joint_reach
from manip_kin.core.kinematics import frame_poses
from manip_kin.core.rotations import make_transform
from manip_kin.core.scene import Scene, make_obstacle

CUTOFF = 0.1
BOTH = pytest.mark.parametrize("native", [True, False], ids=["native", "python"])


def _checker(model, collision, scene, native: bool) -> CollisionChecker:
    checker = CollisionChecker(model, collision, native=native)
    checker.update_scene(scene)
    assert checker.narrow_phase.name == ("native" if native else "python"), checker.narrow_phase_problem
    return checker


def _true_distances(model, collision, obstacles, q) -> list[tuple[str, float]]:
    """``(label, distance)`` of every checked pair at ``q``, each pair by coal alone."""
    frames = frame_poses(model, q)
    robot = [(g.link, g.shape.coal_shape, frames[g.frame] @ g.offset, g.frame) for g in collision.geometries]
    checked = set(collision.pairs.checked)
    pairs = [(a, b) for i, a in enumerate(robot) for b in robot[i + 1 :] if tuple(sorted((a[0], b[0]))) in checked]
    pairs += [(a, b) for b in obstacles for a in robot if a[3] > 0]  # shapes on the base never meet obstacles
    found = []
    for (name_a, shape_a, pose_a, _), (name_b, shape_b, pose_b, _) in pairs:
        found.append((f"{name_a}-{name_b}", fresh_coal_distance(shape_a, pose_a, shape_b, pose_b)[0]))
    return found


@given(
    start=st.lists(st.floats(0.0, 1.0), min_size=7, max_size=7),
    steps=st.lists(st.tuples(st.integers(0, 6), st.floats(-1.0, 1.0), st.integers(1, 8)), min_size=4, max_size=10),
    centres=st.lists(
        st.tuples(st.floats(-0.2, 0.7), st.floats(-0.5, 0.5), st.floats(0.0, 0.9)), min_size=1, max_size=3
    ),
    radius=st.floats(0.03, 0.15),
    # 0.01: steps of at most 10 mrad, a few to a dozen within one band (what a control loop does).
    scale=st.sampled_from([1.0, 0.01, 0.001]),
)
@settings(max_examples=40, deadline=None)
@BOTH
def test_no_pair_within_the_cutoff_is_skipped_along_a_walk(panda, native, start, steps, centres, radius, scale):
    model, collision = panda
    scene = Scene()
    obstacles = []
    for k, centre in enumerate(centres):
        pose = make_transform(None, centre)
        kind, size = ("sphere", (2 * radius,) * 3) if k % 2 == 0 else ("box", (radius, 2 * radius, 3 * radius))
        scene.add(make_obstacle(("cell", k), kind, size, pose))
        shape = coal.Sphere(radius) if kind == "sphere" else coal.Box(*size)
        obstacles.append((f"obstacle:cell/{k}", shape, pose, 0))
    checker = _checker(model, collision, scene, native)
    # Anywhere in the joint ranges: folded arms bring link pairs near each other too.
    q = model.lower + np.array(start) * (model.upper - model.lower)
    # A walk: one joint at a time, in one to eight equal steps (small steps as in a control
    # loop carry the lower bounds; the large ones test the bound's size).
    configurations = [q]
    for joint, move, count in steps:
        for _ in range(count):
            q = q.copy()
            q[joint] = np.clip(q[joint] + scale * move / count, model.lower[joint], model.upper[joint])
            configurations.append(q)
    for q in configurations:
        answer = sorted((p.label, p.distance) for p in checker.pair_distances(q, CUTOFF))
        truth = sorted((label, d) for label, d in _true_distances(model, collision, obstacles, q) if d < CUTOFF)
        assert [label for label, _ in answer] == [label for label, _ in truth], q.tolist()
        assert [d for _, d in answer] == pytest.approx([d for _, d in truth], abs=1e-6)


@given(
    q0=st.lists(st.floats(-2.5, 2.5), min_size=7, max_size=7),
    q1=st.lists(st.floats(-2.5, 2.5), min_size=7, max_size=7),
    direction=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)),
)
@settings(max_examples=60, deadline=None)
def test_joint_reach_bounds_how_far_any_point_of_a_shape_moves(panda, q0, q1, direction):
    model, collision = panda
    reach = joint_reach(model, collision.frames, collision.offsets, collision.centres, collision.radii)
    bound = np.abs(np.array(q1) - np.array(q0)) @ reach
    unit = np.array(direction)
    unit = unit / np.linalg.norm(unit) if np.linalg.norm(unit) > 1e-6 else np.array([1.0, 0.0, 0.0])
    frames = [frame_poses(model, q) for q in (q0, q1)]
    for g, geometry in enumerate(collision.geometries):
        # A point on the bounding sphere's surface, in the shape's frame.
        local = geometry.offset @ np.append(geometry.shape.centre + geometry.shape.radius * unit, 1.0)
        moved = np.linalg.norm(frames[1][geometry.frame] @ local - frames[0][geometry.frame] @ local)
        assert moved <= bound[g] + 1e-12, geometry.link
    assert np.all(reach[:, collision.frames == 0] == 0.0)


@given(start=st.lists(st.floats(0.0, 1.0), min_size=7, max_size=7))
@settings(max_examples=10, deadline=None)
@BOTH
def test_a_still_arm_computes_only_the_pairs_within_the_band(panda, native, start):
    model, collision = panda
    scene = Scene()
    scene.add(make_obstacle(("cell", 0), "sphere", (0.2,) * 3, make_transform(None, [0.4, 0.0, 0.5])))
    obstacles = [("obstacle:cell/0", coal.Sphere(0.1), make_transform(None, [0.4, 0.0, 0.5]), 0)]
    checker = _checker(model, collision, scene, native)
    q = model.lower + np.array(start) * (model.upper - model.lower)
    truth = _true_distances(model, collision, obstacles, q)
    checker.pair_distances(q, CUTOFF)
    first = checker.pairs_computed  # the full pass: every pair whose bounding spheres are near
    for _ in range(3):
        answer = sorted(p.label for p in checker.pair_distances(q.copy(), CUTOFF))
        assert answer == sorted(label for label, d in truth if d < CUTOFF)
        # Unmoved, the band is whole: what is computed is what lies within cutoff + BAND.
        assert checker.pairs_computed == sum(d < CUTOFF + BAND for _, d in truth) <= first


@BOTH
def test_a_pair_found_just_beyond_the_cutoff_is_followed_as_it_comes_near(panda, native):
    """The hand turns with joint 1 towards a ball first found 1 mm beyond the cutoff, in steps
    of 0.1 mrad (well within one band): it must be reported from the step it comes within."""
    from collision_robots import PANDA_READY

    model, collision = panda
    hand = frame_poses(model, PANDA_READY)[-1][:3, 3]
    ahead = np.cross([0.0, 0.0, 1.0], hand)
    ahead /= np.linalg.norm(ahead)  # where joint 1 turns the hand

    def nearest(centre, q):
        ball = [("obstacle:cell/0", coal.Sphere(0.05), make_transform(None, centre), 0)]
        return min(d for label, d in _true_distances(model, collision, ball, q) if "obstacle" in label)

    low, high = 0.0, 0.5  # the ball's offset ahead of the hand, bisected to cutoff + 1 mm
    for _ in range(40):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if nearest(hand + middle * ahead, PANDA_READY) < CUTOFF + 0.001 else (low, middle)
    centre = hand + high * ahead
    scene = Scene()
    scene.add(make_obstacle(("cell", 0), "sphere", (0.1,) * 3, make_transform(None, centre)))
    checker = _checker(model, collision, scene, native)
    q = PANDA_READY.copy()
    crossed = None
    for step in range(200):
        near = [p for p in checker.pair_distances(q, CUTOFF) if p.second == "obstacle:cell/0"]
        within = nearest(centre, q) < CUTOFF
        assert bool(near) == within, (step, nearest(centre, q))
        if within and crossed is None:
            crossed = step
        q[0] += 1e-4
    assert crossed is not None and crossed > 5  # it came within the cutoff, several steps in
