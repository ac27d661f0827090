"""Mesh files to the convex shapes the distance queries use.

A mesh URI of a URDF or a marker (``package://P/rest``, ``file:///abs/path`` or a plain path) is
first made a file by :func:`manip_kin.core.mesh_uris.require_mesh_file` (``mesh_search_path``,
then the ament index).

Meshes are loaded with coal (STL, OBJ, DAE and whatever else its assimp reads) and replaced
by their convex hull: a convex-convex distance costs about 1.3 µs where the triangle-mesh
query costs about 10 µs (measured on the Panda's link meshes), and robot collision meshes
are convex or nearly so. Each (file, scale) is loaded once per process.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from manip_kin.errors import ModelFileError


@functools.lru_cache(maxsize=128)
def _convex_hull(path: str, scale: tuple[float, float, float]):
    import coal

    mesh = coal.MeshLoader().load(path, np.array(scale, dtype=float))
    if mesh.num_vertices < 4:
        raise ValueError(f"{mesh.num_vertices} vertices; a solid needs at least 4")
    mesh.buildConvexHull(True, "Qt")
    return mesh.convex


def load_convex_mesh(path: Path, scale=(1.0, 1.0, 1.0), source: str = "", field: str = ""):
    """The convex hull of the mesh in ``path``, scaled per axis, as a coal shape.

    Raises:
        ModelFileError: coal cannot read the file or it holds no solid; names ``source``
            and ``field`` (the URDF element or the marker).
    """
    key = tuple(float(v) for v in scale)
    try:
        return _convex_hull(str(path), key)
    except Exception as error:  # coal raises plain RuntimeError/ValueError for unreadable files
        raise ModelFileError(source or str(path), field or "mesh", f"{path}: cannot load: {error}") from None


def convex_vertices(shape) -> np.ndarray:
    """The vertices of a coal convex shape in its own frame, shape (k, 3) [m]."""
    return np.array(shape.points(), dtype=float).reshape(-1, 3)
