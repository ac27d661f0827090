"""Which link pairs are checked for self-collision.

A pair of links is never checked when (reasons as in an SRDF):

* ``Adjacent``: the links are joined by a joint (or by links without geometry), always;
* from an SRDF, every ``disable_collisions`` entry with its reason;
* without an SRDF, as MoveIt's setup assistant computes them, by sampling (seeded, so the
  same robot always gives the same list):

  - ``Default``: in contact at rest (the model's start configuration);
  - ``Always``: in contact in at least :data:`ALWAYS_FRACTION` of the random configurations;
  - ``Never``: in contact in none of them.

Every other pair of links with geometry is checked.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from manip_kin.collision.geometry import LinkGeometry, model_frames, sphere_centres, sphere_gaps, world_poses
from manip_kin.collision.srdf import link_pair
from manip_kin.core.model import RobotModel

#: A pair in contact in at least this fraction of the samples is "Always" in collision.
ALWAYS_FRACTION = 0.95
#: Random configurations sampled when no SRDF is given (MoveIt's assistant offers 10 000).
DEFAULT_SAMPLES = 1000


@dataclass(frozen=True)
class PairSelection:
    """The self-collision pairs of a robot.

    Attributes:
        checked: link pairs checked, sorted tuples, sorted.
        disabled: link pair -> reason (``Adjacent``, ``Default``, ``Never``, ``Always`` or
            the SRDF's reason) for the pairs not checked.
    """

    checked: tuple[tuple[str, str], ...]
    disabled: Mapping[tuple[str, str], str]


def _links(geometries: Sequence[LinkGeometry]) -> list[str]:
    return list(dict.fromkeys(g.link for g in geometries))


def contact_counts(
    model: RobotModel,
    geometries: Sequence[LinkGeometry],
    link_pairs: Sequence[tuple[str, str]],
    configurations: np.ndarray,
) -> np.ndarray:
    """In how many of ``configurations`` (N, n) each link pair is in contact, shape (len(link_pairs),)."""
    import coal

    by_link: dict[str, list[int]] = {}
    for index, geometry in enumerate(geometries):
        by_link.setdefault(geometry.link, []).append(index)
    pair_rows = [(p, a, b) for p, (x, y) in enumerate(link_pairs) for a in by_link[x] for b in by_link[y]]
    if not pair_rows:
        return np.zeros(len(link_pairs), dtype=int)
    owner, first, second = (np.array(column) for column in zip(*pair_rows))
    frames = np.array([g.frame for g in geometries])
    offsets = np.array([g.offset for g in geometries])
    centres = np.array([g.shape.centre for g in geometries])
    radii = np.array([g.shape.radius for g in geometries])
    radius_sums = radii[first] + radii[second]
    shapes = [g.shape.coal_shape for g in geometries]
    transforms = [coal.Transform3s() for _ in geometries]
    request, result = coal.CollisionRequest(), coal.CollisionResult()
    counts = np.zeros(len(link_pairs), dtype=int)
    for q in configurations:
        poses = world_poses(model_frames(model, np.asarray(q, dtype=float)), frames, offsets)
        world_centres = sphere_centres(poses, centres)
        near = sphere_gaps(world_centres[first], world_centres[second], radius_sums) <= 0.0
        hit = np.zeros(len(link_pairs), dtype=bool)
        for row in np.flatnonzero(near):
            if hit[owner[row]]:
                continue
            a, b = int(first[row]), int(second[row])
            transforms[a].setTransform(poses[a, :3, :3], poses[a, :3, 3])
            transforms[b].setTransform(poses[b, :3, :3], poses[b, :3, 3])
            result.clear()
            if coal.collide(shapes[a], transforms[a], shapes[b], transforms[b], request, result):
                hit[owner[row]] = True
        counts += hit
    return counts


def sampled_disabled_pairs(
    model: RobotModel,
    geometries: Sequence[LinkGeometry],
    adjacent: set[tuple[str, str]],
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
) -> dict[tuple[str, str], str]:
    """The pairs MoveIt's setup assistant would disable (see the module docstring), sampled with ``seed``."""
    disabled = {pair: "Adjacent" for pair in adjacent}
    candidates = [link_pair(a, b) for a, b in combinations(_links(geometries), 2)]
    candidates = [pair for pair in candidates if pair not in disabled]
    rest = contact_counts(model, geometries, candidates, model.start_configuration()[None, :])
    disabled.update({pair: "Default" for pair, count in zip(candidates, rest) if count})
    candidates = [pair for pair in candidates if pair not in disabled]
    rng = np.random.default_rng(seed)
    configurations = np.array([model.random_configuration(rng) for _ in range(max(int(samples), 1))])
    counts = contact_counts(model, geometries, candidates, configurations)
    for pair, count in zip(candidates, counts):
        if count == 0:
            disabled[pair] = "Never"
        elif count >= ALWAYS_FRACTION * len(configurations):
            disabled[pair] = "Always"
    return disabled


def select_pairs(
    geometries: Sequence[LinkGeometry], disabled: Mapping[tuple[str, str], str], adjacent: set[tuple[str, str]]
) -> PairSelection:
    """The checked pairs: every pair of links with geometry that is neither adjacent nor disabled."""
    reasons = {**{pair: "Adjacent" for pair in adjacent}, **dict(disabled)}
    links = _links(geometries)
    checked = sorted(pair for pair in (link_pair(a, b) for a, b in combinations(links, 2)) if pair not in reasons)
    known = {link_pair(a, b) for a, b in combinations(links, 2)}
    return PairSelection(tuple(checked), {pair: reason for pair, reason in reasons.items() if pair in known})
