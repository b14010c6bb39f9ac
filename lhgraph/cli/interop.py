"""Commands that exchange files with other tools: ``import``, ``export``."""

from __future__ import annotations

import argparse
import sys

from lhgraph.cli.common import COMMANDS, add_common_output, mark_inputs

# --- import ---
# ``lhgraph import SOURCE ...``: one sub-subcommand per foreign recording format.


def _add_import_hive(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("hive", help="hive ROS1 bag (Vive Tracker, OOTX, IMU, OptiTrack)",
                       description="Convert a hive recording (docs/hive.md) into angles.csv, "
                       "board.toml, ootx.toml, imu.csv and mocap.csv in the output directory.")
    p.add_argument("bag", help="hive .bag file (ROS1)")
    p.add_argument("--output", "-o", required=True, help="directory to write the files into")
    p.add_argument("--keep-sync-offsets", action="store_true",
                   help="write the angles as hive gives them, without raising the sweeps "
                   "that read one sync-bit length low (docs/hive.md)")
    add_common_output(p)
    mark_inputs(p, "bag")
    p.set_defaults(_import=_run_import_hive)


def _run_import_hive(args: argparse.Namespace) -> int:
    from lhgraph.importers.hive import import_hive

    result = import_hive(args.bag, args.output, overwrite=args.force,
                         sync_bits=not args.keep_sync_offsets)
    if not args.quiet:
        print(result.summary())
    else:  # what a damaged bag lost is said even when quiet
        for note in result.notes:
            print(f"{args.bag}: {note}", file=sys.stderr)
    return 0


def _add_import_crazyflie(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crazyflie", help="Crazyflie uSD log (Lighthouse deck, LH1 or LH2)",
                       description="Convert a Crazyflie uSD event log (docs/crazyflie.md) into "
                       "angles.csv, board.toml, imu.csv, mocap.csv and, with --system-config, "
                       "ootx.toml and stations-cfclient.toml in the output directory.")
    p.add_argument("log", help="uSD event log (e.g. log02)")
    p.add_argument("--system-config", help="cfclient system-configuration YAML")
    p.add_argument("--mocap", help="Qualisys mocapNN.npy (default: beside logNN)")
    p.add_argument("--output", "-o", required=True, help="directory to write the files into")
    add_common_output(p)
    mark_inputs(p, "log", "system_config", "mocap")
    p.set_defaults(_import=_run_import_crazyflie)


def _run_import_crazyflie(args: argparse.Namespace) -> int:
    from lhgraph.importers.crazyflie import import_crazyflie

    result = import_crazyflie(args.log, args.output, args.system_config, args.mocap,
                              overwrite=args.force)
    if not args.quiet:
        print(result.summary())
    else:  # what a damaged log lost is said even when quiet
        for note in result.notes:
            print(f"{args.log}: {note}", file=sys.stderr)
    return 0


def _add_import_libsurvive(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("libsurvive", help="libsurvive's config.json (station poses, OOTX)",
                       description="Convert libsurvive's config.json (docs/interop.md) into "
                       "stations.toml (libsurvive's world, our station frame, its variances "
                       "as covariances) and, when it holds factory calibration, ootx.toml in "
                       "the output directory.")
    p.add_argument("config", help="libsurvive config.json")
    p.add_argument("--output", "-o", required=True, help="directory to write the files into")
    add_common_output(p)
    mark_inputs(p, "config")
    p.set_defaults(_import=_run_import_libsurvive)


def _run_import_libsurvive(args: argparse.Namespace) -> int:
    from lhgraph.importers.libsurvive import import_libsurvive

    result = import_libsurvive(args.config, args.output, overwrite=args.force)
    if not args.quiet:
        print(result.summary())
    else:  # what the file left out is said even when quiet
        for note in result.config.notes:
            print(f"{args.config}: {note}", file=sys.stderr)
    return 0


def add_import(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("import", help="convert a foreign recording into lhgraph files",
                       description="Convert a recording made by other software into the "
                       "contract files (angles, board, factory calibration, ...).")
    formats = p.add_subparsers(dest="source", required=True, metavar="SOURCE")
    _add_import_hive(formats)
    _add_import_crazyflie(formats)
    _add_import_libsurvive(formats)
    return p


def run_import(args: argparse.Namespace) -> int:
    return int(args._import(args))


COMMANDS.append(("import", add_import, run_import))


# --- export --- (``lhgraph export TARGET ...``: one sub-subcommand per foreign format)


def add_export(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from lhgraph.choices import EXPORT_FRAMES, EXPORT_IMU_SAMPLES, EXPORT_UP

    export = sub.add_parser("export", help="write the stations for other software")
    targets = export.add_subparsers(dest="target", required=True, metavar="TARGET")
    for name, help_text, description, output in (
            ("cfclient", "Bitcraze cfclient's system-config.yaml",
             "Write the stations (LH1 or LH2) and their factory calibration as cfclient's "
             "system configuration, z up from gravity, origin and x chosen by name "
             "(docs/export.md).", "system-config.yaml"),
            ("libsurvive", "libsurvive's config.json",
             "Write the stations (LH1 or LH2), their covariance and factory calibration as "
             "libsurvive's config.json, z up from gravity, origin and x chosen by name "
             "(docs/interop.md, docs/export.md).", "config.json")):
        p = targets.add_parser(name, help=help_text, description=description)
        _add_export_arguments(p, output, EXPORT_UP, EXPORT_IMU_SAMPLES, EXPORT_FRAMES)
        p.set_defaults(_export=_run_export, _target=name)
    return export


def _add_export_arguments(p: argparse.ArgumentParser, output: str, up: tuple[str, ...],
                          imu_samples: tuple[str, ...], frames: tuple[str, ...]) -> None:
    """The arguments both export targets take (docs/export.md)."""
    p.add_argument("stations", help="stations TOML (LH1 or LH2: the file's system from the "
                   "stations' generation)")
    p.add_argument("--output", "-o", required=True, help=f"{output} to write")
    p.add_argument("--calibration", help="factory calibration (ootx.toml) of the stations")
    p.add_argument("--imu", help="the receiver's imu.csv (board frame, SI units)")
    p.add_argument("--trajectory", help="the receiver's trajectory CSV, stations' world")
    for flag, choices in (("--up", up), ("--imu-samples", imu_samples),
                          ("--origin", frames), ("--x", frames)):
        p.add_argument(flag, choices=choices, default="auto", help="docs/export.md")
    p.add_argument("--at", type=float, metavar="S", help="time of the receiver-start pose")
    p.add_argument("--force-unverified", action="store_true",
                   help="export a result whose verdict failed (e.g. an unconverged solve)")
    add_common_output(p)
    mark_inputs(p, "stations", "calibration", "imu", "trajectory")


def _run_export(args: argparse.Namespace) -> int:
    from lhgraph.config import override
    from lhgraph.estimation.world_alignment import WorldOptions
    from lhgraph.workflow.export import export_cfclient, export_libsurvive

    options = override(WorldOptions(), {f"--{name.replace('_', '-')}": (name, getattr(args, name))
                                        for name in ("up", "origin", "x", "imu_samples")}
                       | {"--at": ("at_s", args.at)})
    export = export_cfclient if args._target == "cfclient" else export_libsurvive
    result = export(args.stations, args.output, calibration=args.calibration,
                    imu=args.imu, trajectory=args.trajectory, options=options,
                    overwrite=args.force, unverified=args.force_unverified)
    for warning in result.warnings:
        print(f"lhgraph export: warning: {warning}", file=sys.stderr)
    if not args.quiet:
        print(result.summary())
    return 0


def run_export(args: argparse.Namespace) -> int:
    return int(args._export(args))


COMMANDS.append(("export", add_export, run_export))
