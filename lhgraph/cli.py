"""Command-line interface: thin parsers over the Python API.

Each command is a pair ``add_<name>(subparsers)`` / ``run_<name>(args) -> int``, registered
in ``COMMANDS``. Errors derived from :class:`LhgraphError` become one line on stderr and
their exit code (2 for bad input); nothing else is caught.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from lhgraph.choices import FORMATS, PERIODS, RENDERERS, SYNCS
from lhgraph.errors import LhgraphError

Runner = Callable[[argparse.Namespace], int]


def _add_common_output(p: argparse.ArgumentParser) -> None:
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.add_argument("--quiet", action="store_true", help="no progress output")


# --- commands ---------------------------------------------------------------------------------
# (each command module's public API does the work; these functions only parse and print)


COMMANDS: list[tuple[str, Callable[[argparse._SubParsersAction], argparse.ArgumentParser],
                     Runner]] = []


# --- simulate ---


def add_simulate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("simulate", help="simulate a capture with known truth",
                       description="Simulate a capture of a waved board (docs/simulator.md) and "
                       "write angles.csv, board.toml, truth.toml and trajectory.csv.")
    p.add_argument("config", nargs="?", help="simulation TOML (default: the bundled default)")
    p.add_argument("--output", "-o", required=True, help="output directory")
    p.add_argument("--seed", type=int, help="random seed (overrides the config's seed)")
    p.add_argument("--capture", action="store_true",
                   help="also write the raw signal a board would record (capture.lhcap)")
    _add_common_output(p)
    return p


def run_simulate(args: argparse.Namespace) -> int:
    from lhgraph.sim.simulate import (
        default_simulation_config,
        load_simulation_config,
        simulate,
        write_simulation,
    )

    config = (default_simulation_config() if args.config is None
              else load_simulation_config(args.config))
    capture = simulate(config, args.seed)
    paths = write_simulation(capture, args.output, args.force, raw_capture=args.capture)
    if not args.quiet:
        print(f"{capture.summary()}; wrote {', '.join(p.name for p in paths.values())} "
              f"to {args.output}")
    return 0


COMMANDS.append(("simulate", add_simulate, run_simulate))


# --- solve ---


def add_solve(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from lhgraph.choices import METHODS, WORLDS

    p = sub.add_parser("solve", help="calibrate the station poses",
                       description="Calibrate the stations' poses from a board capture's angles "
                       "(docs/solve.md). Either a CONFIG.toml or --board/--angles/--output.")
    p.add_argument("config", nargs="?", help="solve configuration TOML")
    p.add_argument("--board", help="board TOML")
    p.add_argument("--angles", help="angles CSV")
    p.add_argument("--output", "-o", help="stations TOML to write (with a CONFIG: a path "
                   "without .toml or an existing directory = a run directory, docs/workflow.md)")
    p.add_argument("--method", choices=METHODS, help="default: graph")
    p.add_argument("--trajectory", help="also write the board trajectory CSV")
    p.add_argument("--calibration", help="factory calibration (ootx.toml) of the stations")
    p.add_argument("--truth", help="true stations TOML: print the errors")
    p.add_argument("--reference", type=int, help="station index of the world frame")
    p.add_argument("--duration", type=float, metavar="S",
                   help="solve only the first S seconds in which the board moves")
    p.add_argument("--world", choices=WORLDS,
                   help="world frame: the reference station's (default) or gravity-aligned, "
                   "z up from the stations' OOTX accelerometer vectors")
    _add_common_output(p)
    return p


def run_solve(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from lhgraph.config import override
    from lhgraph.errors import InputError
    from lhgraph.report.text import format_comparison, print_solution
    from lhgraph.workflow.rundir import comparison_rows, is_run_directory, run_to_directory
    from lhgraph.workflow.solve import solve_to_files
    from lhgraph.workflow.solve_config import SolveConfig, load_solve_config

    flags = {f"--{name}": (name, getattr(args, name))
             for name in ("output", "method", "trajectory", "calibration", "truth", "reference",
                          "world")}
    flags["--duration"] = ("duration_s", args.duration)
    if args.config:
        config = load_solve_config(args.config)
    else:
        missing = [o for o in ("board", "angles", "output") if getattr(args, o) is None]
        if missing:
            raise InputError("give a CONFIG.toml or all of --board, --angles, --output "
                             f"(missing: {', '.join('--' + m for m in missing)})")
        config = SolveConfig(board=Path(args.board))
        flags["--angles"] = ("angles", args.angles)
    config = override(config, flags)
    if args.method is not None:
        config = replace(config, methods=None)
    if config.output is None:
        raise InputError("no output: give --output or set 'output' in the config")
    progress = None if args.quiet else (lambda msg: print(f"  {msg}", file=sys.stderr))
    if args.config and is_run_directory(config.output):
        run = run_to_directory(config, config.output, args.force, progress)
        if not args.quiet:
            for r in run.runs:
                print_solution(r.result, r.errors)
            if len(run.runs) > 1:
                print(format_comparison(comparison_rows(run.runs)))
            print(f"wrote {len(run.files)} files to {run.directory}; report: {run.report}")
        return 0
    result, errors, written = solve_to_files(config, args.force, progress)
    if not args.quiet:
        print_solution(result, errors)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return 0


COMMANDS.append(("solve", add_solve, run_solve))


# --- decode ---


def add_decode(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("decode", help="decode a capture into angles and OOTX calibration",
                       description="Decode a board capture (.lhcap), a raw sample dump or a "
                       "libsurvive recording into DIR/angles.csv and DIR/ootx.toml "
                       "(docs/decoding.md).")
    p.add_argument("capture", help="capture file")
    p.add_argument("--output", "-o", required=True, help="output directory")
    p.add_argument("--format", choices=FORMATS,
                   help="input format (docs/decoding.md; default: from the file name)")
    p.add_argument("--device", help="libsurvive device name (e.g. HMD)")
    p.add_argument("--board", help="board TOML: drop pulses of sensors not on it")
    p.add_argument("--sample-rate", type=float, help="raw dump sample rate in Hz (2e6)")
    p.add_argument("--period", choices=PERIODS,
                   help="rotor period: fitted to the sync train or 1/60 s (default: fit; "
                   "nominal for libsurvive recordings)")
    p.add_argument("--sync", choices=SYNCS, default="measured",
                   help="time sweeps from each measured sync flash or from the fitted train")
    _add_common_output(p)
    return p


def run_decode(args: argparse.Namespace) -> int:
    from lhgraph.model.board import load_board
    from lhgraph.signal.decode import DecodeOptions
    from lhgraph.signal.formats import (
        check_output_directory,
        decode_file,
        default_period,
        write_decoded,
    )

    check_output_directory(args.output, args.force)
    board = load_board(args.board) if args.board else None
    options = DecodeOptions(period=args.period or default_period(args.capture, args.format),
                            sync_reference=args.sync)
    result, warnings = decode_file(args.capture, args.format, args.device, board, options,
                                   args.sample_rate)
    written = write_decoded(result, args.output, overwrite=args.force)
    for line in warnings if args.quiet else [*warnings, *result.report.lines()]:
        print(f"  {line}", file=sys.stderr)  # --quiet never hides what the reader dropped
    if not args.quiet:
        print(f"{len(result.angles)} sweep hits, OOTX of station(s) "
              f"{sorted(result.calibrations) or 'none'}; wrote "
              f"{', '.join(str(p) for p in written)}")
    return 0


COMMANDS.append(("decode", add_decode, run_decode))


# --- capture ---


def add_capture(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("capture", help="record a capture with the board and download it",
                       description="Arm the photodiode board, wait for the capture and download "
                       "it as a .lhcap file (docs/protocol.md). Exit code 1 for device or link "
                       "failures, 2 for bad arguments or an existing output.")
    p.add_argument("--port", required=True, help="serial port of the board (e.g. /dev/ttyUSB0)")
    p.add_argument("--output", "-o", required=True, help=".lhcap file to write")
    p.add_argument("--duration", type=float, default=8.0, help="capture length in s (default 8)")
    p.add_argument("--delay", type=float, default=0.0, help="start delay in s (default 0)")
    p.add_argument("--baud", type=int, default=6_000_000, help="baud rate (default 6000000)")
    p.add_argument("--no-arm", action="store_true",
                   help="download the capture the board already holds; do not record")
    _add_common_output(p)
    return p


def run_capture(args: argparse.Namespace) -> int:
    from lhgraph.device.download import download_capture
    from lhgraph.device.progress import ProgressBar

    bar = None if args.quiet else ProgressBar(sys.stderr)
    try:
        result = download_capture(args.port, args.output, duration_s=args.duration,
                                  overwrite=args.force, progress=bar, baudrate=args.baud,
                                  start_delay_s=args.delay, arm=not args.no_arm)
    finally:
        if bar is not None:
            bar.close()
    if not args.quiet:
        print(result.summary())
    return 0


COMMANDS.append(("capture", add_capture, run_capture))


# --- import ---
# ``lhgraph import SOURCE ...``: one sub-subcommand per foreign recording format.


def _add_import_hive(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("hive", help="hive ROS1 bag (Vive Tracker, OOTX, IMU, OptiTrack)",
                       description="Convert a hive recording (docs/hive.md) into angles.csv, "
                       "board.toml, ootx.toml, imu.csv and mocap.csv in the output directory.")
    p.add_argument("bag", help="hive .bag file (ROS1)")
    p.add_argument("--output", "-o", required=True, help="directory to write the files into")
    _add_common_output(p)
    p.set_defaults(_import=_run_import_hive)


def _run_import_hive(args: argparse.Namespace) -> int:
    from lhgraph.importers.hive import import_hive

    result = import_hive(args.bag, args.output, overwrite=args.force)
    if not args.quiet:
        print(result.summary())
    return 0


def _add_import_crazyflie(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crazyflie", help="Crazyflie uSD log (Lighthouse deck, LH1)",
                       description="Convert a Crazyflie uSD event log (docs/crazyflie.md) into "
                       "angles.csv, board.toml, imu.csv, mocap.csv and, with --system-config, "
                       "ootx.toml and stations-cfclient.toml in the output directory.")
    p.add_argument("log", help="uSD event log (e.g. log02)")
    p.add_argument("--system-config", help="cfclient system-configuration YAML")
    p.add_argument("--mocap", help="Qualisys mocapNN.npy (default: beside logNN)")
    p.add_argument("--output", "-o", required=True, help="directory to write the files into")
    _add_common_output(p)
    p.set_defaults(_import=_run_import_crazyflie)


def _run_import_crazyflie(args: argparse.Namespace) -> int:
    from lhgraph.importers.crazyflie import import_crazyflie

    result = import_crazyflie(args.log, args.output, args.system_config, args.mocap,
                              overwrite=args.force)
    if not args.quiet:
        print(result.summary())
    return 0


def add_import(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("import", help="convert a foreign recording into lhgraph files",
                       description="Convert a recording made by other software into the "
                       "contract files (angles, board, factory calibration, ...).")
    formats = p.add_subparsers(dest="source", required=True, metavar="SOURCE")
    _add_import_hive(formats)
    _add_import_crazyflie(formats)
    return p


def run_import(args: argparse.Namespace) -> int:
    return int(args._import(args))


COMMANDS.append(("import", add_import, run_import))


# --- study ---


def add_study(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("study", help="run a simulation protocol with several methods",
                       description="Simulate every capture of a study's protocol, solve it with "
                       "each method (resumable: results kept in DIR/results/) and write the "
                       "Table III comparison and plots (docs/workflow.md).")
    p.add_argument("config", help="study TOML (e.g. configs/study_small.toml)")
    p.add_argument("--output", "-o", required=True, help="study directory")
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel processes (default 1)")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786) instead of "
                   "local processes (needs lhgraph[dask])")
    p.add_argument("--force", action="store_true",
                   help="rerun every capture even when its result is stored")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    return p


def run_study(args: argparse.Namespace) -> int:
    from lhgraph.workflow.study import load_study_config
    from lhgraph.workflow.study import run_study as study

    progress = None if args.quiet else (lambda msg: print(f"  {msg}", file=sys.stderr))
    result = study(load_study_config(args.config), args.output, args.jobs, args.scheduler,
                   rerun=args.force, progress=progress)
    if not args.quiet:
        print(next(f for f in result.files if f.name == "study.md").read_text())
        print(f"ran {result.ran}, reused {result.skipped}; wrote "
              f"{', '.join(str(f) for f in result.files)}")
    return 0


COMMANDS.append(("study", add_study, run_study))


# --- view ---


def add_view(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("view", help="3-D view of a run directory (Open3D)",
                       description="Show a run directory's stations (with sweep frusta), board "
                       "path and diodes in an Open3D window, or --export the scene without a "
                       "display (docs/workflow.md).")
    p.add_argument("run_dir", help="run directory (or one method's subdirectory)")
    p.add_argument("--export", help="write FILE.png, .ply, .glb, .gltf or .obj instead")
    p.add_argument("--renderer", choices=RENDERERS, default="auto",
                   help="PNG renderer (default: Open3D offscreen, else matplotlib)")
    _add_common_output(p)
    return p


def run_view(args: argparse.Namespace) -> int:
    from lhgraph.report.viewer import build_scene, export, show

    scene = build_scene(args.run_dir)
    if args.export:
        path, how = export(scene, args.export, args.force, args.renderer)
        if not args.quiet:
            print(f"wrote {path} ({how})")
    else:
        show(scene)
    return 0


COMMANDS.append(("view", add_view, run_view))


# --- export --- (``lhgraph export TARGET ...``: one sub-subcommand per foreign format)


def add_export(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from lhgraph.choices import EXPORT_FRAMES, EXPORT_IMU_SAMPLES, EXPORT_UP

    export = sub.add_parser("export", help="write the stations for other software")
    targets = export.add_subparsers(dest="target", required=True, metavar="TARGET")
    p = targets.add_parser("cfclient", help="Bitcraze cfclient's system-config.yaml",
                           description="Write the stations and their factory calibration "
                           "as cfclient's system configuration, z up from gravity, origin and "
                           "x chosen by name (docs/export.md).")
    p.add_argument("stations", help="stations TOML (LH1)")
    p.add_argument("--output", "-o", required=True, help="system-config.yaml to write")
    p.add_argument("--calibration", help="factory calibration (ootx.toml) of the stations")
    p.add_argument("--imu", help="the receiver's imu.csv (board frame, SI units)")
    p.add_argument("--trajectory", help="the receiver's trajectory CSV, stations' world")
    for flag, choices in (("--up", EXPORT_UP), ("--imu-samples", EXPORT_IMU_SAMPLES),
                          ("--origin", EXPORT_FRAMES), ("--x", EXPORT_FRAMES)):
        p.add_argument(flag, choices=choices, default="auto", help="docs/export.md")
    p.add_argument("--at", type=float, metavar="S", help="time of the receiver-start pose")
    _add_common_output(p)
    p.set_defaults(_export=_run_export_cfclient)
    return export


def _run_export_cfclient(args: argparse.Namespace) -> int:
    from lhgraph.config import override
    from lhgraph.estimation.world_alignment import WorldOptions
    from lhgraph.workflow.export import export_cfclient

    options = override(WorldOptions(), {f"--{name.replace('_', '-')}": (name, getattr(args, name))
                                        for name in ("up", "origin", "x", "imu_samples")}
                       | {"--at": ("at_s", args.at)})
    result = export_cfclient(args.stations, args.output, calibration=args.calibration,
                             imu=args.imu, trajectory=args.trajectory, options=options,
                             overwrite=args.force)
    for warning in result.warnings:
        print(f"lhgraph export: warning: {warning}", file=sys.stderr)
    if not args.quiet:
        print(result.summary())
    return 0


def run_export(args: argparse.Namespace) -> int:
    return int(args._export(args))


COMMANDS.append(("export", add_export, run_export))


# --- track ---


def add_track(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("track", help="the receiver's path with the stations held fixed",
                       description="Track the board through its angles with every station held "
                       "at its pose in the stations TOML; write the trajectory CSV "
                       "(docs/track.md).")
    for flag, what in (("--stations", "stations TOML (held fixed)"), ("--angles", "angles CSV"),
                       ("--board", "board TOML or built-in name (e.g. crazyflie_deck)"),
                       ("--output", "trajectory CSV to write")):
        p.add_argument(flag, required=True, help=what)
    p.add_argument("--calibration", help="factory calibration (ootx.toml) of the stations")
    p.add_argument("--streaming", action="store_true", help="one sync cycle at a time")
    p.add_argument("--delay", type=float, metavar="S",
                   help="streaming: report each state S seconds after it (docs/track.md)")
    _add_common_output(p)
    return p


def run_track(args: argparse.Namespace) -> int:
    from lhgraph.workflow.track import track_files

    progress = None if args.quiet else (lambda msg: print(f"  {msg}", file=sys.stderr))
    out = track_files(args.board, args.angles, args.stations, args.output, args.calibration,
                      args.streaming, args.force, progress=progress, delay_s=args.delay)
    if not args.quiet:
        print(out.summary())
    return 0


COMMANDS.append(("track", add_track, run_track))


def build_parser() -> argparse.ArgumentParser:
    """The ``lhgraph`` argument parser with every registered command."""
    parser = argparse.ArgumentParser(
        prog="lhgraph",
        description="Calibrate Lighthouse v1 base-station poses from a photodiode-board capture.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for _name, add, run in COMMANDS:
        p = add(sub)
        p.set_defaults(_run=run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lhgraph`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except LhgraphError as exc:
        print(f"lhgraph {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"lhgraph {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
