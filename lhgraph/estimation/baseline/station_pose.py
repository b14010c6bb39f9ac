"""Paper steps 3-5: a station's board path interpolated to the reference's timestamps
(:func:`interpolate_path`), the weighted Kabsch superposition of the two paths
(:func:`initial_station_pose`) and the K2 refinement of the station pose
(:func:`refine_station_pose`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import OptimizeResult, minimize

from lhgraph.errors import SolverError
from lhgraph.estimation.baseline.board_poses import BoardPoses, outliers, typical_spacing
from lhgraph.estimation.baseline.cost import angle_cost, angle_errors, rotation, start_simplex
from lhgraph.estimation.baseline.options import PaperOptions
from lhgraph.estimation.reconstruct import Measurements
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import interpolate_poses, make_pose, transform_points
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board

Array = NDArray[np.float64]


def _bracketed(times: Array, query: Array, max_gap_s: float) -> NDArray[np.bool_]:
    """Where ``query`` lies inside sorted ``times``, between samples <= ``max_gap_s`` apart."""
    if len(times) < 2:
        return np.zeros(len(query), dtype=bool)
    i = np.clip(np.searchsorted(times, query, side="right"), 1, len(times) - 1)
    inside = (query >= times[0]) & (query <= times[-1])
    return inside & (times[i] - times[i - 1] <= max_gap_s)


def interpolate_path(poses: BoardPoses, query: ArrayLike, max_gap_s: float | None = None
                     ) -> tuple[Array, Array, NDArray[np.bool_]]:
    """A station's board path at ``query`` times (paper step 3).

    Rotation slerp and linear position between the valid poses around each query time.
    Returns ``(T_lh_board (Q, 4, 4), mean squared residual (Q,) rad^2 interpolated likewise,
    ok (Q,))``; ``ok`` is False outside the path or where its poses are more than
    ``max_gap_s`` apart (default ``max_gap_periods`` x the typical spacing; those rows are
    clamped values, not to be used).
    """
    q = np.asarray(query, dtype=float)
    t = poses.time[poses.valid]
    if max_gap_s is None:
        max_gap_s = PaperOptions().max_gap_periods * typical_spacing(t)
    if len(t) == 0:
        return np.full((len(q), 4, 4), np.nan), np.full(len(q), np.nan), np.zeros(len(q), bool)
    T = interpolate_poses(t, poses.T_lh_board[poses.valid], q)
    ms = np.interp(q, t, poses.mean_square()[poses.valid])
    return T, ms, _bracketed(t, q, max_gap_s)


def initial_station_pose(master: BoardPoses, slave: BoardPoses, board: Board,
                         options: PaperOptions | None = None) -> Array:
    """Initial ``T_ref_slave`` by weighted Kabsch superposition of the two board paths.

    The slave path (``T_slave_board``) is interpolated to the master's valid timestamps
    (``T_ref_board``) and superposed onto it (paper steps 3-4); see :class:`PaperOptions`
    for the points superposed and the weights. Raises :class:`SolverError` when fewer than
    ``options.min_measurements`` timestamps overlap.
    """
    options = options or PaperOptions()
    t = master.time[master.valid]
    max_gap = options.max_gap_periods * typical_spacing(slave.time[slave.valid])
    T_slave, ms_slave, ok = interpolate_path(slave, t, max_gap)
    if ok.sum() < options.min_measurements:
        raise SolverError(f"station {slave.lighthouse}: only {int(ok.sum())} board poses overlap "
                          f"in time with station {master.lighthouse}'s "
                          f"(need >= {options.min_measurements})")
    T_master = master.T_lh_board[master.valid][ok]
    e = master.mean_square()[master.valid][ok] + ms_slave[ok]
    w = 1.0 / (options.weight_floor * np.median(e) + e + 1e-300)
    if options.kabsch_points == "board":
        c = board.positions.mean(axis=0)
        src, dst = transform_points(T_slave[ok], c), transform_points(T_master, c)
    else:
        s = board.positions[None]
        src = transform_points(T_slave[ok][:, None], s).reshape(-1, 3)
        dst = transform_points(T_master[:, None], s).reshape(-1, 3)
        w = np.repeat(w, len(board.positions))
    return weighted_kabsch(src, dst, w)


@dataclass(frozen=True)
class Refinement:
    """Result of the K2 refinement of one station: pose, K2 (rad^2) over the measurements
    kept, K2 calls and iterations summed over the fits, convergence of the last fit, the
    measurements overlapping the reference path and how many of them were rejected."""

    T_ref_lh: Array
    cost: float
    evaluations: int
    iterations: int
    converged: bool
    n_measurements: int
    n_rejected: int = 0


MAX_K2_FITS = 3
"""K2 fits at most: all measurements, then refits without the outliers until they repeat."""


def _minimise_station(world: Array, measured: Array, T0: Array, options: PaperOptions
                      ) -> tuple[Array, OptimizeResult]:
    """Nelder-Mead on K2 around ``T0`` (``R = Exp(omega) R0``, ``t = t0 + v``): the pose
    ``T_ref_lh`` seeing the reference-frame points ``world`` (n, 3) at ``measured`` (n, 2)."""
    R0, t0 = T0[:3, :3], T0[:3, 3]

    def k2(x: Array) -> float:
        return angle_cost((world - (t0 + x[3:])) @ (rotation(x[:3]) @ R0), measured)

    res = minimize(k2, np.zeros(6), method="Nelder-Mead", options={
        "xatol": options.refine_xatol, "fatol": options.refine_fatol,
        "maxfev": options.refine_maxfev, "initial_simplex": start_simplex(0.01, 0.01)})
    return make_pose(rotation(res.x[:3]) @ R0, t0 + res.x[3:]), res


def refine_station_pose(T_ref_lh: ArrayLike, meas: Measurements, trajectory: Trajectory,
                        board: Board, options: PaperOptions | None = None,
                        max_gap_s: float | None = None) -> Refinement:
    """Final station pose: Nelder-Mead on ``K2 = sum_n ||C(L, P_n) - M_n||_F^2`` (paper step 5).

    ``T_ref_lh`` is the initial pose of the station in the reference frame, ``meas`` its
    measurements (ideal angles), ``trajectory`` the reference board path ``T_ref_board``,
    fixed and interpolated to each measurement's time (measurements outside it or across
    gaps > ``max_gap_s``, default ``max_gap_periods`` x its typical spacing, are skipped).
    Parameterised as ``R = Exp(omega) R0``, ``t = t0 + v``. With a finite
    ``options.outlier_mads`` (ours, not the paper's), measurements whose rms angle residual
    at the fitted pose is an outlier (:func:`outliers`) are dropped and K2 is fitted again
    from that pose, until the dropped set repeats (at most ``MAX_K2_FITS`` fits).
    """
    options = options or PaperOptions()
    T = np.asarray(T_ref_lh, dtype=float)
    if max_gap_s is None:
        max_gap_s = options.max_gap_periods * typical_spacing(trajectory.time)
    ok = _bracketed(trajectory.time, meas.time, max_gap_s)
    both = meas.both() & ok[:, None]
    n_meas = int(np.any(both, axis=1).sum())
    if n_meas < options.min_measurements:
        raise SolverError(f"station {meas.lighthouse}: only {n_meas} measurements overlap the "
                          f"reference board path (need >= {options.min_measurements})")
    rows, cols = np.nonzero(both)
    P = trajectory.at(meas.time[rows])
    world = transform_points(P, board.positions[cols])
    measured = np.stack([meas.azimuth[rows, cols], meas.elevation[rows, cols]], axis=1)
    per_meas = np.bincount(rows, minlength=len(meas))
    seen = per_meas > 0
    rejected = np.zeros(len(meas), dtype=bool)
    evaluations = iterations = 0
    for fit in range(1, MAX_K2_FITS + 1):
        use = ~rejected[rows]
        T, res = _minimise_station(world[use], measured[use], T, options)
        evaluations, iterations = evaluations + int(res.nfev), iterations + int(res.nit)
        if fit == MAX_K2_FITS or not math.isfinite(options.outlier_mads):
            break
        d = angle_errors((world - T[:3, 3]) @ T[:3, :3], measured)
        square = np.bincount(rows, weights=np.einsum("ij,ij->i", d, d), minlength=len(meas))
        now = np.zeros(len(meas), dtype=bool)
        now[seen] = outliers(np.sqrt(square[seen] / (2 * per_meas[seen])), options.outlier_mads)
        if np.array_equal(now, rejected):
            break
        rejected = now
    return Refinement(T, float(res.fun), evaluations, iterations, bool(res.success), n_meas,
                      int(rejected.sum()))
