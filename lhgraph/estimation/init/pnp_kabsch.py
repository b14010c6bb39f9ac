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
from lhgraph.estimation.imu.bridge import bridged_relative_pose
from lhgraph.estimation.init.pnp import PnPResult
from lhgraph.estimation.init.twins import chosen_path, consistent_path, twin_path
from lhgraph.estimation.problem import GraphProblem
from lhgraph.estimation.reconstruct import reconstruct_measurements
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import interpolate_poses, inverse, se3_log, transform_points
from lhgraph.io.angles import Angles
from lhgraph.io.imu import ImuStream
from lhgraph.model.board import Board

Array = NDArray[np.float64]
PoseSolver = Callable[..., PnPResult]
"""Per-measurement board pose in one station's frame: ``(azimuth, elevation, positions,
normals, model) -> PnPResult`` (the signature of :func:`board_poses`)."""


@dataclass(frozen=True)
class Initialisation:
    """Initial values: station poses ``L`` (S, 4, 4) (slot 0 = identity), board poses ``X``
    (K, 4, 4) and twists ``V`` (K, 6); ``overlap`` = time-matched pose pairs per station
    with the station it was joined to, ``parents`` that station's slot (slot 0: itself;
    :func:`join_paths`; empty when not known), ``matches`` the time-matched pairs between
    every two stations' paths (:func:`pair_matches`; None when not known)."""

    L: Array
    X: Array
    V: Array
    overlap: list[int] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    matches: NDArray[np.int64] | None = None


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


def _twin_chain_path(board: Board, angles: Angles, problem: GraphProblem, turn_sigma: float,
                     slot: int) -> tuple[Array, Array, Array]:
    """Station slot's (times, T_lh_board, rms): both planar twins of every merged az/el pair
    with 5 sensors, the temporally consistent chain of them (a seen sensor faces the
    station: on a curved board that rules the wrong twin out)."""
    twins = twin_path(board, angles, problem, slot, "merge", min_sensors=5, min_facing=0.8)
    return chosen_path(twins, twins.emission, turn_sigma)


def in_threads(one: Callable, n: int) -> list:
    """``one(slot)`` of slots ``0..n-1`` in parallel threads (numpy releases the GIL in its
    array loops)."""
    with ThreadPoolExecutor(max_workers=min(n, len(os.sched_getaffinity(0)))) as pool:
        return list(pool.map(one, range(n)))


def station_paths(board: Board, angles: Angles, problem: GraphProblem,
                  pose_solver: PoseSolver | None = None, turn_sigma: float = 1.0
                  ) -> list[tuple[Array, Array, Array]]:
    """Every station slot's path ``(times, T_lh_board, rms)``: by default both planar twins of
    each measurement and the chain the Viterbi picks (random walk ``turn_sigma``
    rad/sqrt(s): :func:`~lhgraph.estimation.init.twins.resolve_twins`); with
    ``pose_solver`` its pose per measurement. The stations in parallel threads (numpy
    releases the GIL in its array loops)."""
    one = (partial(_twin_chain_path, board, angles, problem, turn_sigma) if pose_solver is None
           else partial(_station_path, board, angles, problem, pose_solver))
    return in_threads(one, len(problem.station_ids))


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
               pose_solver: PoseSolver | None = None, turn_sigma: float = 1.0,
               imu: ImuStream | None = None) -> Initialisation:
    """Initial values from per-station PnP paths (:func:`station_paths`: the Viterbi's chain
    of planar twins, random walk ``turn_sigma`` rad/sqrt(s), or ``pose_solver`` per
    measurement) joined by weighted Kabsch on sensor points over the stations' overlap tree
    (:func:`join_paths`, bridged by ``imu`` where two stations never see the board at once);
    twists from the merged path's change over ``velocity_span_s``.

    LH2 stations (default pose solver): the twins from the ideal LH1-equivalent angles
    (:func:`~lhgraph.estimation.init.twins.twin_path` with ``ideal_lh1``), and the twists
    from each station's own path (:func:`world_states`, ``twist_per_path``: LH2 stations see
    the board at the same moments, and the merged path alternates between stations placed
    cm apart before the solve)."""
    lh2 = any(m.generation == 2 for m in problem.models)
    if lh2 and pose_solver is None:
        twins = in_threads(partial(twin_path, board, angles, problem, reconstruction="merge",
                                    min_sensors=5, min_facing=0.8, ideal_lh1=True),
                            len(problem.station_ids))
        paths = [chosen_path(tw, tw.emission, turn_sigma) for tw in twins]
    else:
        paths = station_paths(board, angles, problem, pose_solver, turn_sigma)
    parents: list[int] = []
    matches = pair_matches(paths, max_gap_s)
    L0, overlap = join_paths(board, problem, paths, max_gap_s, parents, matches, imu)
    X0, V0 = world_states(paths, L0, problem.state_time, velocity_span_s, lh2)
    return Initialisation(L0, X0, V0, overlap, parents, matches)


MIN_MATCHES = 3
"""Time-matched pose pairs two stations' paths need for their relative pose (Kabsch)."""


def pair_matches(paths: list[tuple[Array, Array, Array]], max_gap_s: float = 0.05
                 ) -> NDArray[np.int64]:
    """``M[p, c]``: how many of slot c's path times have samples of slot p's path within
    ``max_gap_s`` on both sides (the pairs :func:`relative_pose` would use), (S, S)."""
    S = len(paths)
    M = np.zeros((S, S), dtype=np.int64)
    for p in range(S):
        for c in range(S):
            if p != c:
                M[p, c] = int(_match_times(paths[c][0], paths[p][0], max_gap_s).sum())
    return M


def overlap_tree(matches: NDArray[np.int64], min_matches: int = MIN_MATCHES) -> list[int]:
    """Parent slot of every slot (slot 0, the reference, is its own): every station joined
    straight to the reference when each has ``min_matches`` with it (the star), otherwise a
    maximum spanning tree over the stations' time-matched pairs grown from the reference
    (Prim's: each step joins the unplaced station with the most matches with a placed one,
    so each station's chain to the reference is the one whose weakest link is strongest);
    -1 for a station no placed station shares ``min_matches`` with."""
    S = len(matches)
    if all(matches[0, c] >= min_matches for c in range(1, S)):
        return [0] * S
    parent = [-1] * S
    parent[0] = 0
    placed = [0]
    while len(placed) < S:
        free = [c for c in range(S) if parent[c] < 0]
        w = matches[np.ix_(placed, free)]
        i, j = np.unravel_index(np.argmax(w), w.shape)
        if w[i, j] < min_matches:
            break
        parent[free[j]] = placed[i]
        placed.append(free[j])
    return parent


def relative_pose(board: Board, parent: tuple[Array, Array, Array],
                  child: tuple[Array, Array, Array], max_gap_s: float = 0.05) -> Array:
    """``T_parent_child`` from two stations' paths ``(times, T_lh_board, rms_rad)``: a weighted
    Kabsch (weights 1/rms^2 of the child's fits) between the child path's sensor points and
    the parent path's interpolated to the same times, over the time-matched pairs whose
    proposal agrees with the median (at least :data:`MIN_MATCHES` pairs expected)."""
    t_p, T_p, _ = parent
    t_s, T_s, rms_s = child
    ok = _match_times(t_s, t_p, max_gap_s)
    T_p_at = interpolate_poses(t_p, T_p, t_s[ok])
    # each matched pair proposes T_parent_child; keep those near the median proposal
    proposals = T_p_at @ inverse(T_s[ok])
    centre = np.median(proposals[:, :3, 3], axis=0)
    agree = np.linalg.norm(proposals[:, :3, 3] - centre, axis=1)
    agree = agree <= max(3 * np.median(agree), 0.02)
    src = transform_points(T_s[ok][agree][:, None], board.positions[None])  # child
    dst = transform_points(T_p_at[agree][:, None], board.positions[None])  # parent
    w = np.repeat(1.0 / (rms_s[ok][agree] ** 2 + 1e-10), len(board.positions))
    return weighted_kabsch(src.reshape(-1, 3), dst.reshape(-1, 3), w)


def chain_to_reference(slot: int, parents: list[int]) -> list[int]:
    """Slots from ``slot`` to the reference (slot 0) along ``parents`` (:func:`overlap_tree`;
    ``[slot, 0]`` when the parents are not known)."""
    chain = [slot]
    while chain[-1] != 0 and len(chain) <= len(parents):
        chain.append(parents[chain[-1]] if chain[-1] < len(parents) else 0)
    return chain if chain[-1] == 0 else [slot, 0]


def join_paths(board: Board, problem: GraphProblem, paths: list[tuple[Array, Array, Array]],
               max_gap_s: float = 0.05, parents: list[int] | None = None,
               matches: NDArray[np.int64] | None = None, imu: ImuStream | None = None
               ) -> tuple[Array, list[int]]:
    """Station poses ``T_world_lh`` (S, 4, 4) (slot 0 = identity) from every slot's path
    ``(times, T_lh_board, rms_rad)``, and the time-matched pairs of each slot's join.

    Each station is joined to its parent in the overlap tree (:func:`overlap_tree`; or
    ``parents``, filled in place when given as an empty list): straight to the reference
    when every station saw the board within ``max_gap_s`` of it at least
    :data:`MIN_MATCHES` times (the only case before chaining; unchanged), otherwise through
    chains of stations that saw it at the same moments (a room where each station overlaps
    only its neighbours). Each link is :func:`relative_pose`; ``T_world_lh`` of a station
    is its parent's times the link. ``matches``: the paths' :func:`pair_matches` when the
    caller has them already. ``imu``: the receiver's IMU stream (board frame, the paths'
    clock); a station no placed station saw the board with at the same moments is then
    joined to the reference through it (:func:`~lhgraph.estimation.imu.bridge.
    bridged_relative_pose`: moments up to 0.6 s apart bridged by dead reckoning; its overlap
    counts 0)."""
    t_ref = paths[0][0]
    if len(t_ref) < 2:
        raise SolverError(f"station {problem.station_ids[0]} (reference): too few usable "
                          "measurements to initialise")
    S = len(problem.station_ids)
    M = pair_matches(paths, max_gap_s) if matches is None else matches
    tree = overlap_tree(M)
    bridged = {}
    for c in [c for c in range(S) if tree[c] < 0 and imu is not None]:
        link = bridged_relative_pose(board, paths[0], paths[c], imu)
        if link is not None:
            bridged[c] = link
            tree[c] = 0
    missing = [c for c in range(S) if tree[c] < 0]
    if missing:
        ids = problem.station_ids
        if S == 2:
            raise SolverError(
                f"station {ids[1]}: the board was never seen by it and the reference station "
                f"within {max_gap_s * 1e3:.0f} ms ({M[0, 1]} matches); use a non-planar board "
                "or wave it so both stations see it")
        linked = [ids[c] for c in range(S) if tree[c] >= 0]
        raise SolverError(
            f"station(s) {', '.join(str(ids[c]) for c in missing)}: the board was never seen "
            f"by them at the same time (within {max_gap_s * 1e3:.0f} ms, {MIN_MATCHES} times) "
            f"as by any of the stations linked to the reference ({', '.join(map(str, linked))}"
            "); carry the board where they and a linked station both see it")
    if parents is not None:
        parents[:] = tree
    L0 = np.repeat(np.eye(4)[None], S, axis=0)
    overlap = [len(t_ref)] + [int(M[tree[c], c]) for c in range(1, S)]
    done = {0}
    while len(done) < S:  # parents before children
        for c in range(1, S):
            if c not in done and tree[c] in done:
                link = bridged.get(c)
                if link is None:
                    link = relative_pose(board, paths[tree[c]], paths[c], max_gap_s)
                L0[c] = L0[tree[c]] @ link
                done.add(c)
    return L0, overlap


def world_states(paths: list[tuple[Array, Array, Array]], T_world_lh: Array, t: Array,
                 velocity_span_s: float = 0.01, twist_per_path: bool = False
                 ) -> tuple[Array, Array]:
    """Board poses ``T_world_board`` (K, 4, 4) and body twists (K, 6) at times ``t`` (K,) (s)
    from every station slot's path (:func:`station_paths`) put into the world by its
    ``T_world_lh`` (S, 4, 4) and merged by time: poses interpolated (clamped at the ends),
    twists by central differences over ``velocity_span_s`` on the merged path, or with
    ``twist_per_path`` on each station's own path, the merged twists then interpolated: two
    stations that see the board at once (LH2) place it a few cm apart before the solve, and
    differences across their interleaved paths would read as metres per second."""
    times = np.concatenate([p[0] for p in paths])
    T_all = np.concatenate([T_world_lh[slot] @ path[1] for slot, path in enumerate(paths)])
    order = np.argsort(times, kind="stable")
    times, T_all = times[order], T_all[order]
    keep = np.r_[True, np.diff(times) > 0]
    # states may be closer together than the span
    h = 0.5 * velocity_span_s
    if not twist_per_path:
        X0, before, after = interpolate_poses(
            times[keep], T_all[keep], np.concatenate([t, t - h, t + h])).reshape(3, -1, 4, 4)
        return X0, se3_log(inverse(before) @ after) / (2 * h)
    X0 = interpolate_poses(times[keep], T_all[keep], t)
    t_twist, twists = [], []
    for slot, (t_p, T_p, _) in enumerate(paths):
        if len(t_p) < 2:
            continue
        world = T_world_lh[slot] @ T_p
        before, after = interpolate_poses(t_p, world, np.r_[t_p - h, t_p + h]).reshape(
            2, -1, 4, 4)
        t_twist.append(t_p)
        twists.append(se3_log(inverse(before) @ after) / (2 * h))
    if not twists:
        return X0, np.zeros((len(t), 6))
    t_all, V_all = np.concatenate(t_twist), np.concatenate(twists)
    order = np.argsort(t_all, kind="stable")
    t_all, V_all = t_all[order], V_all[order]
    return X0, np.stack([np.interp(t, t_all, V_all[:, j]) for j in range(6)], axis=1)


@dataclass(frozen=True)
class PnPKabschInitialiser:
    """The default :class:`~lhgraph.estimation.init.Initialiser`: :func:`initialise`, the
    board poses by default both planar twins of every measurement and the temporally
    consistent chain of them; with ``pose_solver`` its pose per measurement
    (:func:`lhgraph.estimation.init.pnp.board_poses`: the better-fitting twin each time;
    :func:`lhgraph.estimation.init.pnp_nonplanar.tracker_board_poses` for curved boards);
    ``imu``: the receiver's IMU stream, which joins stations that never see the board at the
    same moments (:func:`join_paths`)."""

    pose_solver: PoseSolver | None = None
    max_gap_s: float = 0.05
    velocity_span_s: float = 0.01
    imu: ImuStream | None = None

    def __call__(self, board: Board, angles: Angles, problem: GraphProblem) -> Initialisation:
        return initialise(board, angles, problem, self.max_gap_s, self.velocity_span_s,
                          self.pose_solver, imu=self.imu)
