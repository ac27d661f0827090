"""The narrow phase of a control cycle: coal's distance, witness points and damper features of the
pairs the broad phase kept (:class:`~manip_kin.collision.distances.CollisionChecker`).

Two backends with one interface, :meth:`compute`, and one output layout (:data:`ROW_WIDTH`
columns per pair): the distance ``d`` [m]; the witness points ``p_a``, ``p_b`` in base [m]; the
unit normal ``n`` from ``a`` to ``b``; and the damper features ``[p_a × n, n]``, ``[p_b × n, n]``
(a pair's damper row is their product with the joint twists, see
:meth:`~manip_kin.collision.distances.CollisionChecker.evaluate`).

* :class:`NativeNarrowPhase`: ``narrow_phase.cpp``, built against coal's C++ library by
  :mod:`manip_kin.codegen.native` and called once per cycle through ctypes. It builds its
  own shapes from the same descriptions as :mod:`manip_kin.collision.geometry` (a mesh as
  its convex hull, loaded and hulled by the same coal calls). :meth:`NativeNarrowPhase.near_pairs`
  also places the robot's shapes on the model's frames and runs the checker's broad phase before
  and its damper rows (with the braking's lessening) after, in the same call.
* :class:`~manip_kin.collision.python_narrow_phase.PythonNarrowPhase`: the same through coal's
  Python bindings, a few calls per pair.
  It is the fallback where the native one cannot be built (no compiler, no Eigen headers,
  ``MANIP_KIN_NATIVE=0``) and the reference the tests hold the native one to.

On the pairs the collision bench's loop asks for (the Panda, three obstacles, a median of 5 pairs
a cycle), the native call took 9.5 µs median against the Python loop's 28.9 µs (docs/collision.md).
"""

from __future__ import annotations

import ctypes
import functools
import importlib.metadata
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from manip_kin.codegen.native import NativeRecipe, NativeUnavailable, build_pending, load_library, require_enabled
from manip_kin.collision.geometry import CollisionShape
from manip_kin.collision.python_narrow_phase import ROW_WIDTH, PythonNarrowPhase
from manip_kin.core.scene import ShapeKind

#: The kind numbers ``narrow_phase.cpp`` takes.
_KIND_CODES = {ShapeKind.BOX: 0, ShapeKind.SPHERE: 1, ShapeKind.CYLINDER: 2, ShapeKind.MESH: 3}


@functools.cache
def _recipe() -> NativeRecipe:
    """How to build ``narrow_phase.cpp`` against the coal this Python imports.

    Raises:
        NativeUnavailable: coal's headers or library, or Eigen's headers, not found.
    """
    import coal

    # coal's Python package lies in <prefix>/lib/pythonX.Y/site-packages/coal (PyPI's cmeel
    # wheels and a ROS install alike); its headers and library in <prefix>/include and lib.
    prefix = Path(coal.__file__).resolve().parents[4]
    if not (prefix / "include" / "coal" / "config.hh").exists():
        raise NativeUnavailable(f"coal's C++ headers are not in {prefix / 'include'}")
    library_dir = next((prefix / d for d in ("lib", "lib64") if (prefix / d / "libcoal.so").exists()), None)
    if library_dir is None:
        raise NativeUnavailable(f"libcoal.so is not in {prefix / 'lib'}")
    eigen = next(
        (d for d in (prefix / "include" / "eigen3", Path("/usr/include/eigen3")) if (d / "Eigen" / "Core").exists()),
        None,
    )
    if eigen is None:
        raise NativeUnavailable(f"Eigen's headers are not in {prefix / 'include' / 'eigen3'} nor /usr/include/eigen3")
    try:
        version = importlib.metadata.version("coal")
    except importlib.metadata.PackageNotFoundError:
        version = str(prefix)
    return NativeRecipe(
        name="narrow_phase",
        source=Path(__file__).with_name("narrow_phase.cpp"),
        include_dirs=(str(prefix / "include"), str(eigen)),
        library_dirs=(str(library_dir),),
        libraries=("coal",),
        version=f"coal {version}",
    )


@functools.cache
def _library() -> ctypes.CDLL:
    library, _ = load_library(_recipe(), hold_gil=True)  # microseconds a cycle: the loop keeps the GIL
    pointer = ctypes.c_void_p
    library.mk_narrow_error.restype = ctypes.c_char_p
    library.mk_narrow_row_width.restype = ctypes.c_int
    library.mk_narrow_create.restype = pointer
    names = ctypes.POINTER(ctypes.c_char_p)
    library.mk_narrow_create.argtypes = [ctypes.c_int, pointer, pointer, names]
    library.mk_narrow_set_scene.restype = ctypes.c_int
    library.mk_narrow_set_scene.argtypes = [
        pointer,
        ctypes.c_int,
        pointer,
        pointer,
        names,
        pointer,
        ctypes.c_int,
        pointer,
    ]
    library.mk_narrow_destroy.argtypes = [pointer]
    library.mk_narrow_compute.restype = ctypes.c_int
    library.mk_narrow_compute.argtypes = [pointer, pointer, pointer, ctypes.c_int, pointer]
    library.mk_narrow_set_broad.restype = ctypes.c_int
    library.mk_narrow_set_broad.argtypes = [pointer, ctypes.c_int, ctypes.c_double, *[pointer] * 6]
    library.mk_narrow_set_placement.restype = ctypes.c_int
    library.mk_narrow_set_placement.argtypes = [pointer, ctypes.c_int, pointer, pointer]
    library.mk_narrow_near.restype = ctypes.c_int
    library.mk_narrow_near.argtypes = [pointer, pointer, pointer, ctypes.c_double, *[pointer] * 7]
    if library.mk_narrow_row_width() != ROW_WIDTH:
        raise NativeUnavailable(f"narrow_phase.cpp writes {library.mk_narrow_row_width()} columns, not {ROW_WIDTH}")
    return library


def _native_library() -> ctypes.CDLL:
    require_enabled()
    return _library()


def _last_error(library: ctypes.CDLL) -> str:
    """What ``narrow_phase.cpp`` said of its last failure."""
    return library.mk_narrow_error().decode(errors="replace")


def native_problem() -> str:
    """Why the native narrow phase is not used here ("" when it is); builds it on first call."""
    try:
        _native_library()
    except NativeUnavailable as error:
        return str(error)
    return ""


def native_build_pending() -> bool:
    """True when the next native narrow phase compiles ``narrow_phase.cpp`` first (about 10 s, once
    per machine): a caller may say so before it waits."""
    try:
        return build_pending(_recipe())
    except NativeUnavailable:
        return False


def _shape_arrays(shapes: Sequence[CollisionShape]):
    """The kinds, sizes (3 per shape) and mesh paths of ``shapes`` as ``narrow_phase.cpp`` takes them."""
    count = len(shapes)
    kinds = np.array([_KIND_CODES[s.kind] for s in shapes], dtype=np.intc).reshape(count)
    sizes = np.zeros((count, 3))
    for row, shape in zip(sizes, shapes):
        row[: len(shape.size)] = shape.size
    paths = (ctypes.c_char_p * max(count, 1))(*[s.source.encode() for s in shapes])
    return kinds, sizes, paths


class NativeNarrowPhase:
    """The narrow phase in C++ (see the module docstring); the interface of :class:`PythonNarrowPhase`.

    Raises:
        NativeUnavailable: it cannot be built here, or a shape cannot be made (the message says which).
    """

    name = "native"

    def __init__(self, robot_shapes: Sequence[CollisionShape]):
        library = _native_library()
        kinds, sizes, paths = _shape_arrays(robot_shapes)
        handle = library.mk_narrow_create(len(robot_shapes), kinds.ctypes.data, sizes.ctypes.data, paths)
        if not handle:
            raise NativeUnavailable(f"narrow phase: {_last_error(library)}")
        self._library, self._handle = library, handle
        self._robot_count = len(robot_shapes)
        self._compute, self._near = library.mk_narrow_compute, library.mk_narrow_near
        self.set_scene([], np.zeros((0, 4, 4)), np.zeros((0, 2), dtype=int))

    def set_scene(self, obstacle_shapes: Sequence[CollisionShape], obstacle_poses: np.ndarray, pairs) -> None:
        """As :meth:`PythonNarrowPhase.set_scene`.

        Raises:
            ValueError: a pair or an obstacle shape it cannot take (the previous scene stays).
        """
        kinds, sizes, paths = _shape_arrays(obstacle_shapes)
        poses = np.ascontiguousarray(np.asarray(obstacle_poses, dtype=float).reshape(-1, 4, 4)[:, :3, :])
        pair_array = np.ascontiguousarray(np.asarray(pairs, dtype=np.intc).reshape(-1, 2))
        status = self._library.mk_narrow_set_scene(
            self._handle, len(obstacle_shapes), kinds.ctypes.data, sizes.ctypes.data, paths, poses.ctypes.data,
            len(pair_array), pair_array.ctypes.data,
        )  # fmt: skip
        if status != 0:
            raise ValueError(f"narrow phase: {_last_error(self._library)}")
        # Buffers with fixed addresses: one call per cycle passes them without converting anything.
        self._rows = np.zeros(max(len(pair_array), 1), dtype=np.intc)
        self._out = np.zeros((max(len(pair_array), 1), ROW_WIDTH))
        self._rows_address, self._out_address = self._rows.ctypes.data, self._out.ctypes.data

    def set_placement(self, frame_count: int, shape_frames: np.ndarray, offsets_and_centres: np.ndarray) -> None:
        """Where the robot's shapes sit, for :meth:`near_pairs`: the model's ``frame_count``
        frames (base first, the layout of :func:`~manip_kin.collision.geometry.frame_values`),
        each shape's frame index, shape (G,), and its pose in that frame with its bounding-sphere
        centre as a fifth column, shape (G, 4, 5), as
        :class:`~manip_kin.collision.distances.CollisionChecker` places them."""
        frames = np.ascontiguousarray(shape_frames, dtype=np.intc).reshape(self._robot_count)
        offsets = np.ascontiguousarray(offsets_and_centres, dtype=float).reshape(self._robot_count, 4, 5)
        if self._library.mk_narrow_set_placement(self._handle, frame_count, frames.ctypes.data, offsets.ctypes.data):
            raise RuntimeError(f"narrow phase: {_last_error(self._library)}")
        self._frame_count = frame_count

    def set_broad_phase(
        self,
        band: float,
        radius_sums: np.ndarray,
        reach_pairs: np.ndarray,
        reach_most: np.ndarray,
        moves_first: np.ndarray,
        moves_second: np.ndarray,
        obstacle_centres: np.ndarray,
    ) -> None:
        """The broad phase's arrays for the pairs of the last :meth:`set_scene` (P pairs, n
        joints), as :class:`~manip_kin.collision.distances.CollisionChecker` derives them:
        ``radius_sums`` (P,) [m], ``reach_pairs`` (n, P) [m per rad | m] and its largest per joint
        ``reach_most`` (n,), ``moves_first`` and
        ``moves_second`` (P, n) of 0 and 1, ``obstacle_centres`` (m, 3) [m]; ``band`` [m]. Resets
        the bounds :meth:`near_pairs` carries between calls. After :meth:`set_placement`."""
        pairs, dof = np.shape(moves_first)
        arrays = [
            np.ascontiguousarray(a, dtype=float)
            for a in (radius_sums, reach_pairs, reach_most, moves_first, moves_second, obstacle_centres)
        ]
        if self._library.mk_narrow_set_broad(self._handle, dof, band, *[a.ctypes.data for a in arrays]):
            raise RuntimeError(f"narrow phase: {_last_error(self._library)}")
        self._found_rows = np.zeros(max(pairs, 1), dtype=np.intc)
        self._found_columns = np.zeros((max(pairs, 1), ROW_WIDTH))
        self._matrix = np.zeros((max(pairs, 1), dof))
        self._bound = np.zeros(max(pairs, 1))
        self._counts = np.zeros(2, dtype=np.intc)
        # The inputs too: copying into a buffer costs less than asking an array for its address.
        self._q, self._frames = np.zeros(dof), np.zeros(16 * self._frame_count + 6 * dof)
        self._damper, self._travel = np.zeros(3), np.zeros(dof)
        self._addresses = [a.ctypes.data for a in (self._q, self._frames, self._damper, self._travel)]
        self._near_addresses = [
            a.ctypes.data for a in (self._found_rows, self._found_columns, self._matrix, self._bound, self._counts)
        ]

    def near_pairs(
        self,
        q: np.ndarray,
        frames: Sequence[float],
        cutoff: float,
        damper: tuple[float, float, float] | None = None,
        travel: np.ndarray | None = None,
    ) -> tuple[list[int], np.ndarray, np.ndarray | None, np.ndarray | None, int]:
        """The shapes placed on ``frames``, the broad phase of
        :meth:`~manip_kin.collision.distances.CollisionChecker._near_pairs` (its reference) and
        this narrow phase in one call: the pair rows nearer than ``cutoff`` [m], their columns
        (a view the next call overwrites), with ``damper`` their damper rows (k, n) and bounds
        (k,) [m/s], else None and None, and how many pairs were computed.

        Args:
            q: joint positions, shape (n,).
            frames: the model's frames and joint twists, flat
                (:func:`~manip_kin.collision.geometry.frame_values`).
            damper: ``(d_i, d_s, ξ)`` [m, m, m/s].
            travel: with ``damper``, each joint's stopping travel, shape (n,) [rad | m]: each
                distance is lessened by what the pair closes over it, and only the pairs left
                within ``d_i`` are kept (:meth:`~manip_kin.collision.distances.CollisionChecker.evaluate`).
        """
        self._q[:] = q
        self._frames[:] = frames
        q_address, frames_address, damper_address, travel_address = self._addresses
        if damper is None:
            damper_address = travel_address = None
        else:
            self._damper[:] = damper
            if travel is None:
                travel_address = None
            else:
                self._travel[:] = travel
        if self._near(
            self._handle, q_address, frames_address, cutoff, damper_address, travel_address, *self._near_addresses
        ):
            raise RuntimeError(f"narrow phase: {_last_error(self._library)}")
        found, computed = self._counts.tolist()
        if damper is None:
            return self._found_rows[:found].tolist(), self._found_columns[:found], None, None, computed
        return (
            self._found_rows[:found].tolist(),
            self._found_columns[:found],
            self._matrix[:found].copy(),
            self._bound[:found].copy(),
            computed,
        )

    def __del__(self):
        handle, self._handle = getattr(self, "_handle", None), None
        if handle:
            self._library.mk_narrow_destroy(handle)

    def compute(self, placed: np.ndarray, rows: Sequence[int], cutoff: float) -> np.ndarray:
        """As :meth:`PythonNarrowPhase.compute`, every column filled; the result is a view into a
        buffer the next call overwrites."""
        count = len(rows)
        self._rows[:count] = rows
        placed = np.ascontiguousarray(placed, dtype=float)
        if self._compute(self._handle, placed.ctypes.data, self._rows_address, count, self._out_address) != 0:
            raise RuntimeError(f"narrow phase: {_last_error(self._library)}")
        return self._out[:count]


def make_narrow_phase(robot_shapes: Sequence[CollisionShape], native: bool = True):
    """The narrow phase for ``robot_shapes``: the native one where it can be built (unless
    ``native`` is False: a one-off query gains nothing from it), else the Python one; and why
    it is not the native one ("" when it is)."""
    if not native:
        return PythonNarrowPhase(robot_shapes), "not asked for"
    try:
        return NativeNarrowPhase(robot_shapes), ""
    except NativeUnavailable as error:
        return PythonNarrowPhase(robot_shapes), str(error)


if __name__ == "__main__":  # `python -m manip_kin.collision.narrow_phase`: build it now, say which runs
    import time

    started = time.monotonic()
    why_not = native_problem()
    if why_not:
        print(f"collision narrow phase: python ({why_not})")
    else:
        print(f"collision narrow phase: native (ready after {time.monotonic() - started:.1f} s)")
