"""The paper pipeline end to end: :func:`solve_paper` (every station against the reference)
and the per-hit residuals of its solution (:func:`hit_residuals`)."""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from lhgraph.errors import SolverError
from lhgraph.estimation.baseline.board_poses import (
    BoardPoses,
    estimate_board_poses,
    reject_outlier_poses,
)
from lhgraph.estimation.baseline.options import PaperOptions, Progress
from lhgraph.estimation.baseline.station_pose import initial_station_pose, refine_station_pose
from lhgraph.estimation.reconstruct import Measurements, reconstruct_measurements, to_ideal
from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Station, Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.station import IDEAL, StationModel, predict


def hit_residuals(angles: Angles, board: Board, stations: Stations, trajectory: Trajectory
                  ) -> Residuals:
    """Per-hit residuals (measured - predicted, rad; weight 1) of a solution.

    Each hit is predicted from the board pose interpolated at its time (clamped at the
    ends) and its station's pose and model (factory calibration included).
    """
    idx = angles.check_board(board)
    T_board = trajectory.at(angles.time)
    pred = np.empty(len(angles))
    for k in stations.indices():
        sel = angles.lighthouse == k
        st = stations.stations[k]
        pred[sel] = predict(st.T_world_lh, T_board[sel], board.positions[idx[sel]],
                            angles.axis[sel], st.model)
    return Residuals(angles.time.copy(), angles.lighthouse.copy(), angles.axis.copy(),
                     angles.sensor.copy(), angles.angle - pred, np.ones(len(angles)))


@dataclass(frozen=True)
class _StationData:
    """One station: the measurements K2 uses (rejected fits removed), its board poses."""

    meas: Measurements
    poses: BoardPoses
    model: StationModel = field(default_factory=StationModel)


def solve_paper(board: Board, angles: Angles, models: dict[int, StationModel] | None = None,
                reference: int | None = None, options: PaperOptions | None = None,
                progress: Progress | None = None) -> SolveResult:
    """Calibrate every station against the reference one with the paper's method.

    ``models`` (station index -> :class:`StationModel`) gives factory calibrations: measured
    angles are converted to ideal ones before the pipeline. ``reference`` defaults to the
    lowest station index present. Returns a :class:`SolveResult` with the stations in the
    reference frame (covariance None), the reference board path as trajectory, per-hit
    residuals, ``final_error`` = sum of the final K2 (rad^2) and ``iterations`` = sum of the
    K2 Nelder-Mead iterations. Raises :class:`InputError` for sensor ids not on the board and
    :class:`SolverError` when the data cannot determine the poses.
    """
    options = options or PaperOptions()
    models = models or {}
    timings: dict[str, float] = {}
    present = angles.stations()
    if reference is None:
        if not present:
            raise SolverError("the angles table is empty")
        reference = present[0]
    if reference not in present:
        raise SolverError(f"reference station {reference} never seen in the angles "
                          f"(stations present: {present})")
    if len(present) < 2:
        raise SolverError(f"only station {reference} seen: need at least two stations")
    angles.check_board(board)

    data: dict[int, _StationData] = {}
    for k in present:
        tic = _time.perf_counter()
        model = models.get(k, IDEAL)
        meas = to_ideal(reconstruct_measurements(
            angles.select(angles.lighthouse == k), board, options.reconstruction,
            max_gap_periods=options.max_gap_periods), model)
        timings["reconstruct"] = timings.get("reconstruct", 0.0) + _time.perf_counter() - tic
        tic = _time.perf_counter()
        fitted = estimate_board_poses(meas, board, options, progress)
        poses = reject_outlier_poses(fitted, options.outlier_mads)
        timings["board_poses"] = timings.get("board_poses", 0.0) + _time.perf_counter() - tic
        rejected = fitted.valid & ~poses.valid
        meas = meas.select(~rejected)
        if poses.valid.sum() < options.min_measurements:
            raise SolverError(
                f"station {k}: only {int(poses.valid.sum())} usable measurements (need >= "
                f"{options.min_measurements} with >= {options.min_sensors} sensors each)")
        data[k] = _StationData(meas, poses, model)

    master = data[reference].poses
    trajectory = master.path()
    result_stations = {reference: Station(np.eye(4), None, data[reference].model)}
    status, iterations, final_error = "converged", 0, 0.0
    warnings: list[str] = []
    slaves = [k for k in present if k != reference]
    for n, k in enumerate(slaves):
        if progress is not None:
            progress("station poses", n, len(slaves))
        tic = _time.perf_counter()
        T = initial_station_pose(master, data[k].poses, board, options)
        timings["kabsch"] = timings.get("kabsch", 0.0) + _time.perf_counter() - tic
        if options.refine:
            tic = _time.perf_counter()
            ref = refine_station_pose(T, data[k].meas, trajectory, board, options)
            timings["refine"] = timings.get("refine", 0.0) + _time.perf_counter() - tic
            T, iterations, final_error = ref.T_ref_lh, iterations + ref.iterations, \
                final_error + ref.cost
            if not ref.converged:
                status = "max_iterations"
                warnings.append(f"station {k}: K2 refinement stopped at {ref.evaluations} "
                                f"evaluations before converging")
        result_stations[k] = Station(T, None, data[k].model)
    if progress is not None:
        progress("station poses", len(slaves), len(slaves))
    stations = Stations(reference, result_stations)
    tic = _time.perf_counter()
    residuals = hit_residuals(angles, board, stations, trajectory)
    timings["residuals"] = _time.perf_counter() - tic
    if not options.refine:
        final_error = float("nan")
    return SolveResult("paper", stations, trajectory, residuals, status, iterations,
                       final_error, timings, warnings)
