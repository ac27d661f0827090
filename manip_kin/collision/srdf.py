"""The ``disable_collisions`` list of an SRDF (MoveIt's semantic robot description).

Only ``<disable_collisions link1=… link2=… reason=…/>`` is read; groups, states and end
effectors are MoveIt's business. Errors name the file and the element.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from manip_kin.errors import ModelFileError


def link_pair(a: str, b: str) -> tuple[str, str]:
    """An unordered pair of link names as a sorted tuple (the key of every pair table)."""
    return (a, b) if a <= b else (b, a)


def read_disabled_pairs(text: str | bytes, source: str, links: tuple[str, ...] = ()) -> dict[tuple[str, str], str]:
    """``{(link1, link2) sorted: reason}`` from SRDF text.

    Args:
        text: the SRDF document.
        source: what it is (a path), for error messages.
        links: the robot's link names; when given, a pair naming another link is an error
            (an SRDF for another robot).

    Raises:
        ModelFileError: malformed XML, a root that is not ``<robot>``, a ``disable_collisions``
            without both links, or a link the robot does not have.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as error:
        line, column = error.position
        raise ModelFileError(source, f"line {line}, column {column + 1}", "malformed XML") from None
    if root.tag != "robot":
        raise ModelFileError(source, "robot", f"the root element is <{root.tag}>; an SRDF starts with <robot>")
    known = set(links)
    pairs: dict[tuple[str, str], str] = {}
    for index, element in enumerate(root.findall("disable_collisions"), start=1):
        where = f"disable_collisions[#{index}]"
        first, second = element.get("link1", "").strip(), element.get("link2", "").strip()
        if not first or not second:
            raise ModelFileError(source, f"{where}@link1/link2", "missing; both links are needed")
        for name, attribute in ((first, "link1"), (second, "link2")):
            if known and name not in known:
                raise ModelFileError(source, f"{where}@{attribute}", f"{name!r} is not a link of the robot")
        pairs[link_pair(first, second)] = element.get("reason", "").strip() or "Unknown"
    return pairs


def load_disabled_pairs(path: str | Path, links: tuple[str, ...] = ()) -> dict[tuple[str, str], str]:
    """:func:`read_disabled_pairs` of a file."""
    path = Path(path)
    try:
        text = path.read_bytes()
    except OSError as error:
        raise ModelFileError(str(path), "<file>", f"cannot read: {error.strerror}") from None
    return read_disabled_pairs(text, str(path), links)
