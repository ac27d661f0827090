"""A robot's collision model: its link shapes and the self-collision pairs to check.

Built once per robot (loading meshes, and sampling pairs when no SRDF is given, takes
tenths of a second); immutable afterwards, shared by the control law, the path check and
``manip_kin check``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from manip_kin.collision.geometry import LinkGeometry, adjacent_links, link_geometries
from manip_kin.collision.pairs import DEFAULT_SAMPLES, PairSelection, sampled_disabled_pairs, select_pairs
from manip_kin.collision.srdf import load_disabled_pairs
from manip_kin.core.model import RobotModel
from manip_kin.core.robot_files import is_urdf_file
from manip_kin.core.urdf.document import UrdfTree
from manip_kin.errors import ModelFileError


@dataclass(frozen=True)
class CollisionModel:
    """Link shapes of one robot and the self-collision pairs between them.

    Attributes:
        dof: joints of the model it belongs to.
        geometries: one per URDF ``<collision>`` element.
        pairs: checked and disabled link pairs (see :mod:`manip_kin.collision.pairs`).
        source: where the geometry came from (the URDF), for messages.
        frames: model frame of each geometry, shape (G,).
        offsets: pose of each geometry in its frame, shape (G, 4, 4).
        centres: bounding-sphere centre of each geometry in its own frame, shape (G, 3) [m].
        radii: bounding-sphere radius of each geometry, shape (G,) [m].
        self_pairs: geometry index pairs of the checked link pairs, shape (P, 2).
    """

    dof: int
    geometries: tuple[LinkGeometry, ...]
    pairs: PairSelection
    source: str = ""
    frames: np.ndarray = field(init=False, repr=False, compare=False)
    offsets: np.ndarray = field(init=False, repr=False, compare=False)
    centres: np.ndarray = field(init=False, repr=False, compare=False)
    radii: np.ndarray = field(init=False, repr=False, compare=False)
    self_pairs: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        geometries = self.geometries
        checked = set(self.pairs.checked)
        rows = [
            (a, b)
            for a in range(len(geometries))
            for b in range(a + 1, len(geometries))
            if tuple(sorted((geometries[a].link, geometries[b].link))) in checked
        ]
        arrays = {
            "frames": np.array([g.frame for g in geometries], dtype=int),
            "offsets": np.array([g.offset for g in geometries]).reshape(-1, 4, 4),
            "centres": np.array([g.shape.centre for g in geometries]).reshape(-1, 3),
            "radii": np.array([g.shape.radius for g in geometries]),
            "self_pairs": np.array(rows, dtype=int).reshape(-1, 2),
        }
        for name, array in arrays.items():
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def links(self) -> tuple[str, ...]:
        """The links that have geometry, in document order."""
        return tuple(dict.fromkeys(g.link for g in self.geometries))


def load_collision_model(
    model: RobotModel,
    urdf: str | Path | bytes | None = None,
    srdf: str | Path | None = None,
    mesh_search_path: str = "",
    samples: int = DEFAULT_SAMPLES,
    seed: int = 0,
    source: str = "",
) -> CollisionModel:
    """The collision model of ``model`` from its URDF.

    Args:
        model: the chain (loaded from the same URDF).
        urdf: the URDF as a path, or its text (``bytes``, or a ``str`` starting with ``<``);
            None = ``model.source`` when that is a URDF file.
        srdf: an SRDF path whose ``disable_collisions`` list the pairs not checked; None =
            sample ``samples`` random configurations with ``seed`` (see :mod:`manip_kin.collision.pairs`).
        mesh_search_path: ``:``-separated directories holding packages, for ``package://`` meshes.
        source: name of the URDF text for messages (default: the path or ``robot_description``).

    Raises:
        ModelFileError: no URDF, a malformed ``<collision>`` element, a mesh not found, a
            malformed SRDF or one naming links the robot does not have.
    """
    if urdf is None:
        if not (model.source and Path(model.source).is_file() and is_urdf_file(model.source)):
            raise ModelFileError(
                model.source or model.name,
                "<collision>",
                "collision checking needs the robot's URDF (a robot YAML has no collision geometry)",
            )
        urdf = Path(model.source)
    if isinstance(urdf, Path) or (isinstance(urdf, str) and not urdf.lstrip().startswith("<")):
        path = Path(urdf)
        try:
            text = path.read_bytes()
        except OSError as error:
            raise ModelFileError(str(path), "<file>", f"cannot read: {error.strerror}") from None
        reader = UrdfTree(text, source or str(path))
    else:
        reader = UrdfTree(urdf, source or "robot_description")
    geometries = link_geometries(model, reader, mesh_search_path)
    links = {g.link for g in geometries}
    adjacent = adjacent_links(reader, links)
    if srdf:
        disabled = load_disabled_pairs(srdf, tuple(reader.links))
    else:
        disabled = sampled_disabled_pairs(model, geometries, adjacent, samples, seed)
    return CollisionModel(model.dof, geometries, select_pairs(geometries, disabled, adjacent), reader.source)
