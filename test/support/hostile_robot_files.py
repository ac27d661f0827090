"""Hostile robot files, loaded by ``manip_kin fk --json`` in a process bounded by setrlimit.

Run as a script (``python hostile_robot_files.py OUT.json N``) by ``test_hostile_robot_files.py``:
it caps its own CPU time and address space (:mod:`bounded_cli`), then loads

* the cases of issue 29, one file each (:data:`CASES`), and
* hypothesis mutations of real robot files (the bundled YAMLs, the test URDFs and a URDF
  written by ``model_to_urdf``): hostile numbers, swapped link names, deleted or repeated
  lines, truncations, stray bytes, deep nesting and alias bombs,

and writes one outcome per case (and the hypothesis verdict) as JSON. What must hold for
every file: exit 0 with a finite, valid JSON pose, or exit 2 with one line on stderr naming
the file and the field; never a traceback, never NaN in the output, and within a few
seconds of CPU each (a per-case ITIMER_PROF alarm turns a hang into a failure).
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
import tempfile
from pathlib import Path

from bounded_cli import first_failure, limit_this_process, one_line_refusal_problem, run_cli, save_progress

REPO = Path(__file__).resolve().parents[2]
HOSTILE_NUMBERS = [
    ".inf",
    "-.inf",
    ".nan",
    "1e308",
    "-1e308",
    "1e999",
    "-pi/0",
    "pi/0.0",
    "1e400 deg",
    "1e200",
    "5e-324",
    "-0",
    "'x'",
    "[]",
    "{}",
    "null",
    "true",
    "2001-02-30",
    "[1e308, 1e308, 0]",
]
HOSTILE_ATTRIBUTES = ["1e308", "inf", "-inf", "nan", "1e308 1e308 0", "-1e308 0 1e308", "", "1 2", "$(arg x)", "1e-320"]


def _alias_bomb(levels: int = 9) -> str:
    lines = ['a0: &a0 ["x","x","x","x","x","x","x","x","x"]']
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


#: The issue's cases: name -> (file name, content).
CASES: dict[str, tuple[str, bytes]] = {
    "zero_division": ("a.yaml", b"name: x\njoints:\n  - name: j1\n    limits: {lower: -pi/0}\n"),
    "deep_list": ("deep.yaml", b"name: x\njoints: " + b"[" * 3000 + b"]" * 3000 + b"\n"),
    "deep_block": ("block.yaml", ("name: x\njoints:\n" + "".join("  " * i + "-\n" for i in range(1, 400))).encode()),
    "invalid_utf8": ("utf8.yaml", b"name: \xff\xfe\njoints: [{name: a}]\n"),
    "rpy_inf": ("rpy.yaml", b"name: x\njoints:\n  - name: j1\n    origin: {rpy: [.inf, 0, 0]}\n"),
    "alias_bomb": ("bomb.yaml", _alias_bomb().encode() + b"name: x\njoints: [{name: a}]\n"),
    "origin_inf": ("origin.yaml", b"name: x\njoints:\n  - {name: j1, origin: {xyz: [.inf, 0, 0]}}\n"),
    "axis_inf": ("axis.yaml", b"name: x\njoints:\n  - {name: j1, axis: [.inf, 0, 1]}\n"),
    "tool_inf": ("tool.yaml", b"name: x\njoints: [{name: j1}]\ntool: {xyz: [0, 0, .inf]}\n"),
    "dh_d_inf": ("dh.yaml", b"name: x\ndh:\n  - {joint: theta, d: .inf, theta: 0, a: 0, alpha: 0}\n"),
    "poe_screw_inf": (
        "poe.yaml",
        b"name: x\npoe:\n  home: {xyz: [1, 0, 0]}\n  screws:\n    - {screw: [0, 0, 1, .inf, 0, 0]}\n",
    ),
    "square_overflow": ("square.yaml", b"name: x\njoints:\n  - {name: j1, origin: {xyz: [1e200, 0, 0]}}\n"),
    "urdf_origin_1e308": ("origin.urdf", b""),
    "urdf_axis_1e308": ("axis.urdf", b""),
    "urdf_self_parent": ("loop.urdf", b""),
    "urdf_cycle": ("cycle.urdf", b""),
    "urdf_entity_bomb": ("lol.urdf", b""),
    "urdf_deep": ("deep.urdf", b"<robot name='r'>" + b"<a>" * 5000 + b"</a>" * 5000 + b"</robot>"),
}


def _urdf(extra_joint_xml: str = "", joint_inner: str = "", links: str = "") -> bytes:
    text = (
        f'<robot name="r"><link name="a"/><link name="b"/>{links}'
        f'<joint name="j" type="revolute"><parent link="a"/><child link="b"/>{joint_inner}'
        f'<limit lower="-1" upper="1" velocity="1"/></joint>{extra_joint_xml}</robot>'
    )
    return text.encode()


def _fixed(name: str, parent: str, child: str) -> str:
    return f'<joint name="{name}" type="fixed"><parent link="{parent}"/><child link="{child}"/></joint>'


CASES["urdf_origin_1e308"] = ("origin.urdf", _urdf(joint_inner='<origin xyz="1e308 0 0"/>'))
CASES["urdf_axis_1e308"] = ("axis.urdf", _urdf(joint_inner='<axis xyz="1e308 1e308 0"/>'))
CASES["urdf_self_parent"] = ("loop.urdf", _urdf(_fixed("k", "c", "c"), links='<link name="c"/>'))
CASES["urdf_cycle"] = (
    "cycle.urdf",
    _urdf(_fixed("k", "c", "d") + _fixed("m", "d", "c"), links='<link name="c"/><link name="d"/>'),
)
_MANY = 20_000  # and as many side links: quadratic loading took minutes, linear well under a second
CASES["urdf_many_links"] = (
    "many.urdf",
    (
        '<robot name="many">'
        + "".join(f'<link name="l{i}"/><link name="side{i}"/>' for i in range(_MANY - 1))
        + f'<link name="l{_MANY - 1}"/><link name="l{_MANY}"/>'
        + "".join(
            _fixed(f"f{i}", f"l{i}", f"l{i + 1}") + _fixed(f"s{i}", f"l{i}", f"side{i}") for i in range(_MANY - 1)
        )
        + f'<joint name="last" type="revolute"><parent link="l{_MANY - 1}"/><child link="l{_MANY}"/>'
        '<origin xyz="0 0 0.5"/><limit lower="-1" upper="1" velocity="1"/></joint></robot>'
    ).encode(),
)
_ENTITIES = ['<!ENTITY a0 "lol">'] + [f'<!ENTITY a{i} "{f"&a{i - 1};" * 10}">' for i in range(1, 10)]
CASES["urdf_entity_bomb"] = (
    "lol.urdf",
    f'<?xml version="1.0"?><!DOCTYPE robot [{"".join(_ENTITIES)}]><robot name="&a9;"><link name="a"/></robot>'.encode(),
)


def outcome(path: Path) -> dict:
    """``manip_kin fk --robot PATH --json`` in this process (see :func:`bounded_cli.run_cli`)."""
    return {"path": str(path), **run_cli(["fk", "--robot", str(path), "--json"])}


def problem_with(result: dict) -> str | None:
    """Why an outcome breaks the rules, or None."""
    if result["rc"] == 0:

        def no_constant(name):
            raise ValueError(f"{name} in the JSON output")

        try:
            pose = json.loads(result["stdout"], parse_constant=no_constant)
        except ValueError as error:
            return f"exit 0 with invalid JSON: {error}"
        numbers = [v for row in pose["matrix"] for v in row] + pose["xyz"]
        if not all(math.isfinite(v) for v in numbers):
            return "exit 0 with a non-finite pose"
        return None
    problem = one_line_refusal_problem(result, result["path"])
    if problem is None and "field '" not in result["stderr"]:
        return f"the error does not name the field: {result['stderr']}"
    return problem


def _write(directory: Path, name: str, content: bytes) -> Path:
    # A fresh name for every file: load_robot caches by path and mtime.
    _write.count = getattr(_write, "count", 0) + 1
    path = directory / f"{_write.count:05d}_{name}"
    path.write_bytes(content)
    return path


def _base_files() -> dict[str, bytes]:
    from manip_kin.core.robots import load_robot
    from manip_kin.core.urdf import model_to_urdf

    bases = {p.name: p.read_bytes() for p in sorted((REPO / "config" / "robots").glob("*.yaml"))}
    bases.update({p.name: p.read_bytes() for p in sorted((REPO / "test" / "data").glob("*.urdf"))})
    bases["genova7_export.urdf"] = model_to_urdf(load_robot("genova7")).encode()
    return bases


def run_hypothesis(directory: Path, examples: int) -> str | None:
    """Mutated robot files; None when all of them obey the rules, else the failure."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    bases = _base_files()
    number = re.compile(rb"(?<![\w.])-?\d+(\.\d+)?(e-?\d+)?(?![\w.])")
    attribute = re.compile(rb'(xyz|rpy|lower|upper|velocity)="[^"]*"')
    link_reference = re.compile(rb'link="([^"]*)"')

    @st.composite
    def mutation(draw, content: bytes, urdf: bool):
        kind = draw(st.sampled_from(["value", "value", "link", "line", "truncate", "bytes", "nest"]))
        if kind == "value":
            spots = list((attribute if urdf else number).finditer(content))
            if spots:
                spot = draw(st.sampled_from(spots))
                if urdf:
                    value = draw(st.sampled_from(HOSTILE_ATTRIBUTES)).encode()
                    replacement = spot.group(1) + b'="' + value + b'"'
                else:
                    replacement = draw(st.sampled_from(HOSTILE_NUMBERS)).encode()
                return content[: spot.start()] + replacement + content[spot.end() :]
        if kind == "link" and urdf:
            spots = list(link_reference.finditer(content))
            names = sorted({m.group(1) for m in spots})
            if spots:
                spot, name = draw(st.sampled_from(spots)), draw(st.sampled_from(names))
                return content[: spot.start(1)] + name + content[spot.end(1) :]
        lines = content.split(b"\n")
        if kind == "line" and len(lines) > 1:
            index = draw(st.integers(0, len(lines) - 1))
            repeat = draw(st.integers(0, 3))
            return b"\n".join(lines[:index] + [lines[index]] * repeat + lines[index + 1 :])
        if kind == "truncate":
            return content[: draw(st.integers(0, len(content)))]
        if kind == "bytes":
            at = draw(st.integers(0, len(content)))
            return content[:at] + draw(st.binary(min_size=1, max_size=6)) + content[at:]
        if urdf:
            return content.replace(b"<link ", b"<a>" * 100 + b"<link ", 1)
        return _alias_bomb(draw(st.integers(2, 9))).encode() + content

    @st.composite
    def mutated_file(draw):
        name = draw(st.sampled_from(sorted(bases)))
        content = bases[name]
        for _ in range(draw(st.integers(1, 3))):
            content = draw(mutation(content, name.endswith(".urdf")))
        return name, content

    @settings(
        derandomize=True,
        max_examples=examples,
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(mutated_file())
    def check(named):
        name, content = named
        problem = problem_with(outcome(_write(directory, name, content)))
        assert problem is None, f"{name} mutated to {content[:300]!r}: {problem}"

    return first_failure(check)


def main(out: str, examples: int) -> None:
    limit_this_process()
    results: dict = {}
    with tempfile.TemporaryDirectory() as directory:
        for case, (name, content) in CASES.items():
            results[case] = outcome(_write(Path(directory), name, content))
            save_progress(out, results)
        # The same bytes behind a .urdf symlink to a name without a suffix: read as URDF.
        target = _write(Path(directory), "noext", _urdf(joint_inner='<origin xyz="0.25 0 0"/>'))
        link = Path(directory) / "arm.urdf"
        os.symlink(target, link)
        results["urdf_symlink"] = outcome(link)
        results["hypothesis"] = {"problem": run_hypothesis(Path(directory), examples)}
    save_progress(out, results)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
