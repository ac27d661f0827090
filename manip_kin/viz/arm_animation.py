"""The arm as its recording's TF draws it: link positions over time, a picture and an animation.

:func:`iter_tf_poses` replays ``/tf_static`` and ``/tf`` of a recording as a TF listener
would (the latest transform per child frame) and yields, for every ``/tf`` message, the
pose of every frame composed from the root. :func:`load_arm_frames` turns that into
arrays for drawing; :func:`draw_arm_picture` and :func:`write_animation` draw them with
matplotlib (Agg; GIF through Pillow, MP4 through ffmpeg).
"""

from __future__ import annotations

import shutil
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from manip_kin.core.tf_tree import LinkTransform, compose
from manip_kin.errors import InvalidArgumentError
from manip_kin.recording.tf_message import TF_MESSAGE_TYPE, TF_STATIC_TOPIC, TF_TOPIC, decode_tf_message
from manip_kin.viz.figure_axes import equal_3d_axes

ANIMATION_FORMATS = ("gif", "mp4")


def iter_tf_poses(path: str | Path, root: str | None = None) -> Iterator[tuple[int, int, dict[str, np.ndarray]]]:
    """``(stamp_ns, log_time_ns, {frame: 4x4 pose in root})`` for every ``/tf`` message of a recording.

    Args:
        path: ``.mcap`` file or bag directory.
        root: frame to compose from; default: the parent that is nobody's child
            (``base_link`` for manip_kin's robots).
    """
    latest: dict[str, LinkTransform] = {}
    for raw, decoded in _tf_messages(path, [TF_TOPIC, TF_STATIC_TOPIC]):
        for _, transform in decoded:
            latest[transform.child] = transform
        if raw.topic != TF_TOPIC or not decoded:
            continue
        start = root
        if start is None:
            parents = {t.parent for t in latest.values()} - set(latest)
            start = sorted(parents)[0] if parents else decoded[0][1].parent
        yield decoded[0][0], raw.log_time_ns, compose(latest.values(), start)


def _tf_messages(path: str | Path, topics: list[str]) -> Iterator[tuple[object, list]]:
    """``(raw message, decoded transforms)`` of the TFMessage topics among ``topics``.

    Raises:
        CorruptRecordingError: a message that is not a TFMessage in CDR.
    """
    from manip_kin.recording.errors import CorruptRecordingError
    from manip_kin.recording.msgdef import normalize_type_name
    from manip_kin.recording.reader import iter_raw_messages

    for raw in iter_raw_messages(path, topics=topics):
        try:
            if normalize_type_name(raw.type) != TF_MESSAGE_TYPE:
                continue  # a /tf of another type is not TF
            decoded = decode_tf_message(raw.data)
        except (ValueError, struct.error, IndexError, OverflowError) as error:
            raise CorruptRecordingError(
                f"{path}: the {raw.type or 'untyped'} message on {raw.topic} at {raw.log_time_ns} ns is no "
                f"TFMessage ({type(error).__name__}: {str(error)[:80]})"
            ) from None
        yield raw, decoded


@dataclass(frozen=True)
class ArmFrames:
    """Frame origins over time, from a recording's TF.

    Attributes:
        time: seconds since the first ``/tf`` message (receive time), shape (T,).
        stamp_ns: header stamps, shape (T,).
        frames: frame ids, ordered so that parents come before children.
        positions: origin of every frame in the root frame [m], shape (T, F, 3).
        edges: ``(parent index, child index)`` of the tree, drawn as links.
    """

    time: np.ndarray
    stamp_ns: np.ndarray
    frames: tuple[str, ...]
    positions: np.ndarray
    edges: tuple[tuple[int, int], ...]


def load_arm_frames(path: str | Path) -> ArmFrames | None:
    """Every ``/tf`` instant of a recording as arrays; None when it has no ``/tf``."""
    samples = list(iter_tf_poses(path))
    if not samples:
        return None
    parent_of: dict[str, str] = {}
    for raw, decoded in _tf_messages(path, [TF_STATIC_TOPIC, TF_TOPIC]):
        for _, transform in decoded:
            parent_of.setdefault(transform.child, transform.parent)
        if raw.topic == TF_TOPIC:
            break  # the first /tf message names every moving frame
    frames = [f for f in samples[-1][2] if all(f in poses for _, _, poses in samples)]
    index = {name: i for i, name in enumerate(frames)}
    edges = tuple((index[parent_of[f]], index[f]) for f in frames if parent_of.get(f) in index)
    positions = np.array([[poses[f][:3, 3] for f in frames] for _, _, poses in samples])
    log_times = np.array([log for _, log, _ in samples], dtype=np.int64)
    return ArmFrames(
        time=(log_times - log_times[0]) * 1e-9,
        stamp_ns=np.array([stamp for stamp, _, _ in samples], dtype=np.int64),
        frames=tuple(frames),
        positions=positions,
        edges=edges,
    )


# Seen from the side and slightly above: genova7 and the others reach out along y, where the
# default view (elevation 30°, azimuth -60°) foreshortens the arm.
VIEW_ELEVATION_DEG = 15.0
VIEW_AZIMUTH_DEG = -15.0


def set_arm_view(axis, points: np.ndarray) -> None:
    """The view of every arm picture: from the side, slightly above, orthographic, equal axes."""
    axis.view_init(elev=VIEW_ELEVATION_DEG, azim=VIEW_AZIMUTH_DEG)
    axis.set_proj_type("ortho")  # no perspective: heights read true against the z axis
    equal_3d_axes(axis, points)


def draw_arm(axis, arm: ArmFrames, sample: int, colour, label: str | None = None):
    """The arm of TF instant ``sample`` as lines between frame origins; returns (lines, joints)."""
    lines = []
    for k, (parent, child) in enumerate(arm.edges):
        segment = arm.positions[sample, [parent, child]]
        (line,) = axis.plot(*segment.T, color=colour, linewidth=3, label=label if k == 0 else None)
        lines.append(line)
    (joints,) = axis.plot(*arm.positions[sample].T, linestyle="", marker="o", markersize=4, color="tab:orange")
    return lines, joints


def draw_arm_picture(arm: ArmFrames, out: str | Path, tool_frame: str = "tool", title: str = "", instants: int = 4):
    """A PNG of the arm at a few instants and the tool's path, drawn from TF alone."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure = plt.figure(figsize=(7, 7))
    axis = figure.add_subplot(projection="3d")
    samples = np.unique(np.linspace(0, len(arm.time) - 1, instants).astype(int))
    for k, sample in enumerate(samples):
        shade = 0.75 - 0.55 * k / max(1, len(samples) - 1)
        draw_arm(axis, arm, sample, (shade, shade, shade + 0.1), f"arm at t = {arm.time[sample]:.1f} s")
    if tool_frame in arm.frames:
        tool = arm.positions[:, arm.frames.index(tool_frame)]
        axis.plot(*tool.T, color="tab:purple", linewidth=1.5, label=f"{tool_frame} path")
    axis.scatter(0, 0, 0, color="black", marker="s", s=30, label=arm.frames[0])
    set_arm_view(axis, arm.positions.reshape(-1, 3))
    axis.set_title(title or "arm from the recording's /tf")
    axis.legend(loc="upper left", fontsize="small")
    figure.tight_layout()
    figure.savefig(out, dpi=110)
    plt.close(figure)
    return Path(out)


def write_animation(
    arm: ArmFrames,
    out: str | Path,
    tool_frame: str = "tool",
    fps: float = 15.0,
    max_frames: int = 150,
    title: str = "",
) -> Path:
    """An animation of the arm along the run (GIF or MP4 by ``out``'s suffix).

    The run is sampled at ``max_frames`` evenly spaced ``/tf`` instants at most; the title
    shows the recording time of each frame.

    Raises:
        InvalidArgumentError: an unknown suffix, or MP4 without ffmpeg on PATH.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter

    out = Path(out)
    kind = out.suffix.lower().lstrip(".")
    if kind not in ANIMATION_FORMATS:
        raise InvalidArgumentError(f"animation {out}: unknown format {out.suffix!r}; valid: .gif, .mp4")
    if kind == "mp4" and shutil.which("ffmpeg") is None:
        raise InvalidArgumentError("an .mp4 animation needs ffmpeg on PATH; use --gif (Pillow) instead")
    samples = np.unique(np.linspace(0, len(arm.time) - 1, min(max_frames, len(arm.time))).astype(int))
    figure = plt.figure(figsize=(6, 6))
    axis = figure.add_subplot(projection="3d")
    set_arm_view(axis, arm.positions.reshape(-1, 3))
    lines, joints = draw_arm(axis, arm, samples[0], "dimgray")
    tool_index = arm.frames.index(tool_frame) if tool_frame in arm.frames else len(arm.frames) - 1
    (trail,) = axis.plot([], [], [], color="tab:purple", linewidth=1.5)
    heading = axis.set_title("")

    def update(frame: int):
        sample = samples[frame]
        for line, (parent, child) in zip(lines, arm.edges):
            segment = arm.positions[sample, [parent, child]]
            line.set_data_3d(segment[:, 0], segment[:, 1], segment[:, 2])
        points = arm.positions[sample]
        joints.set_data_3d(points[:, 0], points[:, 1], points[:, 2])
        path = arm.positions[: sample + 1, tool_index]
        trail.set_data_3d(path[:, 0], path[:, 1], path[:, 2])
        heading.set_text(f"{title + ': ' if title else ''}t = {arm.time[sample]:.2f} s")
        return [*lines, joints, trail, heading]

    animation = FuncAnimation(figure, update, frames=len(samples), blit=False)
    writer = PillowWriter(fps=fps) if kind == "gif" else FFMpegWriter(fps=fps)
    out.parent.mkdir(parents=True, exist_ok=True)
    animation.save(out, writer=writer, dpi=80)
    plt.close(figure)
    return out
