"""The repository's interface reference (docs/interfaces.md) matches the code, and points nowhere outside."""

import re
import subprocess
from pathlib import Path

import pytest

from manip_kin.cli import build_parser
from manip_kin.ros.nodes import (
    cartesian_controller_interface,
    live_view,
    recorder_config,
    robot_state_interface,
    trajectory_generator_interface,
)
from manip_kin.ros.wire.topics import PIPELINE_TOPIC_TYPES

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "interfaces.md").read_text()


def _section(title: str) -> str:
    """The text under the ``### `title``` heading, up to the next heading."""
    match = re.search(rf"^### `{re.escape(title)}`\n(.*?)(?=^#)", DOC, re.S | re.M)
    assert match, f"docs/interfaces.md has no section ### `{title}`"
    return match.group(1)


def _default_text(spec) -> str:
    if spec.default is None or spec.default_text:
        return spec.default_text
    if isinstance(spec.default, bool):
        return "`true`" if spec.default else "`false`"
    if isinstance(spec.default, str):
        return f"`{spec.default!r}`"
    return f"`{spec.default:g}`" if isinstance(spec.default, float) else f"`{spec.default}`"


@pytest.mark.parametrize(
    "module",
    [robot_state_interface, cartesian_controller_interface, trajectory_generator_interface, recorder_config, live_view],
)
def test_every_node_parameter_is_documented_with_default_unit_liveness_and_range(module):
    rows = {}
    for line in _section(module.NODE_NAME).splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) >= 6 and cells[0].startswith("`"):
            rows[cells[0].strip("`")] = cells
    missing = [spec.name for spec in module.PARAMETERS if spec.name not in rows]
    assert not missing, f"{module.NODE_NAME} parameters not in docs/interfaces.md: {missing}"
    for spec in module.PARAMETERS:
        _, kind, default, unit, live, valid = rows[spec.name][:6]
        assert kind == spec.kind and default == _default_text(spec), (spec.name, rows[spec.name])
        assert unit == spec.unit.replace(" | ", " or "), (spec.name, unit)
        assert live == ("yes" if spec.tunable else "no"), (spec.name, live)
        assert valid == spec.constraint_text(), (spec.name, valid)
    extra = set(rows) - {spec.name for spec in module.PARAMETERS}
    assert not extra, f"documented but not declared by {module.NODE_NAME}: {extra}"


def test_every_topic_and_cli_command_is_documented():
    topics_section = DOC.split("## Topics", 1)[1].split("\n## ", 1)[0]
    documented = {
        name
        for line in topics_section.splitlines()
        if line.startswith("| `")
        for name in re.findall(r"`([^`]+)`", line.split("|")[1])
    }
    assert set(PIPELINE_TOPIC_TYPES) <= documented, set(PIPELINE_TOPIC_TYPES) - documented
    commands = build_parser()._subparsers._group_actions[0].choices
    for command in commands:
        assert f"| `{command}` |" in DOC, f"manip_kin {command} is not in docs/interfaces.md"


def test_nothing_in_the_repository_points_outside_it():
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    offenders = []
    for name in tracked:
        path = ROOT / name
        if path.suffix in (".md", ".py", ".yaml", ".txt", ".toml", ".cfg", ".xml") or path.name == "Makefile":
            if "../shared" in path.read_text(errors="replace") and name != "test/test_docs.py":
                offenders.append(name)
    assert not offenders, f"files pointing outside the repository: {offenders}"
