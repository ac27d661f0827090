"""Figures of a recorded run for a person to read (``manip_kin plot``).

:func:`~manip_kin.viz.run_data.load_run` turns a recording into plain arrays (no plotting,
testable); :func:`plot_run` draws the figures with matplotlib's non-interactive Agg backend:

* ``tool_position.png``: tool position vs its reference (goal pose) over time
* ``errors.png``: position and orientation error norms, log scale
* ``velocities.png``: tool and end-effector linear and angular speed
* ``joint_positions.png``: every joint with its position limits
* ``joint_rate_commands.png``: the joint-rate commands
* ``path_3d.png``: the tool path against the planned line, and the arm at a few instants
  (drawn from the recording's ``/tf`` when it has one, else from the model's kinematics)
* ``arm_tf.png`` (recordings with ``/tf``): the arm at a few instants, from TF alone

An animation of the arm (:func:`manip_kin.viz.arm_animation.write_animation`) is ``manip_kin plot
--gif`` / ``--mp4``.

Times are seconds since the first message of the run (receive time).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from manip_kin.viz.arm_animation import draw_arm_picture
from manip_kin.viz.figure_axes import equal_3d_axes
from manip_kin.viz.run_data import RunData, model_from_description, tracking_errors

FIGURES = (
    "tool_position.png",
    "errors.png",
    "velocities.png",
    "joint_positions.png",
    "joint_rate_commands.png",
    "path_3d.png",
)
TF_FIGURE = "arm_tf.png"


def _legend(axis, **options) -> None:
    """A legend when ``axis`` holds a labelled artist (matplotlib warns about an empty one, as
    for a recording without ``/joint_velocity_commands``)."""
    if axis.get_legend_handles_labels()[1]:
        axis.legend(**options)


def plot_run(run: RunData, out_dir: str | Path, title: str = "") -> list[Path]:
    """Write every figure of :data:`FIGURES` for ``run`` into ``out_dir``; returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    prefix = f"{title}: " if title else ""
    written = []
    model = model_from_description(run)

    def save(figure, name):
        figure.tight_layout()
        path = out_dir / name
        figure.savefig(path, dpi=110)
        plt.close(figure)
        written.append(path)

    # 1. tool position vs reference
    figure, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for i, axis_name in enumerate("xyz"):
        axes[i].plot(run.tool.time, run.tool.position[:, i], label=f"tool {axis_name}")
        if len(run.goal.time):
            axes[i].step(
                run.goal.time, run.goal.position[:, i], where="post", linestyle="--", label=f"reference {axis_name}"
            )
        axes[i].set_ylabel(f"{axis_name} [m]")
        _legend(axes[i], loc="best", fontsize="small")
        axes[i].grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(f"{prefix}tool position vs reference (base frame)")
    save(figure, "tool_position.png")

    # 2. error norms
    time, position_error, orientation_error = tracking_errors(run)
    figure, axis = plt.subplots(figsize=(9, 4.5))
    floor = 1e-12  # log scale cannot show an exact zero
    axis.semilogy(time, np.maximum(position_error, floor), label="position error [m]")
    axis.semilogy(time, np.maximum(orientation_error, floor), label="orientation error [rad]")
    axis.set_xlabel("time [s]")
    axis.set_ylabel("error norm")
    axis.set_title(f"{prefix}tool error against the current goal")
    axis.grid(True, which="both", alpha=0.3)
    _legend(axis)
    save(figure, "errors.png")

    # 3. velocities
    figure, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for series, label in ((run.tool_twist, "tool"), (run.ee_twist, "end effector")):
        axes[0].plot(series.time, np.linalg.norm(series.linear, axis=1) if len(series.time) else [], label=label)
        axes[1].plot(series.time, np.linalg.norm(series.angular, axis=1) if len(series.time) else [], label=label)
    axes[0].set_ylabel("linear speed [m/s]")
    axes[1].set_ylabel("angular speed [rad/s]")
    axes[1].set_xlabel("time [s]")
    axes[0].set_title(f"{prefix}tool and end-effector velocity w.r.t. base")
    for axis in axes:
        axis.grid(True, alpha=0.3)
        _legend(axis, loc="best", fontsize="small")
    save(figure, "velocities.png")

    # 4. joint positions with limits
    count = len(run.joint_names)
    columns = 2
    rows = max(1, (count + columns - 1) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(10, 2.2 * rows + 0.6), sharex=True, squeeze=False)
    limits = {}
    if model is not None:
        limits = {j.name: (j.lower, j.upper, j.is_revolute) for j in model.joints}
    for index, name in enumerate(run.joint_names):
        axis = axes[index // columns][index % columns]
        axis.plot(run.joint_time, run.joint_position[:, index], label=name)
        unit = "rad"
        if name in limits:
            lower, upper, revolute = limits[name]
            unit = "rad" if revolute else "m"
            for bound in (lower, upper):
                if np.isfinite(bound) and abs(bound) < 1e5:
                    axis.axhline(bound, color="red", linestyle=":", linewidth=1)
        axis.set_ylabel(f"{name} [{unit}]")
        axis.grid(True, alpha=0.3)
    for index in range(count, rows * columns):
        axes[index // columns][index % columns].axis("off")
    for axis in axes[-1]:
        axis.set_xlabel("time [s]")
    figure.suptitle(f"{prefix}joint positions (dotted red: position limits)")
    save(figure, "joint_positions.png")

    # 5. joint-rate commands
    figure, axis = plt.subplots(figsize=(9, 4.5))
    for index in range(run.command.shape[1] if run.command.ndim == 2 else 0):
        label = run.joint_names[index] if index < len(run.joint_names) else f"joint {index + 1}"
        axis.plot(run.command_time, run.command[:, index], label=label)
    axis.set_xlabel("time [s]")
    axis.set_ylabel("commanded rate [rad/s | m/s]")
    axis.set_title(f"{prefix}joint-rate commands (/joint_velocity_commands)")
    axis.grid(True, alpha=0.3)
    if not len(run.command_time):
        axis.text(0.5, 0.5, "no /joint_velocity_commands in this recording", transform=axis.transAxes, ha="center")
    _legend(axis, loc="best", fontsize="small", ncol=2)
    save(figure, "joint_rate_commands.png")

    # 6. 3D path and arm snapshots
    figure = plt.figure(figsize=(8, 7))
    axis = figure.add_subplot(projection="3d")
    drawn = []  # every plotted point, for equal axis scales
    if run.arm is not None:
        arm = run.arm
        instants = np.unique(np.linspace(0, len(arm.time) - 1, 5).astype(int))
        for k, sample in enumerate(instants):
            shade = 0.2 + 0.6 * k / max(1, len(instants) - 1)
            for e, (parent, child) in enumerate(arm.edges):
                segment = arm.positions[sample, [parent, child]]
                label = f"arm (/tf) at t = {arm.time[sample]:.1f} s" if e == 0 else None
                axis.plot(*segment.T, color=(shade, shade, shade), linewidth=1.5, label=label)
            axis.plot(*arm.positions[sample].T, linestyle="", marker="o", markersize=3, color=(shade, shade, shade))
            drawn.append(arm.positions[sample])
    elif model is not None and len(run.joint_time):
        from manip_kin.core.kinematics import frame_poses

        instants = np.unique(np.linspace(0, len(run.joint_time) - 1, 5).astype(int))
        for k, sample in enumerate(instants):
            q = run.joint_position[sample]
            if q.shape[0] != model.dof:
                break
            origins = frame_poses(model, q)[:, :3, 3]
            shade = 0.2 + 0.6 * k / max(1, len(instants) - 1)
            axis.plot(
                *origins.T,
                marker="o",
                markersize=3,
                color=(shade, shade, shade),
                linewidth=1.5,
                label=f"arm at t = {run.joint_time[sample]:.1f} s",
            )
            drawn.append(origins)
    if len(run.goal.time):
        axis.scatter(*run.goal.position.T, s=2, color="tab:green", alpha=0.2, label="goal poses")
    if len(run.tool.time):
        axis.plot(*run.tool.position.T, label="tool path", color="tab:blue", linewidth=2.5)
        drawn.append(run.tool.position)
    for k, line in enumerate(run.planned_paths):
        axis.plot(*line.T, linestyle="--", color="tab:orange", linewidth=2, label="planned line" if k == 0 else None)
    if drawn:
        # Equal scales on x, y and z, so a straight line and the arm's proportions look as they are.
        equal_3d_axes(axis, np.vstack(drawn))
    axis.set_title(f"{prefix}tool path, planned line and arm (base frame)")
    _legend(axis, loc="upper left", fontsize="small")
    save(figure, "path_3d.png")

    if run.arm is not None:
        written.append(draw_arm_picture(run.arm, out_dir / TF_FIGURE, title=f"{prefix}arm from /tf"))
    return written
