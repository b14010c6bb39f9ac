"""Commands that use a calibration: ``track``, ``view``."""

from __future__ import annotations

import argparse
import sys

from lhgraph.choices import RENDERERS
from lhgraph.cli.common import (
    COMMANDS,
    add_common_output,
    mark_inputs,
    print_verdict,
    verdict_exit,
)

# --- track ---


def add_track(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("track", help="the receiver's path with the stations held fixed",
                       description="Track the board through its angles with every station held "
                       "at its pose in the stations TOML; write the trajectory CSV "
                       "(docs/track.md).")
    for flags, what in ((("--stations",), "stations TOML (held fixed)"),
                        (("--angles",), "angles CSV"),
                        (("--board",), "board TOML or built-in name (e.g. crazyflie_deck)"),
                        (("--output", "-o"), "trajectory CSV to write")):
        p.add_argument(*flags, required=True, help=what)
    p.add_argument("--calibration", help="factory calibration (ootx.toml) of the stations")
    p.add_argument("--imu", help="the receiver's imu.csv (board frame, the angles' clock): "
                   "gyro and accelerometer factors (batch only; docs/track.md)")
    p.add_argument("--streaming", action="store_true", help="one sync cycle at a time")
    p.add_argument("--delay", type=float, metavar="S",
                   help="streaming: report each state S seconds after it (default: 0.1; "
                   "docs/track.md)")
    add_common_output(p)
    mark_inputs(p, "stations", "angles", "board", "calibration", "imu")
    return p


def run_track(args: argparse.Namespace) -> int:
    from lhgraph.workflow.track import track_files

    progress = None if args.quiet else (lambda msg: print(f"  {msg}", file=sys.stderr))
    out = track_files(args.board, args.angles, args.stations, args.output, args.calibration,
                      args.streaming, args.force, progress=progress, delay_s=args.delay,
                      imu=args.imu)
    if not args.quiet:
        print(out.summary())
    if out.verdict is None:
        return 0
    print_verdict(args, out.verdict)
    return verdict_exit([out.verdict])


COMMANDS.append(("track", add_track, run_track))


# --- view ---


def add_view(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("view", help="3-D view of a run directory (Open3D)",
                       description="Show a run directory's stations (with sweep frusta), board "
                       "path and diodes in an Open3D window, or --export the scene without a "
                       "display (docs/workflow.md).")
    p.add_argument("run_dir", help="run directory: one method's, or a multi-method one "
                   "(every method shown unless --method)")
    p.add_argument("--method", help="of a multi-method run directory, show only this method")
    p.add_argument("--export", help="write FILE.png, .ply, .glb, .gltf or .obj instead")
    p.add_argument("--renderer", choices=RENDERERS, default="auto",
                   help="PNG renderer (auto: Open3D offscreen, else matplotlib)")
    add_common_output(p)
    mark_inputs(p, "run_dir")
    return p


def run_view(args: argparse.Namespace) -> int:
    from lhgraph.report.viewer import build_scene, export, show

    scene = build_scene(args.run_dir, method=args.method)
    if args.export:
        path, how = export(scene, args.export, args.force, args.renderer)
        if not args.quiet:
            print(f"wrote {path} ({how})")
    else:
        show(scene)
    return 0


COMMANDS.append(("view", add_view, run_view))
