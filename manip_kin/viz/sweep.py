"""The arm's joint frames along a straight line in joint space, and a picture of it.

``manip_kin sweep`` answers "where is every link between two configurations": N + 1 evenly
spaced configurations ``q_k = q_start + k/N (q_goal - q_start)`` (start and goal included),
the position of joint frames 1..n at each, and a 3D figure of the arm at every step.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manip_kin.core.kinematics import frame_poses
from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError
from manip_kin.viz.figure_axes import equal_3d_axes


@dataclass(frozen=True)
class Sweep:
    """Frames of the arm at evenly spaced configurations.

    Attributes:
        q: the configurations, shape (N + 1, n) [rad | m].
        positions: joint frames 1..n in base, shape (N + 1, n, 3) [m].
        chain_points: base, joint frames 1..n, ee and tool (if any) in base, the polyline drawn
            for the arm, shape (N + 1, n + 2 or n + 3, 3) [m].
    """

    q: np.ndarray
    positions: np.ndarray
    chain_points: np.ndarray


def joint_sweep(model: RobotModel, q_start, q_goal, steps: int) -> Sweep:
    """The arm at ``steps + 1`` evenly spaced configurations from ``q_start`` to ``q_goal``.

    Raises:
        InvalidArgumentError: ``steps`` not a positive integer, or a configuration outside the
            joint limits.
    """
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InvalidArgumentError(f"steps = {steps!r}; valid: an integer >= 1")
    start = model.check_q(q_start, "q_start")
    goal = model.check_q(q_goal, "q_goal")
    for name, q in (("q_start", start), ("q_goal", goal)):
        if not model.within_limits(q):
            outside = [
                f"{joint.name} = {value:g} not in [{low:g}, {high:g}]"
                for joint, value, low, high in zip(model.joints, q, model.lower, model.upper)
                if not low - 1e-9 <= value <= high + 1e-9
            ]
            raise InvalidArgumentError(f"{name} is outside the joint limits: {'; '.join(outside)}")
    fractions = np.linspace(0.0, 1.0, steps + 1)[:, None]
    configurations = start + fractions * (goal - start)
    n = model.dof
    last = n + 3 if model.has_tool else n + 2
    chain_points = np.array([frame_poses(model, q)[:last, :3, 3] for q in configurations])
    return Sweep(q=configurations, positions=chain_points[:, 1 : n + 1].copy(), chain_points=chain_points)


def plot_sweep(model: RobotModel, sweep: Sweep, path: str | Path, title: str = "") -> Path:
    """Draw the arm at every step of ``sweep`` into a PNG at ``path``; returns the path.

    3D with equal axis scales; the base is a black square, the start configuration blue,
    the goal red and the steps between grey, darker towards the goal.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure = plt.figure(figsize=(8, 7))
    axes = figure.add_subplot(projection="3d")
    points = sweep.chain_points
    count = len(points)
    for k in range(1, count - 1):
        shade = 0.8 - 0.5 * k / max(count - 1, 1)
        line = points[k]
        axes.plot(line[:, 0], line[:, 1], line[:, 2], color=str(shade), linewidth=1.0, marker=".", markersize=3)
    for k, colour, label in ((0, "tab:blue", "start"), (count - 1, "tab:red", "goal")):
        line = points[k]
        axes.plot(
            line[:, 0], line[:, 1], line[:, 2], color=colour, linewidth=2.5, marker="o", markersize=4, label=label
        )
    end = points[:, -1]
    axes.plot(
        end[:, 0], end[:, 1], end[:, 2], color="tab:green", linestyle="--", linewidth=1.0, label=model.default_frame
    )
    axes.scatter([0.0], [0.0], [0.0], color="black", marker="s", s=60, label=f"base ({model.base_frame})")
    equal_3d_axes(axes, points)
    axes.set_title(title or f"{model.name}: {count - 1} steps in joint space (frames in {model.base_frame})")
    axes.legend(loc="upper left", fontsize="small")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
