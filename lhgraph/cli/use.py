"""Commands that use a calibration: ``track``, ``view``, ``compare``."""

from __future__ import annotations

import argparse
import sys

from lhgraph.choices import RENDERERS
from lhgraph.cli.common import (
    COMMANDS,
    add_common_output,
    at_least,
    mark_inputs,
    print_verdict,
    verdict_exit,
)
from lhgraph.errors import InputError
from lhgraph.estimation.watch_options import WatchOptions

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
    p.add_argument("--watch", action="store_true",
                   help="also watch for a station that moved during the capture: 'station N "
                   "moved at t = ... s', exit 3 (docs/track.md)")
    p.add_argument("--watch-window", type=at_least(0, strict=True), metavar="S",
                   default=WatchOptions.window_s,
                   help="watch: the windows' length (s), one every sixth of it")
    p.add_argument("--watch-k-sigma", type=at_least(0, strict=True),
                   default=WatchOptions.k_sigma,
                   help="watch: a window is out over this many sigmas of its history")
    p.add_argument("--watch-csv", metavar="FILE",
                   help="watch: write every station's window tests to this CSV")
    add_common_output(p)
    mark_inputs(p, "stations", "angles", "board", "calibration", "imu")
    return p


def run_track(args: argparse.Namespace) -> int:
    from lhgraph.io.files import check_writable
    from lhgraph.workflow.track import track_files

    if (args.watch_csv or args.watch_window != WatchOptions.window_s
            or args.watch_k_sigma != WatchOptions.k_sigma) and not args.watch:
        raise InputError("the watch's options need --watch", "--watch-csv" if args.watch_csv
                         else "--watch-window/--watch-k-sigma")
    if args.watch_csv:
        check_writable(args.watch_csv, args.force)
    watch = None
    if args.watch:
        try:
            watch = WatchOptions(window_s=args.watch_window, step_s=args.watch_window / 6,
                                 k_sigma=args.watch_k_sigma)
        except InputError as e:  # name the flag, not the option
            flag = {"window_s": "--watch-window", "k_sigma": "--watch-k-sigma"}
            raise InputError(e.problem, flag.get(e.where or "", e.where)) from None
    progress = None if args.quiet else (lambda msg: print(f"  {msg}", file=sys.stderr))
    out = track_files(args.board, args.angles, args.stations, args.output, args.calibration,
                      args.streaming, args.force, progress=progress, delay_s=args.delay,
                      imu=args.imu, watch_options=watch)
    if not args.quiet:
        print(out.summary())
    if out.watch is not None:
        if args.watch_csv:
            from lhgraph.report.station_watch import save_watch_tests

            save_watch_tests(out.watch, args.watch_csv, args.force)
        if args.quiet:
            for move in out.watch.moves:
                print(f"MOVED: {move.message()}")
    if out.verdict is not None:
        print_verdict(args, out.verdict)
    moved = 3 if out.watch is not None and out.watch.moves else 0
    return max(moved, verdict_exit([out.verdict]) if out.verdict is not None else 0)


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


# --- compare ---


def add_compare(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("compare", help="did a station move between two calibrations?",
                       description="Compare two stations TOMLs of one room station by station "
                       "in the frame of a station they share: each difference in mm, degrees "
                       "and combined sigmas, and a verdict (exit 0 same layout, 3 a station "
                       "moved; docs/compare.md).")
    p.add_argument("a", help="stations TOML (the earlier calibration)")
    p.add_argument("b", help="stations TOML (the later calibration)")
    p.add_argument("--reference", type=int, help="the common station whose frame both are "
                   "compared in (default: A's reference if B has it, else the lowest common)")
    p.add_argument("--k-sigma", type=float, default=3.0,
                   help="moved: over this many combined sigmas...")
    p.add_argument("--floor-mm", type=float, default=40.0,
                   help="...and over this position difference (mm; docs/compare.md)")
    p.add_argument("--floor-deg", type=float, default=0.6,
                   help="...or this rotation difference (deg)")
    p.add_argument("--json", help="also write the comparison as JSON to this file")
    add_common_output(p)
    mark_inputs(p, "a", "b")
    return p


def run_compare(args: argparse.Namespace) -> int:
    from lhgraph.estimation.layout_compare import CompareOptions, compare_layouts
    from lhgraph.io.stations import load_stations
    from lhgraph.report.layout_compare import comparison_json, comparison_table

    a, b = load_stations(args.a), load_stations(args.b)
    options = CompareOptions(args.k_sigma, args.floor_mm, args.floor_deg)
    result = compare_layouts(a, b, args.reference, options)
    if args.json:
        from lhgraph.io.files import write_atomic

        write_atomic(args.json, comparison_json(result, args.a, args.b).encode(), args.force)
    if not args.quiet:
        print(comparison_table(result))
    print(("verdict: " if not result.moved else "MOVED: ") + result.verdict())
    return 3 if result.moved else 0


COMMANDS.append(("compare", add_compare, run_compare))
