"""Commands that make and calibrate captures: ``simulate``, ``solve``, ``study``."""

from __future__ import annotations

import argparse
import sys

from lhgraph.cli.common import (
    COMMANDS,
    add_common_output,
    add_verbose,
    at_least,
    mark_inputs,
    print_verdict,
    progress_printer,
    verdict_exit,
)

# --- simulate ---


def add_simulate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("simulate", help="simulate a capture with known truth",
                       description="Simulate a capture of a waved board (docs/simulator.md) and "
                       "write angles.csv, board.toml, truth.toml and trajectory.csv.")
    p.add_argument("config", nargs="?", help="simulation TOML (default: the bundled default)")
    p.add_argument("--output", "-o", required=True, help="output directory")
    p.add_argument("--seed", type=at_least(0, int),
                   help="random seed >= 0 (overrides the config's seed)")
    p.add_argument("--capture", action="store_true",
                   help="also write the raw signal a board would record (capture.lhcap)")
    add_common_output(p)
    mark_inputs(p, "config")
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
    p.add_argument("--angles", action="append",
                   help="angles CSV; repeated: several captures of the same stations solved "
                   "jointly, one board path each (docs/solve.md)")
    p.add_argument("--prior", help="an earlier stations TOML: its poses and covariances as "
                   "priors on the stations (docs/solve.md)")
    p.add_argument("--output", "-o", help="stations TOML to write (with a CONFIG: a path "
                   "without .toml or an existing directory = a run directory, docs/workflow.md)")
    p.add_argument("--method", choices=METHODS, help="default: graph")
    p.add_argument("--trajectory", help="also write the board trajectory CSV")
    p.add_argument("--board-output", metavar="BOARD.toml",
                   help="also solve for the board's sensor positions (graph method) and write "
                   "the board with them (docs/solve.md)")
    p.add_argument("--calibration", help="factory calibration (ootx.toml) of the stations")
    p.add_argument("--factory-terms", metavar="TERMS",
                   help="graph method: also solve these factory terms of every station, "
                   "comma-separated (e.g. tilt,gibmag), prior centred on the calibration's "
                   "values (graph option factory_terms; docs/self_calibration.md)")
    p.add_argument("--truth", help="true stations TOML: print the errors")
    p.add_argument("--reference", type=int,
                   help="station index of the world frame (default: the lowest index seen)")
    p.add_argument("--duration", type=float, metavar="S",
                   help="solve only the first S seconds in which the board moves")
    p.add_argument("--world", choices=WORLDS,
                   help="world frame: the reference station's (default) or gravity-aligned, "
                   "z up from the stations' OOTX accelerometer vectors")
    p.add_argument("--imu", help="the receiver's imu.csv (board frame, the angles' clock): "
                   "refine the graph's solution with IMU factors (docs/solve.md)")
    p.add_argument("--resume", action="store_true",
                   help="run directory: keep the methods that finished before with the same "
                   "inputs and options, compute the rest")
    add_common_output(p)
    add_verbose(p)
    mark_inputs(p, "config", "board", "angles", "calibration", "truth", "imu", "prior")
    return p


def run_solve(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from lhgraph.config import override
    from lhgraph.errors import InputError
    from lhgraph.report.text import format_comparison, print_solution
    from lhgraph.workflow.inputs import calibration_beside
    from lhgraph.workflow.rundir import (
        comparison_rows,
        is_run_directory,
        run_to_directory,
        run_verdict,
    )
    from lhgraph.workflow.solve import solve_to_files
    from lhgraph.workflow.solve_config import SolveConfig, load_solve_config

    flags = {f"--{name}": (name, getattr(args, name))
             for name in ("output", "method", "trajectory", "calibration", "truth", "reference",
                          "world", "imu", "prior")}
    flags["--duration"] = ("duration_s", args.duration)
    flags["--board-output"] = ("board_output", args.board_output)
    if args.config:
        config = load_solve_config(args.config)
    else:
        missing = [o for o in ("board", "angles", "output") if getattr(args, o) is None]
        if missing:
            raise InputError("give a CONFIG.toml or all of --board, --angles, --output "
                             f"(missing: {', '.join('--' + m for m in missing)})")
        config = SolveConfig(board=Path(args.board))
    if args.angles:
        flags["--angles"] = ("angles", args.angles[0])
        config = replace(config, more_angles=tuple(Path(a) for a in args.angles[1:]))
    config = override(config, flags)
    if args.factory_terms is not None:
        try:
            config = replace(config, graph=config.graph.with_values(
                factory_terms=args.factory_terms))
        except InputError as err:
            raise InputError(err.problem, where="--factory-terms") from None
    if args.method is not None:
        config = replace(config, methods=None)
    if config.output is None:
        raise InputError("no output: give --output or set 'output' in the config")
    calibration, note = calibration_beside(config.angles, config.calibration)
    config = replace(config, calibration=calibration)
    if note and not args.quiet:
        print(f"lhgraph solve: {note}", file=sys.stderr)
    progress = progress_printer(args)
    if args.config and is_run_directory(config.output):
        shown = None if args.quiet else (lambda r: print_solution(r.result, r.errors,
                                                                    flush=True))
        run = run_to_directory(config, config.output, args.force, progress, args.resume,
                               shown)
        if not args.quiet and len(run.runs) > 1:
            print(format_comparison(comparison_rows(run.runs)))
        verdicts = {r.method: run_verdict(r.summary) for r in run.runs}
        for method, v in verdicts.items():
            print_verdict(args, v, method if len(verdicts) > 1 else "")
        if not args.quiet:
            print(f"wrote {len(run.files)} files to {run.directory}; report: {run.report}")
        return verdict_exit(verdicts.values())
    if args.resume:
        raise InputError("--resume is for a run directory output (a CONFIG and an output "
                         "without .toml)", config.output)
    result, errors, written, verdict = solve_to_files(config, args.force, progress)
    if not args.quiet:
        print_solution(result, errors)
    print_verdict(args, verdict)
    if not args.quiet:
        print(f"wrote {', '.join(str(p) for p in written)}")
    return verdict_exit([verdict])


COMMANDS.append(("solve", add_solve, run_solve))


# --- study ---


def add_study(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("study", help="run a simulation protocol with several methods",
                       description="Simulate every capture of a study's protocol, solve it with "
                       "each method (resumable: results kept in DIR/results/) and write the "
                       "Table III comparison and plots (docs/workflow.md).")
    p.add_argument("config", help="study TOML (e.g. configs/study_small.toml)")
    p.add_argument("--output", "-o", required=True, help="study directory")
    p.add_argument("--jobs", "-j", type=at_least(1, int), default=1,
                   help="parallel processes")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786) instead of "
                   "local processes (needs lhgraph[dask])")
    p.add_argument("--force", action="store_true",
                   help="rerun every capture even when its result is stored")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    mark_inputs(p, "config")
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
