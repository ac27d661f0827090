"""IK restarts from the seed table: the table's nearest poses, ranked by an independent FK.

The ranking is recomputed here with the core's numpy forward kinematics (not the batched
unrolled chain the table is built with) and a plain weighted pose distance.
"""

from __future__ import annotations

import numpy as np
import pytest

import manip_kin.ik.problem as problem_module
import manip_kin.ik.seeds as seeds_module
from manip_kin.core.kinematics import KinematicsData, forward_kinematics
from manip_kin.core.pose_rows import parse_task
from manip_kin.core.robots import load_robot
from manip_kin.ik.iterative import solve_ik


def _pose(model, q) -> np.ndarray:
    data = KinematicsData(model)
    forward_kinematics(model, data, np.asarray(q, dtype=float))
    return data.tool.copy()


@pytest.mark.parametrize("name", ["genova7", "irb120"])
def test_nearest_starts_are_the_table_entries_nearest_the_target(name):
    model = load_robot(name)
    frame_index = model.frame_index(model.default_frame)
    problem = problem_module.problem_for(model, frame_index, parse_task(None, model))
    rng = np.random.default_rng(3)
    target = _pose(model, model.random_configuration(rng))
    starts = np.array(problem.seeds.nearest(target.tolist(), 5))
    configurations = problem.seeds.configurations
    assert len(configurations) == seeds_module.TABLE_SIZE
    assert np.all(configurations >= model.lower) and np.all(configurations <= model.upper)
    scale = (seeds_module.ORIENTATION_SCALE * problem.reach) ** 2

    def distance(q):
        pose = _pose(model, q)
        return np.sum((pose[:3, 3] - target[:3, 3]) ** 2) + scale * np.sum((pose[:3, :3] - target[:3, :3]) ** 2)

    all_distances = np.array([distance(q) for q in configurations])
    expected = np.sort(all_distances)[:5]
    found = np.array([distance(q) for q in starts])
    # the table ranks in float32: equal up to its rounding, nearest first
    np.testing.assert_allclose(np.sort(found), expected, rtol=1e-6, atol=1e-9)
    assert np.all(np.diff(found) >= -1e-6 * found[1:])
    # and they are far nearer than a typical table entry
    assert expected[0] < 0.1 * np.median(all_distances)


def test_restarts_use_the_seed_table_first(monkeypatch):
    model = load_robot("genova7")
    rng = np.random.default_rng(5)
    target = _pose(model, model.random_configuration(rng))
    used = []
    original = seeds_module.SeedTable.pop_nearest

    def recording(self, distances):
        used.append(original(self, distances))
        return used[-1]

    monkeypatch.setattr(seeds_module.SeedTable, "pop_nearest", recording)
    # One iteration per attempt forces restarts: they start from the table's nearest entries.
    result = solve_ik(model, target, model.random_configuration(rng), max_iterations=1, restarts=3, seed=1)
    assert result.attempts == 4
    monkeypatch.undo()
    problem = problem_module.problem_for(model, model.frame_index(model.default_frame), parse_task(None, model))
    assert used == problem.seeds.nearest(target.tolist(), 3)
    # A full solve from a poor start converges within limits.
    solved = solve_ik(model, target, model.lower.copy(), seed=1)
    assert solved.success and model.within_limits(solved.q, 0.0)
    orientation = _pose(model, solved.q)[:3, :3] @ target[:3, :3].T
    assert np.linalg.norm(_pose(model, solved.q)[:3, 3] - target[:3, 3]) < 1e-5
    assert np.arccos(np.clip((np.trace(orientation) - 1) / 2, -1, 1)) < 1e-4
