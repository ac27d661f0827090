"""Mesh URIs of URDFs and markers (``package://P/…``, ``file://…``, relative paths) to files.

``package://P/rest`` is looked up first in each directory of a ``mesh_search_path``
(``:``-separated directories that hold packages, as ``ROS_PACKAGE_PATH``: ``<dir>/P/rest``),
then through the ament index (``share/P/rest`` of the package's prefix, which needs
``AMENT_PREFIX_PATH``). ``file:///abs/path`` is that path; a plain relative path is taken
relative to the URDF file's directory.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import unquote, urlparse


def _package_share(package: str) -> Path | None:
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:  # no ROS here: only the search path
        return None
    try:
        return Path(get_package_share_directory(package))
    except (OSError, PackageNotFoundError, KeyError, ValueError):  # OSError: no AMENT_PREFIX_PATH
        return None


def resolve_mesh_uri(uri: str, search_path: str = "", base_dir: str | Path | None = None) -> Path | None:
    """The existing file a mesh URI names, or None when it cannot be found.

    Args:
        uri: ``package://P/rest``, ``file:///abs``, an absolute or a relative path.
        search_path: ``:``-separated directories holding packages (``<dir>/P/rest``).
        base_dir: directory of the document the URI came from (for relative paths).
    """
    uri = uri.strip()
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://") :].partition("/")
        if not package or not rest:
            return None
        candidates = [Path(d) / package / rest for d in search_path.split(":") if d]
        share = _package_share(package)
        if share is not None:
            candidates.append(share / rest)
    elif uri.startswith("file://"):
        candidates = [Path(unquote(urlparse(uri).path))]
    elif "://" in uri:
        return None  # http:// and friends: nothing is fetched
    else:
        path = Path(uri)
        candidates = [path if path.is_absolute() or base_dir is None else Path(base_dir) / path]
    return next((c for c in candidates if c.is_file()), None)
