"""Every module the benchmark scripts import, also inside functions, can be found from the
folders each script puts on sys.path: a helper they take from test/support that moved or was
renamed breaks ``make bench`` and ``make soak``, which the suite does not run."""

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"
#: Imported only where installed: the anchors' own venv (make bench-anchors), proxsuite for a comparison row.
OPTIONAL = {"pinocchio", "roboticstoolbox", "spatialmath", "proxsuite"}

# In a fresh interpreter: import what sets the paths (the script itself where it runs alone, else
# bench/run.py, which runs the sections), then the script, then look for the rest.
_FIND = """
import importlib, importlib.util, json, sys
sys.path.insert(0, sys.argv[1])
for module in sys.argv[2:4]:
    importlib.import_module(module)
print(json.dumps(sorted(name for name in json.loads(sys.argv[4]) if importlib.util.find_spec(name) is None)))
"""


def _sets_its_own_path(tree: ast.Module) -> bool:
    """A script run alone (make soak, make bench-anchors) puts its folders on sys.path at import."""
    return any(isinstance(node, ast.Expr) and "sys.path.insert" in ast.unparse(node) for node in tree.body)


def _imported(tree: ast.Module) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("script", sorted(p.stem for p in BENCH.glob("*.py")))
def test_every_module_a_benchmark_imports_is_found(script):
    tree = ast.parse((BENCH / f"{script}.py").read_text())
    names = sorted(_imported(tree) - OPTIONAL)
    first = script if _sets_its_own_path(tree) else "run"
    result = subprocess.run(
        [sys.executable, "-c", _FIND, str(BENCH), first, script, json.dumps(names)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=BENCH.parent / "bench",
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert json.loads(result.stdout.splitlines()[-1]) == [], f"{script} imports modules that are nowhere"
