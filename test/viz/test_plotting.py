"""Figures of a recording that lacks some topics: drawn without warnings, saying what is missing."""

import warnings
from pathlib import Path

import numpy as np

from manip_kin.core.rotations import matrix_to_quat, rpy_to_matrix
from manip_kin.viz.plotting import FIGURES, plot_run
from manip_kin.viz.run_data import PoseSeries, RunData


def _run_without_commands() -> RunData:
    """Joint states, tool poses and goals of two joints, as a recorder given only those topics
    writes them (the README's two-arm recording); no /joint_velocity_commands, no /tf."""
    time = np.linspace(0.0, 2.0, 41)
    joint_position = np.column_stack([0.5 * time, -0.25 * time])
    tool = PoseSeries(
        time=time,
        position=np.column_stack([np.cos(time), np.sin(time), 0.1 * time]),
        quaternion=np.array([matrix_to_quat(rpy_to_matrix(0.0, 0.0, t)) for t in time]),
    )
    goal = PoseSeries(time=time[:1], position=tool.position[-1:], quaternion=tool.quaternion[-1:])
    return RunData(
        joint_names=["shoulder", "elbow"],
        joint_time=time,
        joint_position=joint_position,
        tool=tool,
        goal=goal,
    )


def test_a_recording_without_commands_plots_without_warnings(tmp_path, monkeypatch):
    import matplotlib.figure

    texts: dict[str, list[str]] = {}
    save = matplotlib.figure.Figure.savefig

    def capture(figure, path, *args, **kwargs):
        texts[Path(path).name] = [text.get_text() for axes in figure.axes for text in axes.texts]
        return save(figure, path, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", capture)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib's "No artists with labels found" was one
        written = plot_run(_run_without_commands(), tmp_path)
    assert sorted(path.name for path in written) == sorted(FIGURES)
    assert texts["joint_rate_commands.png"] == ["no /joint_velocity_commands in this recording"]
    assert texts["joint_positions.png"] == []  # the joint states are there: nothing said missing
