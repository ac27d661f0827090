"""The executables' entry points (manip_kin.entry): each runs its module's main; a Ctrl-C while
that module is still being imported ends the executable quietly with 130."""

import importlib
import re
from pathlib import Path

from manip_kin import entry

SETUP = Path(__file__).resolve().parents[2] / "setup.py"


def _console_scripts() -> dict[str, str]:
    """``name = module:function`` of setup.py's console_scripts."""
    return dict(re.findall(r'"(\w+) = ([\w.:]+)"', SETUP.read_text()))


def test_every_executable_goes_through_an_entry_that_finds_its_main():
    scripts = _console_scripts()
    assert set(scripts) == {
        "manip_kin",
        "robot_state",
        "cartesian_controller",
        "trajectory_generator",
        "recorder",
        "live_view",
    }
    for name, target in scripts.items():
        module, function = target.split(":")
        assert module == "manip_kin.entry" and function == name
        wrapped = getattr(entry, function).module
        assert callable(importlib.import_module(wrapped).main), wrapped


def test_a_ctrl_c_during_the_import_exits_130_and_prints_nothing(monkeypatch, capsys):
    def interrupted(name):
        raise KeyboardInterrupt

    monkeypatch.setattr(entry.importlib, "import_module", interrupted)
    assert entry.recorder() == 130
    assert entry.manip_kin() == 130
    assert capsys.readouterr() == ("", "")


def test_after_the_import_main_runs_and_its_code_is_the_exit_code(monkeypatch):
    class Module:
        @staticmethod
        def main():
            return 7

    monkeypatch.setattr(entry.importlib, "import_module", lambda name: Module)
    assert entry.robot_state() == 7


def test_a_ctrl_c_while_the_cli_registers_its_commands_exits_130(monkeypatch):
    import manip_kin.cli as cli

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["robots"]) == 130
