"""Hostile robot files (issue 29): every one gives exit 0 with a finite pose or exit 2 naming the
file and the field, within setrlimit bounds on CPU time and memory.

The files are loaded in one subprocess (``hostile_robot_files.py``) that limits itself with
RLIMIT_CPU and RLIMIT_AS and each file with a CPU alarm, so an alias bomb or a quadratic
loop fails the test instead of the machine.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from bounded_cli import CASE_CPU_SECONDS, run_bounded_script
from hostile_robot_files import CASES, problem_with

HERE = Path(__file__).resolve().parent
EXAMPLES = 150


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("hostile_files") / "outcomes.json"
    return run_bounded_script("hostile_robot_files.py", out, str(EXAMPLES))


# What each issue case must be refused for (a word of the field or the problem).
EXPECTED_REFUSALS = {
    "zero_division": ("limits.lower", "divides by zero"),
    "deep_list": ("line 2", "nesting depth"),
    "deep_block": ("line ", "nested deeper than 64"),
    "invalid_utf8": ("line 1, column 7", "invalid UTF-8"),
    "rpy_inf": ("origin.rpy[0]", "out of range"),
    "alias_bomb": ("line ", "aliases expanded"),
    "origin_inf": ("origin.xyz[0]", "out of range"),
    "axis_inf": ("axis[0]", "out of range"),
    "tool_inf": ("tool.xyz[2]", "out of range"),
    "dh_d_inf": ("dh[0].d", "out of range"),
    "poe_screw_inf": ("screw[3]", "out of range"),
    "square_overflow": ("origin.xyz[0]", "out of range"),
    "urdf_origin_1e308": ("joint[j]/origin@xyz", "out of range"),
    "urdf_axis_1e308": ("joint[j]/axis@xyz", "out of range"),
    "urdf_self_parent": ("joint[k]/child@link", "both parent and child"),
    "urdf_cycle": ("joint[m]/child@link", "cycle"),
    "urdf_entity_bomb": ("<!ENTITY>", "entity declarations"),
    "urdf_deep": ("<a>", "nested deeper than 64"),
}


@pytest.mark.parametrize("case", sorted(EXPECTED_REFUSALS))
def test_issue_case_is_refused_with_file_and_field(outcomes, case):
    result = outcomes[case]
    assert problem_with(result) is None, problem_with(result)
    field, problem = EXPECTED_REFUSALS[case]
    assert result["rc"] == 2
    assert f"{CASES[case][0]}: field '" in result["stderr"] and field in result["stderr"], result["stderr"]
    assert problem in result["stderr"]


def test_a_urdf_symlink_to_a_file_without_suffix_is_read_as_urdf(outcomes):
    result = outcomes["urdf_symlink"]
    assert result["rc"] == 0, result["stderr"]
    assert json.loads(result["stdout"])["xyz"] == [0.25, 0.0, 0.0]


def test_mutated_robot_files_exit_0_finite_or_2_with_file_and_field(outcomes):
    assert outcomes["hypothesis"]["problem"] is None, outcomes["hypothesis"]["problem"]


def test_a_urdf_of_40_000_links_loads_within_the_cpu_alarm(outcomes):
    # Side branches at every link: the default-tip walk asks "anything movable below?" at each.
    result = outcomes["urdf_many_links"]
    assert result["rc"] == 0, result.get("escaped") or result["stderr"]
    assert json.loads(result["stdout"])["xyz"] == [0.0, 0.0, 0.5]


def test_a_node_started_with_a_bomb_file_exits_2_with_the_one_line_reason(tmp_path):
    name, content = CASES["alias_bomb"]
    path = tmp_path / name
    path.write_bytes(content)
    completed = subprocess.run(
        [sys.executable, "-m", "manip_kin.ros.nodes.robot_state", "--ros-args", "-p", f"robot:={path}"],
        capture_output=True,
        text=True,
        timeout=CASE_CPU_SECONDS * 6,
    )
    assert completed.returncode == 2, completed.stderr[-2000:]
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}: field 'line " in lines[0] and "aliases expanded" in lines[0], lines
