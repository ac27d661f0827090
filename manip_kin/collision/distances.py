"""Distances every control cycle: the pairs within an influence distance and their damper rows.

:class:`CollisionChecker` holds one robot's collision model and the scene's obstacles (their
shapes rebuilt only when ``scene.version`` moves). Each cycle
(:meth:`CollisionChecker.evaluate`):

1. every frame and joint twist (one generated function) and the pose of every shape (one
   batched product);
2. a broad phase drops the pairs that cannot be within the influence distance ``d_i``: each
   pair keeps a lower bound on its distance, the larger of the gap between bounding spheres
   and the distance last computed less a joint-rate bound on how far its shapes moved since
   (:func:`~manip_kin.collision.geometry.joint_reach`); while that bound has not spent
   :data:`BAND`, only the pairs within ``d_i + BAND`` at the last full pass are looked at,
   and a pair found beyond ``d_i`` plus what is left of the band is not looked at again;
3. the narrow phase (:mod:`~manip_kin.collision.narrow_phase`: coal, from C++ where that can be
   built, else through its Python bindings) computes the distance ``d`` and witness points
   ``p_a``, ``p_b`` of the others (convex shapes: about 1 µs a pair from C++; negative ``d`` is
   the penetration depth). The native one runs steps 1 (but the generated function) to 4 in
   one call (``mk_narrow_near``); the Python code here is their reference;
4. each pair with ``d < d_i`` becomes a velocity-damper row (Faverjon and Tournassoud)::

       n·(J_a(p_a) - J_b(p_b)) q̇  <=  ξ (d - d_s) / (d_i - d_s)

   with ``n`` the unit normal from ``a`` to ``b``, ``J(p)`` the linear Jacobian of the
   witness point on its link (zero on an obstacle), ``d_s`` the safety distance and ``ξ``
   the gain [m/s]: the closing speed ``-ḋ`` may not exceed ``ξ`` at ``d_i`` and falls to
   zero at ``d_s``, so ``d`` approaches ``d_s`` at most exponentially and never crosses it.
   With a stopping ``travel`` per joint, ``d`` is first lessened by what the pair closes over
   it (see :meth:`CollisionChecker.evaluate`).

Shapes fixed on the base are not paired with obstacles: no joint can move them apart.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from manip_kin.collision.collision_model import CollisionModel
from manip_kin.collision.geometry import (
    CollisionShape,
    frame_values,
    frames_and_twists,
    joint_reach,
    obstacle_shape,
    sphere_centres,
)
from manip_kin.collision.narrow_phase import NativeNarrowPhase, make_narrow_phase
from manip_kin.collision.pair_distance import DamperRows, PairDistance, obstacle_name
from manip_kin.collision.python_narrow_phase import ROW_WIDTH, PythonNarrowPhase
from manip_kin.core.model import RobotModel
from manip_kin.core.scene import Scene
from manip_kin.errors import ModelFileError

#: Pairs this far beyond the cutoff [m] are checked every cycle too, so that the others can be
#: left out for the cycles it takes the joints to spend it (see :meth:`CollisionChecker._near_pairs`).
BAND = 0.005
_NO_COLUMNS = np.zeros((0, ROW_WIDTH))


class CollisionChecker:
    """Distances between a robot's links and to the scene's obstacles (see the module docstring).

    Not thread-safe: it reuses coal transforms and request/result objects, and keeps a lower
    bound on each pair's distance between calls.

    Args:
        model: the robot.
        collision_model: its shapes and self-collision pairs.
        mesh_search_path: for ``package://`` mesh obstacles.
        native: use the native narrow phase where it can be built
            (:func:`~manip_kin.collision.narrow_phase.make_narrow_phase`; the same answers, faster).
    """

    def __init__(
        self, model: RobotModel, collision_model: CollisionModel, mesh_search_path: str = "", native: bool = True
    ):
        self.model = model
        self.collision_model = collision_model
        self.mesh_search_path = mesh_search_path
        # Also builds the unrolled kinematics of every frame now, not in the first control cycle.
        self._twists = frames_and_twists(model, model.start_configuration())[1]
        # Each shape's pose in its frame with its bounding-sphere centre as a fifth column:
        # one product per cycle places both, shape (G, 4, 5).
        centres = np.concatenate([collision_model.centres, np.ones((len(collision_model.centres), 1))], axis=1)
        self._offsets_and_centres = np.concatenate(
            [collision_model.offsets, (collision_model.offsets @ centres[:, :, None])], axis=2
        )
        geometries = collision_model.geometries
        self._robot_count = len(geometries)
        self._robot_names = [g.link for g in geometries]
        self._robot_frames = [g.frame for g in geometries]
        #: The narrow phase (native or Python, see :mod:`manip_kin.collision.narrow_phase`) and
        #: why it is not the native one ("" when it is).
        self._robot_shapes = [g.shape for g in geometries]
        self.narrow_phase, self.narrow_phase_problem = make_narrow_phase(self._robot_shapes, native)
        if isinstance(self.narrow_phase, NativeNarrowPhase):
            self.narrow_phase.set_placement(model.dof + 1, collision_model.frames, self._offsets_and_centres)
        self._scene_version: int | None = None
        #: Why obstacles of the last scene taken were left out (empty: all were taken).
        self.scene_problems: tuple[str, ...] = ()
        self._set_obstacles([], [])

    # --- scene ---------------------------------------------------------------------------------

    def update_scene(self, scene: Scene) -> bool:
        """Take the scene's obstacles if ``scene.version`` moved; True when rebuilt.

        An obstacle whose shape cannot be built (a mesh file not found or unreadable) is left
        out, with its reason in :attr:`scene_problems`; the others apply.
        """
        if scene.version == self._scene_version:
            return False
        obstacles, shapes, problems = [], [], []
        for obstacle in scene.obstacles:
            try:
                shapes.append(obstacle_shape(obstacle, self.mesh_search_path))
            except ModelFileError as error:
                problems.append(str(error))
                continue
            obstacles.append(obstacle)
        self._set_obstacles(obstacles, shapes)
        self.scene_problems = tuple(problems)
        self._scene_version = scene.version
        return True

    def _set_obstacles(self, obstacles: Sequence, shapes: Sequence[CollisionShape]) -> None:
        """One table of shapes (robot, then obstacles) and pairs (self, then robot-obstacle)."""
        cm, count = self.collision_model, self._robot_count
        self._obstacle_count = len(obstacles)
        self._names = self._robot_names + [obstacle_name(o.key) for o in obstacles]
        self._frames = self._robot_frames + [0] * len(obstacles)
        poses = np.array([o.pose_in_base for o in obstacles]).reshape(-1, 4, 4)
        self._obstacle_centres = sphere_centres(poses, np.array([s.centre for s in shapes]).reshape(-1, 3))
        radii = np.concatenate([cm.radii, [s.radius for s in shapes]])
        moving = np.flatnonzero(cm.frames > 0)
        grid = [(g, count + o) for o in range(len(obstacles)) for g in moving]
        pairs = np.concatenate([cm.self_pairs, np.array(grid, dtype=int).reshape(-1, 2)])
        self._pairs = pairs
        first, second = pairs[:, 0], pairs[:, 1]
        self._first_list, self._second_list = first.tolist(), second.tolist()
        self._radius_sums = radii[first] + radii[second]
        self._labels = [f"{self._names[a]}-{self._names[b]}" for a, b in pairs.tolist()]
        # Which joints move each pair's shapes (frame i moves with joints 1..i; obstacles: none).
        frames = np.array(self._frames)
        joints = np.arange(self.model.dof)[None, :]
        self._moves_first = (joints < frames[first][:, None]).astype(float)
        self._moves_second = (joints < frames[second][:, None]).astype(float)
        # Pair-by-shape matrices: ``moved @ _pair_sums`` adds each pair's two robot shapes'
        # motions, ``_pair_differences @ centres`` subtracts its sphere centres.
        rows = np.arange(len(pairs))
        self._pair_sums = np.zeros((count, len(pairs)))
        for column in (first, second):
            robot = column < count
            self._pair_sums[column[robot], rows[robot]] += 1.0
        self._pair_differences = np.zeros((len(pairs), count + len(obstacles)))
        self._pair_differences[rows, first] = 1.0
        self._pair_differences[rows, second] -= 1.0
        self._centres = np.zeros((count + len(obstacles), 3))
        self._centres[count:] = self._obstacle_centres
        # |Δq| @ _reach_pairs bounds how much each pair's distance can fall (see _near_pairs). A
        # joint that moves both shapes of a pair moves them as one body: it leaves their distance.
        reach = joint_reach(self.model, cm.frames, cm.offsets, cm.centres, cm.radii) @ self._pair_sums
        self._reach_pairs = reach * (1.0 - self._moves_first * self._moves_second).T
        self._reach_most_array = self._reach_pairs.max(axis=1, initial=0.0)
        self._reach_most = self._reach_most_array.tolist()
        try:
            self.narrow_phase.set_scene(shapes, poses, pairs)
        except ValueError as error:  # the native one could not take a shape coal's Python bindings could
            self.narrow_phase_problem = str(error)
            self.narrow_phase = PythonNarrowPhase(self._robot_shapes)
            self.narrow_phase.set_scene(shapes, poses, pairs)
        # The native narrow phase runs this broad phase and the damper rows itself, in the same call.
        self._native_broad = isinstance(self.narrow_phase, NativeNarrowPhase)
        if self._native_broad:
            self.narrow_phase.set_broad_phase(
                BAND, self._radius_sums, self._reach_pairs, self._reach_most_array, self._moves_first,
                self._moves_second, self._obstacle_centres.reshape(-1, 3),
            )  # fmt: skip
        # A lower bound on each pair's distance, valid at the configuration _previous.
        self._lower = np.full(len(pairs), -math.inf)
        # The configuration of the last call, and per joint the sum of |Δq| since the last
        # full pass (the lower bounds' own configuration).
        self._previous: list[float] | None = None
        self._travel = [0.0] * self.model.dof
        # The pairs of the last full pass within its cutoff + BAND, that cutoff, and what is left
        # of BAND after the joints' motion since: the most any pair can have come nearer.
        self._near_rows: list[int] = []
        self._near_cutoff: float | None = None
        self._budget = 0.0
        #: How many pairs coal computed in the last call (the others were skipped).
        self.pairs_computed = 0

    @property
    def shape_pairs(self) -> np.ndarray:
        """The checked pairs as shape indices ``(first, second)``: robot shapes in the collision
        model's order, then the obstacles taken; shape (P, 2)."""
        return self._pairs

    @property
    def reach_most(self) -> np.ndarray:
        """Per joint, the most any checked pair's distance can fall per unit of its motion
        [m per rad | m per m] (:func:`~manip_kin.collision.geometry.joint_reach`), shape (n,)."""
        return self._reach_most_array

    @property
    def obstacle_count(self) -> int:
        """Obstacles currently taken from the scene."""
        return self._obstacle_count

    # --- distances -----------------------------------------------------------------------------

    def _place(self, q: np.ndarray) -> np.ndarray:
        """The robot shapes' rotations, origins and bounding-sphere centres in base at ``q``:
        ``[R | t | c]``, shape (G, 3, 5); keeps the joints' twists for the damper rows."""
        frames, self._twists = frames_and_twists(self.model, q)
        return np.matmul(frames[self.collision_model.frames, :3], self._offsets_and_centres)

    def _near_pairs(
        self, q: np.ndarray, cutoff: float, damper: tuple[float, float, float] | None = None, travel=None
    ) -> tuple[list[int], np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The pair rows nearer than ``cutoff``, their narrow-phase columns (distance, witness
        points, normal, damper features: :mod:`~manip_kin.collision.narrow_phase`), shape
        (k, 22), and with ``damper`` (``(d_i, d_s, ξ)``) their damper rows (:meth:`_damper_matrix`)
        and bounds, else None and None; with ``travel`` too, only the pairs whose distance less
        what they close over it is within ``d_i`` (:meth:`evaluate`). Updates the lower bounds
        (see :meth:`pair_distances`). The native narrow phase does all of it in C++
        (``mk_narrow_near``); this is the reference it is held to.

        Since the last call each shape moved by at most ``Σ_j |Δq_j| · reach[j]``
        (:func:`~manip_kin.collision.geometry.joint_reach`, whatever the path between the two
        configurations), so a pair's distance fell by at most its two shapes' bounds: the lower
        bound carried from the last call less those stays one.
        """
        if self._native_broad:
            rows, columns, matrix, bound, self.pairs_computed = self.narrow_phase.near_pairs(
                q, frame_values(self.model, q), cutoff, damper, travel
            )
            return rows, columns, matrix, bound
        placed = self._place(q)
        q_values = q.tolist()
        if self._previous is not None:
            step = [abs(a - b) for a, b in zip(q_values, self._previous)]
            self._travel = [t + d for t, d in zip(self._travel, step)]
            self._budget -= sum(d * r for d, r in zip(step, self._reach_most))
        self._previous = q_values
        lower = self._lower
        if cutoff == self._near_cutoff and self._budget > 0.0:
            # Every pair left out at the last full pass was BAND beyond the cutoff, and none can
            # have come nearer by more than the budget spent since: only the near ones again.
            rows = self._near_rows
        else:
            lower -= np.array(self._travel) @ self._reach_pairs
            self._travel = [0.0] * len(q_values)
            centres = self._centres
            centres[: self._robot_count] = placed[:, :, 4]
            gaps = self._pair_differences @ centres
            # The gap between bounding spheres is a lower bound too: keep the larger.
            np.maximum(lower, np.sqrt(np.einsum("ij,ij->i", gaps, gaps)) - self._radius_sums, out=lower)
            rows = self._near_rows = np.flatnonzero(lower < cutoff + BAND).tolist()
            self._near_cutoff, self._budget = cutoff, BAND
        self.pairs_computed = len(rows)
        if not rows:
            return [], _NO_COLUMNS, None, None
        columns = self.narrow_phase.compute(placed, rows, cutoff)
        distances = columns[:, 0]
        lower[rows] = distances
        # A pair found at cutoff + budget or beyond cannot come within the cutoff before the
        # budget is spent (it is what the pair may still come nearer): it leaves the near rows,
        # so a still arm computes only the pairs it must.
        near = (distances < cutoff + self._budget).tolist()
        self._near_rows = [row for row, keep in zip(rows, near) if keep]
        found = (distances < cutoff).tolist()
        if not all(found):
            rows, columns = [row for row, keep in zip(rows, found) if keep], columns[found]
        if damper is None or not rows:
            return rows, columns, None, None
        influence, safety, gain = damper
        matrix = self._damper_matrix(rows, columns)
        left = columns[:, 0]
        if travel is not None:
            left = left - np.maximum(matrix @ travel, 0.0)
            keep = left < influence
            rows = [row for row, kept in zip(rows, keep.tolist()) if kept]
            columns, matrix, left = columns[keep], matrix[keep], left[keep]
        return rows, columns, matrix, gain * (left - safety) / (influence - safety)

    def _pair(self, row: int, columns: np.ndarray) -> PairDistance:
        """The :class:`PairDistance` of pair ``row`` from its narrow-phase columns."""
        names = self._names
        return PairDistance(
            names[self._first_list[row]],
            names[self._second_list[row]],
            float(columns[0]),
            columns[1:4].copy(),
            columns[4:7].copy(),
            columns[7:10].copy(),
        )

    def pair_distances(self, q: np.ndarray, cutoff: float = math.inf) -> list[PairDistance]:
        """Every checked pair of shapes closer than ``cutoff`` [m], with its distance; unsorted.

        ``q``: joint positions, shape (n,), a float array. A pair is skipped when a lower bound
        on its distance is ``cutoff`` or more: the gap between bounding spheres, or the distance
        last computed minus how far each shape has moved since (see :meth:`_near_pairs`).
        Between nearby configurations (a control loop, a sampled path) most far pairs are
        therefore computed once and skipped afterwards.
        """
        rows, columns, _, _ = self._near_pairs(q, cutoff)
        return [self._pair(row, line) for row, line in zip(rows, columns)]

    def link_distances(self, q: np.ndarray) -> list[PairDistance]:
        """The distance of every checked link pair and link-obstacle pair (the nearest of their
        shapes), nearest first."""
        nearest: dict[tuple[str, str], PairDistance] = {}
        for pair in self.pair_distances(q):
            known = nearest.get(pair.pair)
            if known is None or pair.distance < known.distance:
                nearest[pair.pair] = pair
        return sorted(nearest.values(), key=lambda pair: pair.distance)

    def evaluate(
        self,
        q: np.ndarray,
        influence_distance: float,
        safety_distance: float,
        gain: float,
        travel: np.ndarray | None = None,
    ) -> DamperRows:
        """The velocity-damper rows of the pairs within ``influence_distance`` (see the module docstring).

        Args:
            q: joint positions, shape (n,), a float array.
            influence_distance: ``d_i`` [m], > ``safety_distance``.
            safety_distance: ``d_s`` [m], >= 0.
            gain: ``ξ`` [m/s], > 0: the closing speed allowed at ``d_i``.
            travel: each joint's travel until the command comes to rest, signed, shape (n,)
                [rad | m], or None. Each pair's ``d`` is then first lessened by what it closes
                over it, ``max(0, n·(J_a − J_b) travel)``, in its row's bound and in the choice of
                the rows (those left within ``d_i``), and the pairs within ``d_i`` plus the most
                any shape can move over it are looked at (:class:`~manip_kin.control.qp.limits.CollisionLimit`).
                :attr:`DamperRows.distances` and the nearest pair stay the distances themselves.
        """
        cutoff = influence_distance
        if travel is not None:
            reach = float(np.abs(travel) @ self._reach_most_array)  # the most any pair closes over it
            # Whole bands: a cutoff that stays the same from cycle to cycle keeps the broad
            # phase's near rows (a new cutoff is a full pass).
            cutoff += BAND * math.ceil(reach / BAND)
        rows, columns, matrix, bound = self._near_pairs(q, cutoff, (influence_distance, safety_distance, gain), travel)
        if not rows:
            return DamperRows((), np.zeros(0), np.zeros((0, self.model.dof)), np.zeros(0), None)
        distances = columns[:, 0].copy()
        labels = self._labels
        nearest = int(distances.argmin())
        return DamperRows(
            tuple(labels[row] for row in rows),
            distances,
            matrix,
            bound,
            # Reported within d_i only, as the status documents (a row kept for its travel may be beyond).
            self._pair(rows[nearest], columns[nearest]) if distances[nearest] < influence_distance else None,
        )

    def _damper_matrix(self, rows: list[int], columns: np.ndarray) -> np.ndarray:
        """``n·(J_a(p_a) − J_b(p_b))`` of each pair of ``rows`` (their narrow-phase columns
        ``columns``) at the ``q`` of the last query, shape (k, n).

        A point ``p`` moving with joint j has the velocity ``v_j + ω_j × p`` per unit rate
        (``[ω_j; v_j]`` the joint's twist), so ``n·J(p)`` column j is ``(p × n)·ω_j + n·v_j``:
        the features ``[p × n, n]`` of both sides times the (6, n) twists.
        """
        twists = self._twists
        return (columns[:, 10:16] @ twists) * self._moves_first[rows] - (
            columns[:, 16:22] @ twists
        ) * self._moves_second[rows]
