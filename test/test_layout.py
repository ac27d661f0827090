"""The package's layout (docs/layout.md): no import cycle between modules, wings import one way,
no module over :data:`MAX_MODULE_LINES` lines.

The import graph is read from the source with ``ast`` (every ``import``, at module level or inside
a function: a lazy import is still a dependency), nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "manip_kin"
TEST_ROOT = Path(__file__).resolve().parent

#: The wings from the bottom up: a module may import its own wing and the wings below it.
WINGS = (
    "errors",
    "cdr",
    "codegen",
    "core",
    "collision",
    "control",
    "ik",
    "motion",
    "plant",
    "recording",
    "ros.wire",
    "ros.runtime",
    "pipeline",
    "viz",
    "ros.nodes",
    "cli",
    "entry",
)

#: The upward imports there are, each with its reason (none: the codegen redesign of issue 25
#: moved the plain-float functions the generated code inlines into codegen.inlined).
KNOWN_UPWARD: set[tuple[str, str]] = set()

#: Longest module [lines]: a longer one has more than one job (split it along a seam, see docs/layout.md).
MAX_MODULE_LINES = 400


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """``manip_kin`` module -> the ``manip_kin`` modules it imports (a package stands for its ``__init__``)."""
    modules = {module_name(path): path for path in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*anchor, *([base] if base else [])])
                if base.startswith("manip_kin"):
                    for alias in node.names:
                        target = f"{base}.{alias.name}"
                        found.add(target if target in modules else base)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names if alias.name.startswith("manip_kin"))
        graph[name] = {target for target in found if target != name and target != "manip_kin"}
    return graph


def wing_of(module: str) -> str | None:
    """The wing of a ``manip_kin`` module (the longest wing name that prefixes it), or None."""
    local = module.removeprefix("manip_kin.")
    matches = [w for w in WINGS if local == w or local.startswith(w + ".")]
    return max(matches, key=len) if matches else None


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` as the modules along it, or None."""
    state: dict[str, int] = {}  # 1: on the path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for target in sorted(graph.get(node, ())):
            if state.get(target) == 1:
                return path[path.index(target) :] + [target]
            if target not in state and (cycle := visit(target)) is not None:
                return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)) is not None:
            return cycle
    return None


GRAPH = import_graph()


def test_the_graph_is_read():
    """The reader sees real edges (a broken reader would pass every other test here)."""
    assert "manip_kin.core.model" in GRAPH["manip_kin.core.kinematics"]
    assert "manip_kin.ros.runtime.rate_loop" in GRAPH["manip_kin.ros.runtime.looping_node"]
    assert len(GRAPH) > 150


def test_no_import_cycle():
    assert find_cycle(GRAPH) is None, " -> ".join(find_cycle(GRAPH) or ())


def test_find_cycle_finds_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_every_module_is_in_a_wing():
    loose = sorted(m for m in GRAPH if m not in ("manip_kin", "manip_kin.ros") and wing_of(m) is None)
    assert not loose, f"modules outside every wing (add them to a wing, see docs/layout.md): {loose}"


def test_wings_import_only_downwards():
    rank = {wing: i for i, wing in enumerate(WINGS)}
    upward = set()
    for module, targets in GRAPH.items():
        for target in targets:
            source_wing, target_wing = wing_of(module), wing_of(target)
            if source_wing and target_wing and rank[target_wing] > rank[source_wing]:
                upward.add((module.removeprefix("manip_kin."), target.removeprefix("manip_kin.")))
    assert upward - KNOWN_UPWARD == set(), f"imports against the wings' direction: {sorted(upward - KNOWN_UPWARD)}"
    assert KNOWN_UPWARD - upward == set(), f"gone, drop from KNOWN_UPWARD: {sorted(KNOWN_UPWARD - upward)}"


def test_no_lower_wing_imports_rclpy():
    """Below ros.wire nothing needs ROS: the math is importable and testable without it."""
    ros_free = {w for w in WINGS[: WINGS.index("ros.wire")]} - {"recording"}
    for path in PACKAGE.rglob("*.py"):
        if wing_of(module_name(path)) in ros_free:
            tree = ast.parse(path.read_text())
            names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
            names |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
            assert not {n for n in names if n.split(".")[0] in ("rclpy", "geometry_msgs", "sensor_msgs")}, path


def long_modules(package: Path, limit: int = MAX_MODULE_LINES) -> dict[str, int]:
    """``{path: lines}`` of the modules under ``package`` longer than ``limit`` lines."""
    counts = {path: len(path.read_text().splitlines()) for path in sorted(package.rglob("*.py"))}
    return {str(path.relative_to(package.parent)): n for path, n in counts.items() if n > limit}


def test_no_module_is_over_the_line_limit():
    assert long_modules(PACKAGE) == {}, f"modules over {MAX_MODULE_LINES} lines: {long_modules(PACKAGE)}"


def test_long_modules_finds_one(tmp_path):
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "short.py").write_text("x = 1\n" * MAX_MODULE_LINES)
    (package / "sub" / "long.py").write_text("x = 1\n" * (MAX_MODULE_LINES + 1))
    assert long_modules(package) == {"pkg/sub/long.py": MAX_MODULE_LINES + 1}


@pytest.mark.parametrize("folder", ["support", "core", "control", "ros/nodes"])
def test_test_folders_exist(folder):
    assert any((TEST_ROOT / folder).glob("*.py"))


def test_test_module_basenames_are_unique():
    """Tests run in pytest's rootdir-relative mode without ``__init__.py``: a basename used twice
    would be one module."""
    names = [p.name for p in TEST_ROOT.rglob("*.py") if "foxglove_client" not in p.parts]
    assert sorted(n for n in set(names) if names.count(n) > 1) == []
