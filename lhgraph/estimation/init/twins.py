"""The planar mirror ambiguity resolved over time: a two-state Viterbi over a sequence of
twin poses.

A flat target seen by one station has two poses that fit its image almost equally well
(the board normal reflected about the line of sight); with few sensors far away the fit
alone cannot tell them apart. A board moves smoothly, though: :func:`resolve_twins` picks,
per measurement, the twin that makes the whole sequence most consistent, trading each twin's
own fit (an emission cost) against the rotation between consecutive choices (a random walk
on the orientation). :func:`twin_path` gives one station's measurements with both twins,
:func:`chosen_path` the chain :func:`resolve_twins` picks from them, filtered by
:func:`consistent_path`; both initialisers use them (few-diode boards always, larger planar
boards by default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.init.pnp import planar_twins
from lhgraph.estimation.problem import GraphProblem
from lhgraph.estimation.reconstruct import reconstruct_measurements
from lhgraph.geometry.transforms import rotation_angle
from lhgraph.io.angles import Angles
from lhgraph.model.board import Board
from lhgraph.model.station import IDEAL, ideal_from_measured

Array = NDArray[np.float64]


def resolve_twins(time: Array, R: Array, emission: Array, turn_sigma: float = 1.0,
                  min_dt_s: float = 1e-3) -> NDArray[np.int64]:
    """The temporally consistent twin (0 or 1) of each measurement.

    ``time`` (M,) s, increasing; ``R`` (M, 2, 3, 3) the two twins' rotations (any common
    frame, e.g. ``R_lh_board`` of one station); ``emission`` (M, 2) each twin's own cost (a
    chi-square; ``inf`` or NaN = impossible). The orientation is a random walk with
    ``turn_sigma`` rad/sqrt(s): the cost of going from twin i at m to twin j at m + 1 is
    ``angle(R[m, i]^T R[m + 1, j])^2 / (turn_sigma^2 max(dt, min_dt_s))``. Measurements
    with neither twin possible get -1 and do not break the chain. Minimises the summed
    cost exactly (dynamic programming, two states).
    """
    emission = np.where(np.isfinite(emission), emission, np.inf)
    choice = np.full(len(time), -1, dtype=np.int64)
    rows = np.flatnonzero(np.isfinite(emission).any(axis=1))
    if len(rows) == 0:
        return choice
    e = emission[rows]
    Rr = R[rows]
    dt = np.maximum(np.diff(time[rows]), min_dt_s)
    # (M-1, 2, 2): transition i -> j between consecutive kept measurements
    rel = np.swapaxes(Rr[:-1, :, None], -1, -2) @ Rr[1:, None, :]
    trans = rotation_angle(rel) ** 2 / (turn_sigma**2 * dt[:, None, None])
    trans = np.where(np.isfinite(trans), trans, np.inf)
    cost = e[0].copy()
    back = np.zeros((len(rows), 2), dtype=np.int64)
    for m in range(1, len(rows)):
        total = cost[:, None] + trans[m - 1]  # (from, to)
        back[m] = np.argmin(total, axis=0)
        cost = total[back[m], [0, 1]] + e[m]
    path = np.empty(len(rows), dtype=np.int64)
    path[-1] = int(np.argmin(cost))
    for m in range(len(rows) - 1, 0, -1):
        path[m - 1] = back[m, path[m]]
    choice[rows] = path
    return choice


def consistent_path(t: Array, T: Array, window: int = 7, max_jump_m: float = 0.15,
                     max_turn_rad: float = 0.5) -> NDArray[np.bool_]:
    """Poses within ``max_jump_m`` of the running median position of their ``window``
    neighbours and within ``max_turn_rad`` of the rotation of most of them (a board moves
    < 2 m/s and turns < 10 rad/s; a wrong PnP twin is turned, and a fit to a handful of
    reflected hits lands far away)."""
    if len(t) < window:
        return np.ones(len(t), dtype=bool)
    half = window // 2
    p = T[:, :3, 3]
    padded = np.pad(p, ((half, half), (0, 0)), mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, window, axis=0)
    near = np.linalg.norm(p - np.median(windows, axis=-1), axis=1) < max_jump_m
    R = T[:, :3, :3]
    agree = np.zeros(len(t), dtype=int)
    for shift in range(1, half + 1):
        # relative rotation angle to the neighbour ``shift`` steps later: cos = (tr - 1) / 2
        cos = (np.einsum("kij,kij->k", R[:-shift], R[shift:]) - 1.0) / 2.0
        close = cos > np.cos(max_turn_rad)
        agree[:-shift] += close
        agree[shift:] += close
    neighbours = np.minimum(np.arange(len(t)), half) + np.minimum(np.arange(len(t))[::-1], half)
    return near & (2 * agree >= neighbours)


@dataclass(frozen=True)
class TwinPath:
    """One station's measurements with both planar twins: ``time`` (M,) s, ``T_lh_board``
    (M, 2, 4, 4), ``rms_rad`` (M, 2), ``emission`` (M, 2) each twin's own cost (chi-square
    of its fit; inf: impossible)."""

    time: Array
    T_lh_board: Array
    rms_rad: Array
    emission: Array


def twin_path(board: Board, angles: Angles, problem: GraphProblem, slot: int,
              reconstruction: str = "full", min_sensors: int = 4, min_facing: float = 0.5,
              fit_sigma_rad: float = 1e-4, ideal_lh1: bool = False) -> TwinPath:
    """Station slot's measurements (``reconstruction`` as in
    :func:`~lhgraph.estimation.reconstruct.reconstruct_measurements`) and both planar twins
    of each with at least ``min_sensors`` sensors on both axes; emission = the twin's
    chi-square at ``fit_sigma_rad``, a twin with less than ``min_facing`` of its seen
    sensors facing the station is impossible. With ``ideal_lh1`` the twins are solved from
    the measurements' ideal LH1-equivalent angles
    (:func:`~lhgraph.model.station.ideal_from_measured`: calibration inverted, an LH2 pair
    converted) as an ideal LH1 station: ``planar_twins`` seeds its homography with the
    tangents of the two angles it is given, which for LH2's tilted planes is no projection
    (off the optical axis both twins then converged 60-150° away from the board, for 5-30 %
    of a station's measurements in a simulated room; none from the converted angles)."""
    s = problem.station_ids[slot]
    station = angles.select(angles.lighthouse == s)
    if len(station) == 0:
        return TwinPath(np.empty(0), np.empty((0, 2, 4, 4)), np.empty((0, 2)),
                        np.empty((0, 2)))
    meas = reconstruct_measurements(station, board, reconstruction)
    a0, a1, model = meas.azimuth, meas.elevation, problem.models[slot]
    if ideal_lh1:
        a0, a1 = ideal_from_measured(a0, a1, model)
        model = IDEAL
    twins = planar_twins(a0, a1, board.positions, board.normals, model,
                         min_sensors=min_sensors)
    chi2 = 2 * twins.n_sensors[:, None] * (twins.rms_rad / fit_sigma_rad) ** 2
    emission = np.where((twins.facing > min_facing) & np.isfinite(chi2), chi2, np.inf)
    valid = np.isfinite(emission).any(axis=1)
    return TwinPath(meas.time[valid], twins.T_lh_board[valid], twins.rms_rad[valid],
                    emission[valid])


def chosen_path(twins: TwinPath, emission: Array, turn_sigma: float
                ) -> tuple[Array, Array, Array]:
    """The path ``(times, T_lh_board, rms_rad)`` of the Viterbi twins under ``emission``,
    filtered like the default initialiser's paths (:func:`consistent_path`)."""
    choice = resolve_twins(twins.time, twins.T_lh_board[..., :3, :3], emission, turn_sigma)
    rows = np.flatnonzero(choice >= 0)
    T = twins.T_lh_board[rows, choice[rows]]
    rms = twins.rms_rad[rows, choice[rows]]
    keep = consistent_path(twins.time[rows], T)
    return twins.time[rows][keep], T[keep], rms[keep]
