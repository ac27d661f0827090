"""Mesh URIs of URDFs and markers (``package://P/…``, ``file://…``, plain paths) to files: the one
resolver of the package (collision geometry, the physics model and its renders use it).

* ``package://P/rest`` is looked up first in each directory of a ``mesh_search_path``
  (``:``-separated directories that hold packages, as ``ROS_PACKAGE_PATH``: ``<dir>/P/rest``;
  ``~`` expanded, blank entries skipped), then in the share directory of package ``P`` in the
  ament index (``share/P/rest`` of its prefix; needs ``AMENT_PREFIX_PATH``);
* ``file:///abs/path`` is that path (percent-escapes decoded);
* any other ``scheme://`` is refused: nothing is fetched;
* a plain relative path is taken relative to the directory of the document it came from (the
  URDF file's), or the working directory when there is none.

:func:`require_mesh_file` says where it looked when there is no such file (a collision model
cannot do without the mesh); :func:`resolve_mesh_uri` gives None instead (a physics model
leaves the mesh out with a note).
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import unquote, urlparse

PACKAGE_SCHEME = "package://"
FILE_SCHEME = "file://"


def search_directories(mesh_search_path: str) -> list[Path]:
    """The directories of a ``:``-separated ``mesh_search_path`` (blank entries skipped)."""
    return [Path(part).expanduser() for part in mesh_search_path.split(":") if part.strip()]


def _package_share(package: str) -> Path | None:
    """The ament share directory of ``package``, or None (no ROS here, no index, not in it)."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:  # no ROS here: only the search path
        return None
    try:
        return Path(get_package_share_directory(package))
    except (OSError, PackageNotFoundError, KeyError, ValueError):  # OSError: no AMENT_PREFIX_PATH
        return None


def require_mesh_file(uri: str, mesh_search_path: str = "", base_dir: str | Path | None = None) -> Path:
    """The existing file a mesh URI names.

    Args:
        uri: ``package://P/rest``, ``file:///abs/path``, an absolute or a relative path
            (surrounding white space ignored).
        mesh_search_path: ``:``-separated directories holding packages (``<dir>/P/rest``).
        base_dir: directory of the document the URI came from, for a relative path
            (default: the working directory).

    Raises:
        FileNotFoundError: no such file; the message names the URI and where it looked.
    """
    text = uri.strip()
    if text.startswith(PACKAGE_SCHEME):
        package, _, rest = text[len(PACKAGE_SCHEME) :].partition("/")
        if not package or not rest:
            raise FileNotFoundError(f"{uri}: not a mesh URI; valid: package://<package>/<path in it>")
        candidates = [directory / package / rest for directory in search_directories(mesh_search_path)]
        share = _package_share(package)
        if share is not None:
            candidates.append(share / rest)
        found = next((candidate for candidate in candidates if candidate.is_file()), None)
        if found is not None:
            return found
        looked = ", ".join(str(c) for c in candidates) or "no mesh_search_path directory"
        hint = "" if share is not None else f"; package {package!r} is not in the ament index (AMENT_PREFIX_PATH)"
        raise FileNotFoundError(f"{uri}: not found (looked in {looked}{hint}); set mesh_search_path")
    if text.startswith(FILE_SCHEME):
        path = Path(unquote(urlparse(text).path))
    elif "://" in text:
        raise FileNotFoundError(f"{uri}: not fetched; valid: package://, file:// or a path")
    else:
        path = Path(text)
        if not path.is_absolute():
            path = (Path.cwd() if base_dir is None else Path(base_dir)) / path
    if not path.is_file():
        raise FileNotFoundError(f"{uri}: no such file {path}")
    return path


def resolve_mesh_uri(uri: str, mesh_search_path: str = "", base_dir: str | Path | None = None) -> Path | None:
    """:func:`require_mesh_file`, with None where it would raise (same arguments)."""
    try:
        return require_mesh_file(uri, mesh_search_path, base_dir)
    except FileNotFoundError:
        return None
