"""``manip_kin plot FILE [--out DIR]``: PNG figures of a recorded run."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from manip_kin.plotting import FIGURES, load_run, plot_run


def register(subparsers) -> None:
    """Add the ``plot`` sub-command."""
    parser = subparsers.add_parser(
        "plot",
        help="write PNG figures of a recorded run (tool vs reference, errors, velocities, joints, 3D path)",
        description="Figures: " + ", ".join(FIGURES) + ". Times are seconds since the first message.",
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
    parser.set_defaults(run=run_plot)


def run_plot(args: argparse.Namespace) -> int:
    source = Path(args.file)
    out_dir = Path(args.out) if args.out else source.parent / f"{source.stem}_plots"
    run = load_run(source, namespace=args.namespace)
    paths = plot_run(run, out_dir, title=args.title or source.stem)
    for path in paths:
        print(path)
    print(f"wrote {len(paths)} figures to {out_dir}", file=sys.stderr)
    return 0
