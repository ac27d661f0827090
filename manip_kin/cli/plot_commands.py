"""``manip_kin plot FILE [--out DIR] [--gif|--mp4 [OUT]]``: PNG figures and an animation of a recorded run."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from manip_kin.viz.collision_plot import FIGURE as COLLISION_FIGURE
from manip_kin.viz.plotting import FIGURES, plot_run
from manip_kin.viz.run_data import load_run


def register(subparsers) -> None:
    """Add the ``plot`` sub-command."""
    parser = subparsers.add_parser(
        "plot",
        help="write PNG figures of a recorded run (tool vs reference, errors, velocities, joints, 3D path)",
        description="Figures: " + ", ".join(FIGURES) + f"; {COLLISION_FIGURE} (the arm, the obstacles and the "
        "nearest pair) when the controller ran with collision_avoidance. Times are seconds since the first message.",
    )
    parser.add_argument("file", metavar="FILE", help="a recording: .mcap file or rosbag2 bag directory")
    parser.add_argument(
        "--out", metavar="DIR", default=None, help="output directory (default: next to FILE, <name>_plots)"
    )
    parser.add_argument("--title", default="", help="prefix for the figure titles")
    parser.add_argument(
        "--namespace",
        default="",
        metavar="NS",
        help="plot the pipeline recorded in namespace NS (/NS/joint_states...; default: the root namespace)",
    )
    animation = parser.add_mutually_exclusive_group()
    animation.add_argument(
        "--gif",
        nargs="?",
        const="",
        default=None,
        metavar="OUT",
        help="also write an animation of the arm from the recording's /tf (default OUT: DIR/arm.gif)",
    )
    animation.add_argument(
        "--mp4", nargs="?", const="", default=None, metavar="OUT", help="as --gif, as MP4 (needs ffmpeg on PATH)"
    )
    parser.add_argument(
        "--frames", type=int, default=150, metavar="N", help="animation frames, evenly spread over the run (150)"
    )
    parser.add_argument(
        "--render",
        action="store_true",
        help="also draw the arm with MuJoCo's offscreen renderer (EGL; MUJOCO_GL=osmesa for OSMesa): "
        "DIR/render_{start,middle,end}.png and DIR/render.gif, 60 frames, with the recorded collision_objects",
    )
    parser.add_argument(
        "--mesh-search-path",
        default="",
        metavar="DIRS",
        help="':'-separated directories holding packages, for the URDF's package:// meshes (--render)",
    )
    parser.set_defaults(run=run_plot)


def run_plot(args: argparse.Namespace) -> int:
    source = Path(args.file)
    out_dir = Path(args.out) if args.out else source.parent / f"{source.stem}_plots"
    run = load_run(source, namespace=args.namespace)
    for plotted, recorded in run.found_by_type.items():
        print(f"plot: {plotted} read from {recorded} (found by its type)", file=sys.stderr)
    paths = plot_run(run, out_dir, title=args.title or source.stem)
    for path in paths:
        print(path)
    paths += _collision_figure(source, run, out_dir, args)
    print(f"wrote {len(paths)} figures to {out_dir}", file=sys.stderr)
    if args.render:
        from manip_kin.viz.physics_render import recorded_scene, render_run

        print("rendering 60 frames with MuJoCo ...", file=sys.stderr, flush=True)
        scene = recorded_scene(source, args.namespace)
        for path in render_run(run, out_dir, mesh_search_path=args.mesh_search_path, scene=scene):
            print(path)
    kind = "gif" if args.gif is not None else "mp4" if args.mp4 is not None else None
    if kind is not None:
        from manip_kin.errors import InvalidArgumentError
        from manip_kin.viz.arm_animation import write_animation

        if run.arm is None:
            raise InvalidArgumentError(
                f"{source} has no /tf to animate; add it with `manip_kin info --add-tf OUT {source}`"
            )
        if args.frames < 2:
            raise InvalidArgumentError(f"--frames {args.frames}; valid: 2 or more")
        target = Path((args.gif if kind == "gif" else args.mp4) or out_dir / f"arm.{kind}")
        print(f"animating {min(args.frames, len(run.arm.time))} frames ...", file=sys.stderr, flush=True)
        print(write_animation(run.arm, target, max_frames=args.frames, title=args.title or source.stem))
    return 0


def _collision_figure(source: Path, run, out_dir: Path, args) -> list[Path]:
    """``collision.png`` when the recording holds the controller's nearest pair; else nothing."""
    from manip_kin.viz.collision_plot import arm_from_joint_states, load_nearest, plot_collision
    from manip_kin.viz.physics_render import recorded_scene

    nearest = load_nearest(source, args.namespace)
    if not len(nearest.time):
        return []
    scene = recorded_scene(source, args.namespace)
    arm = run.arm or arm_from_joint_states(run)
    path = plot_collision(arm, scene, nearest, out_dir / COLLISION_FIGURE, title=args.title or source.stem)
    print(path)
    return [path]
