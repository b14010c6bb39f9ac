"""One entry point for every calibration method.

``solve(board, angles, method=...)`` dispatches to the factor graph (``"graph"``, default)
or the paper's pipeline (``"paper"``); :func:`run_config` solves what a
:class:`~lhgraph.workflow.solve_config.SolveConfig` names and :func:`solve_to_files` writes
the result as a stations TOML (and trajectory CSV). The configuration file is read by
:mod:`lhgraph.workflow.solve_config`, its input files by :mod:`lhgraph.workflow.inputs`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from lhgraph.choices import METHODS
from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.gravity import imu_up, to_gravity_world, up_angle_deg
from lhgraph.estimation.metrics import PoseError, station_errors
from lhgraph.estimation.result import SolveResult
from lhgraph.estimation.station_prior import StationPriors
from lhgraph.io.angles import Angles
from lhgraph.io.files import check_writable
from lhgraph.io.imu import ImuStream
from lhgraph.io.stations import Stations, load_stations, save_stations
from lhgraph.io.trajectory import save_trajectory
from lhgraph.model.board import Board, save_board
from lhgraph.model.station import StationModel
from lhgraph.report.assessment import Verdict, result_verdict
from lhgraph.workflow.inputs import SolveInputs, check_inputs, load_inputs
from lhgraph.workflow.solve_config import SolveConfig

if TYPE_CHECKING:
    from lhgraph.estimation.baseline import PaperOptions


def solve(board: Board, angles: Angles, method: str = "graph",
          models: dict[int, StationModel] | None = None, reference: int | None = None,
          graph_options: GraphOptions | None = None,
          progress: Callable[[str], None] | None = None,
          paper_options: PaperOptions | None = None,
          world_up: dict[int, NDArray[np.float64]] | None = None,
          imu: ImuStream | None = None, prior: StationPriors | None = None) -> SolveResult:
    """Calibrate the stations seen in ``angles`` with ``method`` ("graph" or "paper").

    ``prior``: an earlier result as a prior on the stations (the graph only: InputError for
    the paper's method; :func:`lhgraph.estimation.station_prior.station_priors`).

    ``imu``: the receiver's IMU stream, for the graph's IMU refinement (the paper's method
    has no use for it: InputError). The paper's method is for LH1 stations, as the paper's
    own (LH2 stations in ``models``: InputError; on a simulated two-station LH2 capture it
    returned station 1 6.6 m off with only a warning).

    The world is the reference station's frame, or with ``world_up`` (station index -> up
    vector in the station frame, :func:`lhgraph.estimation.gravity.up_vectors`) gravity-aligned:
    by the receiver's IMU when the solve has one (``imu``; then ``world_up`` may be empty,
    and where it is not, ``diagnostics["imu_ootx_up_deg"]`` is the angle between the two
    ups), else by the stations' OOTX vectors.
    ``reference`` overrides ``graph_options.data.reference`` (the caller's options are not changed).
    """
    angles.check_board(board)
    if method == "graph":
        options = graph_options or GraphOptions()
        if reference is not None:
            options = options.with_values(reference=reference)
        result = solve_graph(board, angles, models, options, progress, imu=imu, prior=prior)
    elif method == "paper":
        if prior is not None:
            raise InputError("the paper's method takes no prior: drop 'prior' (--prior) or "
                             "solve with the graph", where="prior")
        if imu is not None:
            raise InputError("the paper's method does not use an IMU: drop 'imu' (--imu) or "
                             "solve with the graph", where="imu")
        lh2 = sorted(k for k, m in (models or {}).items() if m.generation == 2)
        if lh2:
            raise InputError(f"the paper's method is for LH1 stations; station(s) {lh2} are "
                             "LH2 (SteamVR 2.0): solve with the graph", where="method")
        from lhgraph.estimation.baseline import solve_paper

        staged = None if progress is None else (
            lambda stage, done, total: progress(f"{stage}: {done}/{total}"))
        result = solve_paper(board, angles, models, reference, paper_options, staged)
    else:
        raise InputError(f"unknown method '{method}' (expected one of {', '.join(METHODS)})",
                         where="--method")
    if world_up is None:
        return result
    if result.gravity_world is None:
        return to_gravity_world(result, world_up)
    # the receiver's IMU observed up during the capture: it sets the world, and the
    # stations' OOTX vectors (when any) are compared with it
    up = imu_up(result)
    compared = ({"imu_ootx_up_deg": up_angle_deg(result.stations, up, world_up)}
                if world_up else {})
    aligned = to_gravity_world(result, up)
    return dataclasses.replace(aligned, diagnostics={**aligned.diagnostics, **compared})


def with_verdict(stations: Stations, verdict: Verdict) -> Stations:
    """``stations`` with the result's ``verdict`` table (:meth:`Verdict.as_dict`, written
    into the stations TOML, docs/formats.md; ``lhgraph export`` refuses a failed one)."""
    return dataclasses.replace(stations, extra={**stations.extra, "verdict": verdict.as_dict()})


def write_solution(result: SolveResult, output: str | Path, trajectory: str | Path | None,
                   overwrite: bool, verdict: Verdict | None = None) -> list[Path]:
    """Write the stations TOML (with ``verdict`` when given) and the board trajectory CSV
    when asked."""
    stations = result.stations if verdict is None else with_verdict(result.stations, verdict)
    written = [save_stations(stations, output, overwrite)]
    if trajectory is not None and result.trajectory is not None:
        written.append(save_trajectory(result.trajectory, trajectory, overwrite))
    return written


def run_config(config: SolveConfig, progress: Callable[[str], None] | None = None,
               inputs: SolveInputs | None = None, method: str | None = None) -> SolveResult:
    """Solve with ``method`` (default: the config's first), the inputs the config names
    loaded unless given; the result's ``captures`` start with the joined captures' lines."""
    inputs = inputs or load_inputs(config)
    result = solve(inputs.board, inputs.angles, method or config.method_list()[0],
                   inputs.models, config.reference, config.graph_options(), progress,
                   world_up=inputs.world_up, imu=inputs.imu, prior=inputs.prior)
    if not inputs.captures:
        return result
    return dataclasses.replace(result, captures=inputs.captures + result.captures)


def solve_to_files(config: SolveConfig, overwrite: bool = False,
                   progress: Callable[[str], None] | None = None
                   ) -> tuple[SolveResult, list[PoseError] | None, list[Path], Verdict]:
    """Solve a one-method config into its ``output`` stations TOML (and ``trajectory``).

    Inputs and output targets are checked before solving (InputError, nothing written).
    Returns the result, its errors against ``truth`` (when given), the files written and the
    result's verdict (:func:`lhgraph.report.assessment.result_verdict`, also written into the
    stations TOML).
    """
    if config.output is None:
        raise InputError("no output: give --output or set 'output' in the config")
    if len(config.method_list()) > 1:
        raise InputError("several methods need a run directory output (a path without "
                         ".toml)", config.output)
    if config.board_output is not None and config.method_list()[0] != "graph":
        raise InputError("the sensor positions are solved by the graph method only",
                         config.path, "board_output")
    if config.graph.factory.terms and config.method_list()[0] != "graph":
        raise InputError("the factory terms are solved by the graph method only",
                         config.path, "factory_terms")
    check_inputs(config)
    targets = [Path(t) for t in (config.output, config.trajectory, config.board_output)
               if t is not None]
    if len({t.resolve() for t in targets}) < len(targets):
        raise InputError("output, trajectory and board output must be different files",
                         config.output)
    for target in targets:
        check_writable(target, overwrite, create_parents=False)
    truth = load_stations(config.truth) if config.truth else None
    inputs = load_inputs(config)
    result = run_config(config, progress, inputs)
    verdict = result_verdict(result, inputs.angles)
    written = write_solution(result, config.output, config.trajectory, overwrite, verdict)
    if config.board_output is not None:
        board = result.corrected_board(inputs.board)
        written.append(save_board(board, config.board_output, overwrite))
    errors = station_errors(truth, result.stations) if truth else None
    return result, errors, written, verdict
