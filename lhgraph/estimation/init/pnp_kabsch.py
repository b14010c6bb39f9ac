"""Initial values for the graph: per-station PnP paths, joined by a weighted Kabsch on sensor
points."""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import SolverError
from lhgraph.estimation.init.pnp import PnPResult, board_poses
from lhgraph.estimation.problem import GraphProblem
from lhgraph.estimation.reconstruct import reconstruct_measurements
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import interpolate_poses, inverse, se3_log, transform_points
from lhgraph.io.angles import Angles
from lhgraph.model.board import Board

Array = NDArray[np.float64]
PoseSolver = Callable[..., PnPResult]
"""Per-measurement board pose in one station's frame: ``(azimuth, elevation, positions,
normals, model) -> PnPResult`` (the signature of :func:`board_poses`)."""


@dataclass(frozen=True)
class Initialisation:
    """Initial values: station poses ``L`` (S, 4, 4) (slot 0 = identity), board poses ``X``
    (K, 4, 4) and twists ``V`` (K, 6); ``overlap`` = time-matched pose pairs per station."""

    L: Array
    X: Array
    V: Array
    overlap: list[int] = field(default_factory=list)


def _station_path(board: Board, angles: Angles, problem: GraphProblem, pose_solver: PoseSolver,
                  slot: int) -> tuple[Array, Array, Array]:
    """Station slot's (times, T_lh_board, rms) from merged az/el pairs + PnP."""
    model = problem.models[slot]
    s = problem.station_ids[slot]
    meas = reconstruct_measurements(angles.select(angles.lighthouse == s), board, "merge")
    if len(meas) == 0:
        return np.empty(0), np.empty((0, 4, 4)), np.empty(0)
    pnp = pose_solver(meas.azimuth, meas.elevation, board.positions, board.normals, model)
    ok = pnp.valid
    ok[ok] = consistent_path(meas.time[ok], pnp.T_lh_board[ok])
    return meas.time[ok], pnp.T_lh_board[ok], pnp.rms_rad[ok]


def station_paths(board: Board, angles: Angles, problem: GraphProblem,
                  pose_solver: PoseSolver) -> list[tuple[Array, Array, Array]]:
    """Every station slot's path ``(times, T_lh_board, rms)``, the stations in parallel
    threads (numpy releases the GIL in its array loops)."""
    slots = range(len(problem.station_ids))
    with ThreadPoolExecutor(max_workers=min(len(slots), len(os.sched_getaffinity(0)))) as pool:
        return list(pool.map(partial(_station_path, board, angles, problem, pose_solver), slots))


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


def _match_times(t_query: Array, t_ref: Array, max_gap_s: float) -> NDArray[np.bool_]:
    """Query times that have reference samples on both sides within ``max_gap_s``."""
    i = np.searchsorted(t_ref, t_query)
    ok = (i > 0) & (i < len(t_ref))
    i = np.clip(i, 1, max(len(t_ref) - 1, 1))
    if len(t_ref) < 2:
        return np.zeros(len(t_query), dtype=bool)
    return ok & (t_query - t_ref[i - 1] < max_gap_s) & (t_ref[i] - t_query < max_gap_s)


def initialise(board: Board, angles: Angles, problem: GraphProblem,
               max_gap_s: float = 0.05, velocity_span_s: float = 0.01,
               pose_solver: PoseSolver = board_poses) -> Initialisation:
    """Initial values from per-station PnP paths (``pose_solver`` per measurement) and a
    weighted Kabsch on sensor points; twists from the merged path's change over
    ``velocity_span_s``."""
    paths = station_paths(board, angles, problem, pose_solver)
    L0, overlap = join_paths(board, problem, paths, max_gap_s)
    X0, V0 = world_states(paths, L0, problem.state_time, velocity_span_s)
    return Initialisation(L0, X0, V0, overlap)


def join_paths(board: Board, problem: GraphProblem, paths: list[tuple[Array, Array, Array]],
               max_gap_s: float = 0.05) -> tuple[Array, list[int]]:
    """Station poses ``T_world_lh`` (S, 4, 4) (slot 0 = identity) from every slot's path
    ``(times, T_lh_board, rms_rad)``: a weighted Kabsch (weights 1/rms^2) between the sensor
    points of each path and of the reference path interpolated to its times, over the pairs
    whose proposal agrees with the median; and the time-matched pairs per slot."""
    t_ref, T_ref, _ = paths[0]
    if len(t_ref) < 2:
        raise SolverError(f"station {problem.station_ids[0]} (reference): too few usable "
                          "measurements to initialise")
    S = len(problem.station_ids)
    L0 = np.repeat(np.eye(4)[None], S, axis=0)
    overlap = [len(t_ref)]
    for slot in range(1, S):
        t_s, T_s, rms_s = paths[slot]
        ok = _match_times(t_s, t_ref, max_gap_s)
        overlap.append(int(ok.sum()))
        if ok.sum() < 3:
            raise SolverError(
                f"station {problem.station_ids[slot]}: the board was never seen by it and the "
                f"reference station within {max_gap_s * 1e3:.0f} ms ({ok.sum()} matches); "
                "use a non-planar board or wave it so both stations see it")
        T_ref_at = interpolate_poses(t_ref, T_ref, t_s[ok])
        # each matched pair proposes T_ref_s; keep those near the median proposal
        proposals = T_ref_at @ inverse(T_s[ok])
        centre = np.median(proposals[:, :3, 3], axis=0)
        agree = np.linalg.norm(proposals[:, :3, 3] - centre, axis=1)
        agree = agree <= max(3 * np.median(agree), 0.02)
        src = transform_points(T_s[ok][agree][:, None], board.positions[None])  # station s
        dst = transform_points(T_ref_at[agree][:, None], board.positions[None])  # reference
        w = np.repeat(1.0 / (rms_s[ok][agree] ** 2 + 1e-10), len(board.positions))
        L0[slot] = weighted_kabsch(src.reshape(-1, 3), dst.reshape(-1, 3), w)
    return L0, overlap


def world_states(paths: list[tuple[Array, Array, Array]], T_world_lh: Array, t: Array,
                 velocity_span_s: float = 0.01) -> tuple[Array, Array]:
    """Board poses ``T_world_board`` (K, 4, 4) and body twists (K, 6) at times ``t`` (K,) (s)
    from every station slot's path (:func:`station_paths`) put into the world by its
    ``T_world_lh`` (S, 4, 4) and merged by time: poses interpolated (clamped at the ends),
    twists by central differences over ``velocity_span_s`` on the merged path."""
    times = np.concatenate([p[0] for p in paths])
    T_all = np.concatenate([T_world_lh[slot] @ path[1] for slot, path in enumerate(paths)])
    order = np.argsort(times, kind="stable")
    times, T_all = times[order], T_all[order]
    keep = np.r_[True, np.diff(times) > 0]
    # states may be closer together than the span
    h = 0.5 * velocity_span_s
    X0, before, after = interpolate_poses(times[keep], T_all[keep],
                                          np.concatenate([t, t - h, t + h])).reshape(3, -1, 4, 4)
    return X0, se3_log(inverse(before) @ after) / (2 * h)


@dataclass(frozen=True)
class PnPKabschInitialiser:
    """The default :class:`~lhgraph.estimation.init.Initialiser`: :func:`initialise` with
    ``pose_solver`` for the per-measurement board poses (planar homography PnP by default;
    :func:`lhgraph.estimation.init.pnp_nonplanar.tracker_board_poses` suits curved boards)."""

    pose_solver: PoseSolver = board_poses
    max_gap_s: float = 0.05
    velocity_span_s: float = 0.01

    def __call__(self, board: Board, angles: Angles, problem: GraphProblem) -> Initialisation:
        return initialise(board, angles, problem, self.max_gap_s, self.velocity_span_s,
                          self.pose_solver)
