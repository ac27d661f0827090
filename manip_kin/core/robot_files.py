"""Reading robot files safely: bounded size, nesting, element and alias counts, type by content.

Every robot description (a robot YAML, a URDF file, a ``robot_description`` string) is read
through these functions, so a hostile file gets a :class:`~manip_kin.errors.ModelFileError`
naming the file and the field, in bounded time and memory, never a traceback. The caps
(documented in ``docs/hostile_inputs.md``):

* :data:`MAX_URDF_BYTES` and :data:`MAX_YAML_BYTES`: the size of a file or string;
* :data:`MAX_NESTING_DEPTH`: nesting of YAML collections and of XML elements;
* :data:`MAX_YAML_NODES`: YAML nodes *with aliases expanded* (an alias counts as the whole
  node it refers to), so a 0.5 kB "billion laughs" alias bomb is refused before it is built;
  :data:`MAX_YAML_ALIASES`: aliases of any size;
* :data:`MAX_XML_ELEMENTS`: XML elements; entity declarations are refused (a URDF has none);
* :data:`MAX_MAGNITUDE`: every length [m], angle [rad] and axis component of a model, so
  that squares and products of them stay far from overflow.

The file type is decided by the content (:func:`robot_file_kind`): text starting with ``<``
is a URDF, anything else a robot YAML, whatever the name or a symlink's target says.
"""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import yaml

from manip_kin.errors import ModelFileError, bounded_repr

MAX_URDF_BYTES = 16 * 2**20  # 16 MiB: the largest example-robot-data URDF is 0.2 MB
MAX_YAML_BYTES = 1 * 2**20  # 1 MiB: a robot YAML is a few kB
MAX_NESTING_DEPTH = 64
MAX_YAML_NODES = 100_000
MAX_YAML_ALIASES = 1_000
MAX_XML_ELEMENTS = 1_000_000
#: Largest magnitude of a length [m], angle [rad] or axis component in a model.
MAX_MAGNITUDE = 1.0e6

_XML_FEED_BYTES = 1 << 16
_BYTE_ORDER_MARKS = (b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff")


def read_robot_file(path: str | Path) -> bytes:
    """The bytes of a robot file, at most :data:`MAX_URDF_BYTES` (the larger cap) of them.

    Raises:
        ModelFileError: unreadable, not a regular file, or larger than the cap.
    """
    path = Path(path)
    try:
        with open(path, "rb") as stream:
            data = stream.read(MAX_URDF_BYTES + 1)
    except OSError as error:
        raise ModelFileError(str(path), "<file>", f"cannot read: {error.strerror or error}") from None
    if len(data) > MAX_URDF_BYTES:
        raise ModelFileError(str(path), "<file>", f"larger than {MAX_URDF_BYTES} bytes; valid: a robot file up to that")
    return data


def is_urdf_file(path: str | Path) -> bool:
    """True when the file at ``path`` holds a URDF (by its content, see :func:`robot_file_kind`);
    False for a YAML robot or a file that cannot be read."""
    try:
        with open(path, "rb") as stream:
            return robot_file_kind(stream.read(4096)) == "urdf"
    except OSError:
        return False


def robot_file_kind(data: bytes | str) -> str:
    """``"urdf"`` when the content is XML (starts with ``<`` after a BOM and blanks), else ``"yaml"``."""
    head = data[:4096].encode("utf-8", "replace") if isinstance(data, str) else data[:4096]
    for mark in _BYTE_ORDER_MARKS:
        if head.startswith(mark):
            head = head[len(mark) :].replace(b"\x00", b"")
            break
    return "urdf" if head.lstrip().startswith(b"<") else "yaml"


def decode_utf8(data: bytes, source: str) -> str:
    """``data`` as UTF-8 text; an invalid byte is a ModelFileError naming its line and column."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        before = data[: error.start]
        line = before.count(b"\n") + 1
        column = error.start - (before.rfind(b"\n") + 1) + 1
        problem = f"invalid UTF-8 (byte 0x{data[error.start]:02x} at offset {error.start}); valid: UTF-8 text"
        raise ModelFileError(source, f"line {line}, column {column}", problem) from None


# --- YAML


def _yaml_problem(source: str, event: yaml.Event, problem: str) -> ModelFileError:
    mark = event.start_mark
    return ModelFileError(source, f"line {mark.line + 1}, column {mark.column + 1}", problem)


def _check_yaml_events(text: str, source: str) -> None:
    """Walk the YAML event stream (no document is built) and enforce the caps.

    Each open collection counts its nodes with aliases expanded; an anchored node's count is
    remembered so an alias adds it. Linear in the text, no recursion.
    """
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    open_counts: list[list] = []  # [expanded node count, anchor] per open collection
    anchor_sizes: dict[str, int] = {}
    total, aliases = 0, 0

    def add(count: int, event: yaml.Event) -> None:
        nonlocal total
        total += count
        if total > MAX_YAML_NODES:
            raise _yaml_problem(source, event, f"more than {MAX_YAML_NODES} nodes (aliases expanded); valid: fewer")
        if open_counts:
            open_counts[-1][0] += count

    for event in yaml.parse(text, Loader=loader):
        if isinstance(event, yaml.AliasEvent):
            aliases += 1
            if aliases > MAX_YAML_ALIASES:
                raise _yaml_problem(source, event, f"more than {MAX_YAML_ALIASES} aliases; valid: fewer")
            if event.anchor not in anchor_sizes:
                problem = f"alias *{event.anchor} refers to no complete node before it (undefined or recursive)"
                raise _yaml_problem(source, event, problem)
            add(anchor_sizes[event.anchor], event)
        elif isinstance(event, yaml.ScalarEvent):
            if event.anchor:
                anchor_sizes[event.anchor] = 1
            add(1, event)
        elif isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            if len(open_counts) >= MAX_NESTING_DEPTH:
                raise _yaml_problem(source, event, f"nested deeper than {MAX_NESTING_DEPTH}; valid: less deep")
            add(1, event)
            open_counts.append([1, event.anchor])
        elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            count, anchor = open_counts.pop()
            if open_counts:
                open_counts[-1][0] += count - 1  # the start event was added already
            if anchor:
                anchor_sizes[anchor] = count


def parse_yaml(data: bytes | str, source: str, max_bytes: int = MAX_YAML_BYTES) -> Any:
    """A YAML document (a robot YAML, bag metadata), parsed within the caps.

    Raises:
        ModelFileError: larger than ``max_bytes``, invalid UTF-8, malformed, too deep, too
            many nodes or aliases; the field is the line and column.
    """
    if isinstance(data, str):
        data = data.encode("utf-8", "surrogatepass")
    if len(data) > max_bytes:
        raise ModelFileError(source, "<file>", f"larger than {max_bytes} bytes; valid: a YAML document up to that")
    text = decode_utf8(data, source)
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    try:
        _check_yaml_events(text, source)
        return yaml.load(text, Loader=loader)  # noqa: S506 - a safe loader, the caps checked above
    except ModelFileError:
        raise
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "<file>"
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise ModelFileError(source, where, f"malformed YAML: {problem}") from None
    except (ValueError, TypeError, OverflowError) as error:  # e.g. a timestamp 2001-02-30
        raise ModelFileError(source, "<file>", f"malformed YAML value: {bounded_repr(str(error))}") from None


# --- XML


def parse_xml(data: bytes | str, source: str) -> ET.Element:
    """The root element of an XML document, parsed within the caps.

    Raises:
        ModelFileError: too large, malformed (with line and column), an entity declaration,
            nested deeper than :data:`MAX_NESTING_DEPTH` or more than :data:`MAX_XML_ELEMENTS`.
    """
    raw = data.encode("utf-8") if isinstance(data, str) else data
    if len(raw) > MAX_URDF_BYTES:
        raise ModelFileError(source, "<file>", f"larger than {MAX_URDF_BYTES} bytes; valid: a URDF up to that")
    if b"<!ENTITY" in raw:
        raise ModelFileError(source, "<!ENTITY>", "entity declarations are not accepted in a URDF; expand them first")
    parser = ET.XMLPullParser(events=("start", "end"))
    depth, elements = 0, 0
    root = None
    stream = io.BytesIO(raw)
    try:
        while chunk := stream.read(_XML_FEED_BYTES):
            parser.feed(chunk)
            for event, element in parser.read_events():
                if event == "end":
                    depth -= 1
                    continue
                depth += 1
                elements += 1
                root = element if root is None else root
                if depth > MAX_NESTING_DEPTH:
                    raise ModelFileError(
                        source, f"<{element.tag}>", f"nested deeper than {MAX_NESTING_DEPTH}; valid: less deep"
                    )
                if elements > MAX_XML_ELEMENTS:
                    raise ModelFileError(source, f"<{element.tag}>", f"more than {MAX_XML_ELEMENTS} elements")
        parser.close()
    except ET.ParseError as error:
        line, column = error.position  # expat counts columns from 0, editors from 1
        problem = f"malformed XML: {str(error).split(':')[0]}"
        raise ModelFileError(source, f"line {line}, column {column + 1}", problem) from None
    if root is None:
        raise ModelFileError(source, "<file>", "no XML element; a URDF starts with <robot>")
    return root
