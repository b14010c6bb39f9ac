"""Stations' poses from the hits of a receiver whose path is known (resection).

With the board's path known in some frame ``ref`` (a motion-capture system's; a simulation's
truth), every station's pose in that frame is a small least-squares problem: six unknowns per
station, the bearing model :func:`lhgraph.model.station.predict` against the measured angles,
Gauss-Newton on right perturbations with Cauchy weights (iteratively reweighted). A mocap
tracks a marker body, not the board's origin: its offset from the board (the lever, board
frame) can be solved with the stations, shared by all of them, under a weak prior centred on
zero (a level flight leaves its vertical part unobserved; it then moves every station alike
and leaves their relative poses alone). Nothing of the receiver's path is estimated, so a
geometry found this way owes nothing to the graph's trajectory, motion prior or board scale:
the benchmarks use it as the reference geometry of the real recordings
(benchmarks/anchored_stations.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.errors import SolverError
from lhgraph.geometry.transforms import se3_exp
from lhgraph.model.station import StationModel, predict

Array = NDArray[np.float64]
ANNEALING = 3.0
"""The loss's scale is at least this many median absolute residuals: far from the solution,
or on a path noisier than the scale asked for, most hits would otherwise be outliers."""


@dataclass(frozen=True)
class Resection:
    """Resected stations: ``T_ref_lh`` (4, 4) by station, the tracked point's position
    ``lever_m`` (3,) in the board frame (m; zeros unless solved), the residuals
    ``residual_rad`` (N,) of the hits at the solution (predicted - measured, rad, in the
    hits' order), the Gauss-Newton ``iterations`` run and whether the step fell below the
    tolerance (``converged``)."""

    T_ref_lh: dict[int, Array]
    lever_m: Array
    residual_rad: Array
    iterations: int
    converged: bool

    @property
    def median_abs_residual_rad(self) -> float:
        """Median absolute residual (rad)."""
        return float(np.median(np.abs(self.residual_rad)))


def resect_stations(T_ref_tracked: ArrayLike, s_board: ArrayLike, station: ArrayLike,
                    axis: ArrayLike, angle_rad: ArrayLike, models: dict[int, StationModel],
                    T_ref_lh_start: dict[int, ArrayLike], *, solve_lever: bool = False,
                    lever_sigma_m: float = 0.1, angle_sigma_rad: float = 1e-4,
                    cauchy_scale_rad: float = 2e-4,
                    max_iterations: int = 50, step_tolerance: float = 1e-10) -> Resection:
    """The stations' poses ``T_ref_lh`` from ``N`` hits.

    ``T_ref_tracked`` ``(N, 4, 4)``: at each hit the board's orientation and the tracked
    point's position (m, frame ``ref``); the tracked point sits at the lever (board frame)
    from the board's origin: zero, or solved with ``solve_lever`` under a prior of spread
    ``lever_sigma_m`` against hits of noise ``angle_sigma_rad``. Per hit: the sensor's
    board-frame position ``s_board`` ``(N, 3)`` (m), the ``station`` index, ``axis`` and
    measured ``angle_rad``. ``models`` and the starts ``T_ref_lh_start`` by station index; a
    start must lie within the model's basin (a few degrees and decimetres). Residuals are
    weighted by the Cauchy loss of scale ``cauchy_scale_rad`` (or :data:`ANNEALING` median
    residuals, when larger); iterations stop when the step's norm (rad and m
    together) is below ``step_tolerance``. SolverError when the hits cannot fix the
    unknowns."""
    T_t = np.asarray(T_ref_tracked, dtype=float)
    s = np.asarray(s_board, dtype=float)
    st = np.asarray(station, dtype=int)
    ax = np.asarray(axis, dtype=int)
    measured = np.asarray(angle_rad, dtype=float)
    keys = sorted(set(st.tolist()))
    missing = [k for k in keys if k not in models or k not in T_ref_lh_start]
    if missing:
        raise SolverError(f"no model or start for station(s) {missing}")
    few = [k for k in keys if np.sum(st == k) < 6]
    if few:
        raise SolverError(f"resection needs at least 6 hits per station; station(s) {few} "
                          "have fewer")
    T = {k: np.asarray(T_ref_lh_start[k], dtype=float).copy() for k in keys}
    lever = np.zeros(3)
    n = 6 * len(keys) + (3 if solve_lever else 0)
    iterations, step = 0, np.full(n, np.inf)
    while iterations < max_iterations and np.linalg.norm(step) >= step_tolerance:
        iterations += 1
        r, J = _residuals(T, tracked_board_poses(T_t, lever), s, st, ax, measured, models, keys,
                          solve_lever)
        scale = max(cauchy_scale_rad, ANNEALING * float(np.median(np.abs(r))))
        w = 1.0 / (1.0 + (r / scale) ** 2)
        A = J.T @ (w[:, None] * J) / angle_sigma_rad**2
        g = J.T @ (w * r) / angle_sigma_rad**2
        if solve_lever:
            A[-3:, -3:] += np.eye(3) / lever_sigma_m**2
            g[-3:] += lever / lever_sigma_m**2
        if np.linalg.cond(A) > 1e12:
            raise SolverError("the hits do not determine the stations' poses (a degenerate "
                              "path: too few distinct board poses or sensors)")
        step = -np.linalg.solve(A, g)
        for i, k in enumerate(keys):
            T[k] = T[k] @ se3_exp(step[6 * i:6 * i + 6])
        if solve_lever:
            lever = lever + step[-3:]
    r, _ = _residuals(T, tracked_board_poses(T_t, lever), s, st, ax, measured, models, keys, False)
    return Resection(T, lever, r, iterations, bool(np.linalg.norm(step) < step_tolerance))


def tracked_board_poses(T_ref_tracked: Array, lever_m: Array) -> Array:
    """Board poses whose origin lies ``-lever_m`` (board frame) from the tracked point."""
    T = T_ref_tracked.copy()
    T[:, :3, 3] -= T[:, :3, :3] @ lever_m
    return T


def _residuals(T_ref_lh: dict[int, Array], T_ref_board: Array, s: Array, station: Array,
               axis: Array, measured: Array, models: dict[int, StationModel],
               keys: list[int], lever: bool) -> tuple[Array, Array]:
    """Residuals (predicted - measured, rad) and their Jacobian: right perturbations of each
    station in ``keys``' order, then the lever (a board origin moved by ``-d lever`` is the
    board's right translation ``-d lever``)."""
    r = np.zeros(len(measured))
    J = np.zeros((len(measured), 6 * len(keys) + (3 if lever else 0)))
    for i, k in enumerate(keys):
        m = station == k
        predicted, H_lh, H_board = predict(T_ref_lh[k], T_ref_board[m], s[m], axis[m],
                                           models[k], jacobians=True)
        r[m] = predicted - measured[m]
        J[np.flatnonzero(m), 6 * i:6 * i + 6] = H_lh
        if lever:
            J[np.flatnonzero(m), -3:] = -H_board[:, 3:]
    return r, J
