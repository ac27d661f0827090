#!/usr/bin/env python3
"""``make mutate``: a small mutation round over the core, reporting the mutants no test catches.

A mutant is one small change to one expression of a module: a comparison turned around
(``<`` to ``<=``, ``==`` to ``!=``), an arithmetic operator swapped (``+``/``-``, ``*``/``/``),
``and``/``or`` exchanged, a ``not`` dropped, a number changed (0 to 1, c to 2c), a boolean
flipped, or a ``return`` value replaced by ``None``. Each module has its own test files
(:data:`TARGETS`); every mutant runs them (``pytest -x``) in a copy of the package, so the
working tree is never touched. A mutant the tests fail on (or time out on) is *killed*; one
they pass with is a *survivor*: either a missing test, or a change that cannot alter
behaviour (an equivalent mutant), to be looked at by hand.

The mutants are a seeded sample (``--per-module``), so a round is bounded: about 15 minutes
on a shared 2-core machine at the defaults. ``python tools/mutate.py --help`` for the options;
the report is a table on stdout and JSON (``--out``).
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Module -> the test files that should catch a change to it (kept small: they run per mutant).
TARGETS: dict[str, tuple[str, ...]] = {
    "manip_kin/core/model.py": ("test/core/test_kinematics.py", "test/core/test_mutation_survivors.py"),
    "manip_kin/core/kinematics.py": ("test/core/test_kinematics.py",),
    "manip_kin/core/rotations.py": ("test/core/test_rotations.py", "test/core/test_mutation_survivors.py"),
    "manip_kin/codegen/chain.py": ("test/core/test_kinematics.py", "test/codegen/test_ir.py"),
    "manip_kin/codegen/ir.py": (
        "test/codegen/test_ir.py",
        "test/core/test_kinematics.py",
        "test/control/test_control.py",
    ),
    "manip_kin/codegen/inlined.py": ("test/core/test_rotations.py", "test/control/test_control.py"),
    "manip_kin/codegen/pose_error.py": ("test/control/test_control.py", "test/ik/test_ik.py"),
    "manip_kin/codegen/unrolled_linalg.py": ("test/control/test_control.py",),
    "manip_kin/core/damped_least_squares.py": (
        "test/control/test_control.py",
        "test/control/test_reference_law.py",
        "test/core/test_mutation_survivors.py",
    ),
    "manip_kin/codegen/control_step.py": ("test/control/test_control.py", "test/control/test_reference_law.py"),
    "manip_kin/control/resolved_rate.py": (
        "test/control/test_control.py",
        "test/control/test_reference_law.py",
        "test/core/test_mutation_survivors.py",
    ),
    "manip_kin/core/pose_rows.py": ("test/control/test_control.py", "test/core/test_mutation_survivors.py"),
    "manip_kin/ik/iteration.py": ("test/ik/test_ik.py", "test/core/test_mutation_survivors.py"),
    "manip_kin/codegen/ik_step.py": ("test/ik/test_ik.py",),
    "manip_kin/ik/closed_form/scara.py": ("test/ik/test_closed_form.py", "test/core/test_mutation_survivors.py"),
    "manip_kin/ik/closed_form/rpp.py": (
        "test/ik/test_closed_form.py",
        "test/ik/test_ik.py",
        "test/core/test_mutation_survivors.py",
    ),
    "manip_kin/core/bounds.py": ("test/core/test_mutation_survivors.py", "test/ros/wire/test_hostile_inputs.py"),
    "manip_kin/ros/wire/validation.py": ("test/ros/wire/test_conversions.py", "test/core/test_mutation_survivors.py"),
    "manip_kin/control/simulation.py": ("test/control/test_simulation.py",),
}

_COMPARE_SWAPS = {
    ast.Lt: ast.LtE,
    ast.LtE: ast.Lt,
    ast.Gt: ast.GtE,
    ast.GtE: ast.Gt,
    ast.Eq: ast.NotEq,
    ast.NotEq: ast.Eq,
    ast.Is: ast.IsNot,
    ast.IsNot: ast.Is,
    ast.In: ast.NotIn,
    ast.NotIn: ast.In,
}
_BINARY_SWAPS = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult, ast.Pow: ast.Mult}


@dataclass(frozen=True)
class Mutant:
    """One change: ``module`` line ``line``, the expression ``original`` written as ``mutated``."""

    module: str
    line: int
    start: tuple[int, int]
    end: tuple[int, int]
    original: str
    mutated: str
    operator: str


def _docstring_nodes(tree: ast.AST) -> set[int]:
    """ids of the constant nodes that are docstrings (never mutated)."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = getattr(node, "body", [])
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                found.add(id(body[0].value))
    return found


def _variants(node: ast.AST) -> list[tuple[str, ast.AST]]:
    """``(operator name, mutated copy)`` for every mutation of this one node."""
    out = []
    if isinstance(node, ast.Compare):
        for i, op in enumerate(node.ops):
            swap = _COMPARE_SWAPS.get(type(op))
            if swap is not None:
                ops = list(node.ops)
                ops[i] = swap()
                out.append(("compare", ast.Compare(left=node.left, ops=ops, comparators=node.comparators)))
    elif isinstance(node, ast.BinOp) and not (_is_text(node.left) or _is_text(node.right)):
        swap = _BINARY_SWAPS.get(type(node.op))
        if swap is not None:
            out.append(("arithmetic", ast.BinOp(left=node.left, op=swap(), right=node.right)))
    elif isinstance(node, ast.BoolOp):
        other = ast.Or() if isinstance(node.op, ast.And) else ast.And()
        out.append(("boolean", ast.BoolOp(op=other, values=node.values)))
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        out.append(("not", node.operand))
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        out.append(("sign", node.operand))
    elif isinstance(node, ast.Constant) and isinstance(node.value, bool):
        out.append(("boolean constant", ast.Constant(value=not node.value)))
    elif isinstance(node, ast.Constant) and type(node.value) in (int, float):
        value = node.value
        changed = 1 if value == 0 else (value + 1 if isinstance(value, int) else value * 2.0)
        out.append(("number", ast.Constant(value=changed)))
    elif isinstance(node, ast.Return) and node.value is not None and not _is_none(node.value):
        out.append(("return", ast.Return(value=ast.Constant(value=None))))
    return out


def _is_text(node: ast.AST) -> bool:
    """A string operand: ``+`` joins text there (a swap would only raise TypeError)."""
    return isinstance(node, ast.JoinedStr) or (isinstance(node, ast.Constant) and isinstance(node.value, str))


def _is_none(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and node.value is None


def _inside_strings(tree: ast.AST) -> set[int]:
    """ids of nodes inside f-strings and type annotations (messages and hints: not behaviour)."""
    skipped = set()
    for node in ast.walk(tree):
        roots = []
        if isinstance(node, ast.JoinedStr):
            roots.append(node)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            roots += [a.annotation for a in node.args.args + node.args.kwonlyargs if a.annotation] + [node.returns]
        if isinstance(node, ast.AnnAssign):
            roots.append(node.annotation)
        for root in roots:
            if root is not None:
                skipped.update(id(inner) for inner in ast.walk(root))
    return skipped


def mutants_of(module: str) -> list[Mutant]:
    """Every mutant of one module (relative path), in source order."""
    source = (ROOT / module).read_text()
    tree = ast.parse(source)
    skipped = _docstring_nodes(tree) | _inside_strings(tree)
    lines = source.splitlines()
    found = []
    for node in ast.walk(tree):
        if id(node) in skipped or not hasattr(node, "lineno") or node.end_lineno is None:
            continue
        if "no mutate" in lines[node.lineno - 1]:
            continue
        original = ast.get_source_segment(source, node)
        if original is None:
            continue
        for operator, variant in _variants(node):
            mutated = ast.unparse(variant)
            if isinstance(node, ast.Return):
                mutated = "return None"
            found.append(
                Mutant(
                    module,
                    node.lineno,
                    (node.lineno, node.col_offset),
                    (node.end_lineno, node.end_col_offset),
                    original,
                    f"({mutated})" if isinstance(node, ast.expr) else mutated,
                    operator,
                )
            )
    return sorted(found, key=lambda m: (m.start, m.operator, m.mutated))


def apply(source: str, mutant: Mutant) -> str:
    """``source`` with the mutant's expression replaced."""
    lines = source.splitlines(keepends=True)
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line.encode()))
    data = source.encode()
    begin = offsets[mutant.start[0] - 1] + mutant.start[1]
    finish = offsets[mutant.end[0] - 1] + mutant.end[1]
    return (data[:begin] + mutant.mutated.encode() + data[finish:]).decode()


def _copy_tree(destination: Path) -> None:
    for name in ("manip_kin", "test", "config", "resource"):
        if (ROOT / name).exists():
            shutil.copytree(ROOT / name, destination / name, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("setup.py", "setup.cfg", "package.xml", "ruff.toml", "pytest.ini", "pyproject.toml"):
        if (ROOT / name).exists():
            shutil.copy2(ROOT / name, destination / name)


def _run_tests(copy: Path, tests: tuple[str, ...], timeout: float) -> tuple[str, float]:
    """``passed``, ``failed`` or ``timeout``, and the wall time [s]."""
    environment = dict(os.environ, PYTHONPATH=str(copy), HYPOTHESIS_PROFILE="ci", PYTHONDONTWRITEBYTECODE="1")
    command = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests]
    started = time.monotonic()
    try:
        result = subprocess.run(command, cwd=copy, env=environment, capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "timeout", time.monotonic() - started
    return ("passed" if result.returncode == 0 else "failed"), time.monotonic() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--per-module", type=int, default=6, help="mutants sampled per module (default 6)")
    parser.add_argument("--seed", type=int, default=25, help="seed of the sample")
    parser.add_argument("--modules", default="", help="comma-separated subset of the modules in TARGETS")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "mutate.json", help="JSON report")
    parser.add_argument("--list", action="store_true", help="only list the sampled mutants")
    args = parser.parse_args(argv)
    chosen = [m.strip() for m in args.modules.split(",") if m.strip()] or list(TARGETS)
    unknown = sorted(set(chosen) - set(TARGETS))
    if unknown:
        parser.error(f"unknown module(s) {unknown}; valid: {', '.join(TARGETS)}")
    generator = random.Random(args.seed)
    sample = {}
    for module in chosen:
        every = mutants_of(module)
        sample[module] = sorted(generator.sample(every, min(args.per_module, len(every))), key=lambda m: m.start)
    if args.list:
        for module, mutants in sample.items():
            for m in mutants:
                print(f"{module}:{m.line}: {m.original!r} -> {m.mutated!r}")
        return 0
    results = []
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="manip_kin_mutate_") as directory:
        copy = Path(directory)
        _copy_tree(copy)
        for module, mutants in sample.items():
            tests = TARGETS[module]
            baseline, seconds = _run_tests(copy, tests, timeout=600)
            if baseline != "passed":
                print(f"{module}: its tests fail unmutated ({baseline}); skipped", file=sys.stderr)
                continue
            timeout = 3.0 * seconds + 20.0
            original = (copy / module).read_text()
            for mutant in mutants:
                (copy / module).write_text(apply(original, mutant))
                try:
                    outcome, _ = _run_tests(copy, tests, timeout)
                finally:
                    (copy / module).write_text(original)
                status = "survived" if outcome == "passed" else "killed"
                results.append({**asdict(mutant), "status": status, "outcome": outcome})
                print(f"{status:8} {module}:{mutant.line} {mutant.original!r} -> {mutant.mutated!r}", flush=True)
    survivors = [r for r in results if r["status"] == "survived"]
    elapsed = time.monotonic() - started
    print(
        f"\n{len(results)} mutants, {len(results) - len(survivors)} killed, {len(survivors)} survived, {elapsed:.0f} s"
    )
    for r in survivors:
        print(f"  survivor {r['module']}:{r['line']} ({r['operator']}): {r['original']!r} -> {r['mutated']!r}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"seed": args.seed, "elapsed_s": elapsed, "results": results}, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
