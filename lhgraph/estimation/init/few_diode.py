"""Initial values for receivers with few diodes (the Crazyflie Lighthouse deck: 4 coplanar
diodes 30 x 15 mm apart), whose sweeps rarely hold every diode of both axes at once.

Per station, every sweep becomes a measurement whose other axis is interpolated per diode
in time from that diode's neighbouring sweeps (the paper's "full" reconstruction: a board
moves little between sweeps 8-33 ms apart), so a diode missed by one sweep is filled in from
the next. Each measurement with at least 4 diodes gives both planar twins
(:func:`~lhgraph.estimation.init.pnp.planar_twins`); a two-state Viterbi over each station's
sequence keeps the temporally consistent twin (:func:`~lhgraph.estimation.init.twins.
resolve_twins`); the station paths are joined by the weighted Kabsch of the default
initialiser (:func:`~lhgraph.estimation.init.pnp_kabsch.join_paths`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import SolverError
from lhgraph.estimation.init.pnp_kabsch import (
    Initialisation,
    in_threads,
    join_paths,
    world_states,
)
from lhgraph.estimation.init.twins import TwinPath, chosen_path, twin_path
from lhgraph.estimation.problem import GraphProblem, expand_ranges
from lhgraph.geometry.transforms import inverse, rotation_angle
from lhgraph.io.angles import Angles
from lhgraph.model.board import Board
from lhgraph.model.station import sweep_angle

Array = NDArray[np.float64]

def cross_station_cost(twins: list[TwinPath], T_world_lh: Array, slot: int,
                       sigma_rad: float, max_gap_s: float, turn_sigma: float = 0.0) -> Array:
    """(M, 2) cost of each twin of ``slot`` against the other stations: the squared angle to
    the nearest twin, in the world, of the other stations' measurement closest in time
    (within ``max_gap_s``; else 0), in units of ``sigma_rad`` widened by the board's turning
    over the time between them (variance ``sigma_rad^2 + turn_sigma^2 dt``, the Viterbi's
    random walk). Mirror twins are mirrored about each station's own line of sight, so only
    the true orientation is common to two stations."""
    own = twins[slot]
    R_own = T_world_lh[slot, :3, :3] @ own.T_lh_board[..., :3, :3]  # (M, 2, 3, 3)
    best = np.full((len(own.time), 2), np.inf)
    for other in range(len(twins)):
        if other == slot or len(twins[other].time) == 0:
            continue
        o = twins[other]
        j = np.searchsorted(o.time, own.time)
        lo, hi = np.clip(j - 1, 0, len(o.time) - 1), np.clip(j, 0, len(o.time) - 1)
        i = np.where(np.abs(o.time[lo] - own.time) <= np.abs(o.time[hi] - own.time), lo, hi)
        dt = np.abs(o.time[i] - own.time)
        R_o = T_world_lh[other, :3, :3] @ o.T_lh_board[i][..., :3, :3]  # (M, 2, 3, 3)
        rel = np.swapaxes(R_own[:, :, None], -1, -2) @ R_o[:, None, :]  # (M, 2, 2, 3, 3)
        angle = np.nanmin(np.where(np.isfinite(rel).all(axis=(-1, -2)),
                                   rotation_angle(np.nan_to_num(rel)), np.inf), axis=2)
        z2 = angle**2 / (sigma_rad**2 + turn_sigma**2 * dt)[:, None]
        best = np.where((dt < max_gap_s)[:, None], np.minimum(best, z2), best)
    return np.where(np.isfinite(best), best, 0.0)


def partial_view_cost(twins: list[TwinPath], problem: GraphProblem, T_world_lh: Array,
                      slot: int, sigma_rad: float, max_gap_s: float) -> Array:
    """(M, 2) cost of each twin of ``slot`` against the other stations' hits within
    ``max_gap_s`` of it, however few (a sweep of one or two diodes gives no pose of its own):
    each hit's angle predicted from the twin's world pose through ``T_world_lh`` (S, 4, 4),
    less the mean of its sweep's (the other station's state and axis), squared, in units of
    ``sigma_rad``, summed. The mean is taken out because a 4-point pose's range is ~1 %
    off, which moves every diode of a sweep alike; what is left is the diodes' spread, which
    the board's orientation sets (on the 30 x 15 mm deck at 4 m the twins differ there by
    mrad)."""
    own, hits = twins[slot], problem.hits
    cost = np.zeros((len(own.time), 2))
    if len(own.time) == 0:
        return cost
    t_hit = problem.state_time[hits.state] + hits.dt
    P = T_world_lh[slot] @ own.T_lh_board  # (M, 2, 4, 4) T_world_board of each twin
    for other in range(len(problem.station_ids)):
        if other == slot:
            continue
        rows = np.flatnonzero(hits.station == other)
        rows = rows[np.argsort(t_hit[rows], kind="stable")]
        lo = np.searchsorted(t_hit[rows], own.time - max_gap_s)
        n = np.searchsorted(t_hit[rows], own.time + max_gap_s) - lo
        m, at = expand_ranges(lo, n)  # (pairs,) measurement of each pair, its hit's row
        hit = rows[at]
        if len(hit) == 0:
            continue
        s = np.c_[hits.s_board[hit], np.ones(len(hit))][..., None]  # (pairs, 4, 1)
        sweep = np.unique((m * problem.n_states + hits.state[hit]) * 2 + hits.axis[hit],
                          return_inverse=True)[1]
        for j in range(2):
            p_lh = (inverse(T_world_lh[other]) @ P[m, j] @ s)[:, :3, 0]
            r = sweep_angle(p_lh, hits.axis[hit], problem.models[other]) - hits.angle[hit]
            r -= (np.bincount(sweep, weights=r) / np.bincount(sweep))[sweep]
            cost[:, j] += np.bincount(m, weights=r**2, minlength=len(own.time))
    return cost / sigma_rad**2


def triangulated(paths: list[tuple[Array, Array, Array]], T_world_lh: Array,
                 max_gap_s: float) -> list[tuple[Array, Array, Array]]:
    """The paths with each board position replaced by the point closest to its own ray and
    the ray of another station toward its path interpolated to the same time (within
    ``max_gap_s`` on both sides): the directions are precise, a 4-point pose's range is not
    (~1 % at 3 m)."""
    origin = T_world_lh[:, :3, 3]
    world = [(t, T_world_lh[slot] @ T) for slot, (t, T, _) in enumerate(paths)]
    out = []
    for slot, (t, T, rms) in enumerate(paths):
        p = world[slot][1][:, :3, 3].copy()
        d0 = p - origin[slot]
        d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
        for other, (t_o, T_o) in enumerate(world):
            if other == slot or len(t_o) < 2:
                continue
            i = np.clip(np.searchsorted(t_o, t), 1, len(t_o) - 1)
            ok = ((t > t_o[0]) & (t < t_o[-1]) & (t - t_o[i - 1] < max_gap_s)
                  & (t_o[i] - t < max_gap_s))
            w = ((t - t_o[i - 1]) / np.maximum(t_o[i] - t_o[i - 1], 1e-9))[:, None]
            q = (1 - w) * T_o[i - 1, :3, 3] + w * T_o[i, :3, 3]
            d1 = q - origin[other]
            d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
            # closest points of the rays o0 + a d0 and o1 + b d1
            b_ = np.sum(d0 * d1, axis=1)
            r = origin[other] - origin[slot]
            denom = np.maximum(1 - b_**2, 1e-9)
            a = (r @ d0.T - b_ * (r @ d1.T)) / denom
            c = (b_ * (r @ d0.T) - r @ d1.T) / denom
            mid = 0.5 * (origin[slot] + a[:, None] * d0 + origin[other] + c[:, None] * d1)
            ok &= (denom > 0.05) & (a > 0) & (c > 0)  # rays not near-parallel, both forward
            p[ok] = mid[ok]
        T_new = T.copy()
        T_new[:, :3, 3] = (inverse(T_world_lh[slot]) @ np.c_[p, np.ones(len(p))].T).T[:, :3]
        out.append((t, T_new, rms))
    return out


def station_twins(board: Board, angles: Angles, problem: GraphProblem) -> list[TwinPath]:
    """Each station's pair of twin board paths (:func:`twin_path`), by slot, the stations
    in parallel threads (numpy releases the GIL in its array loops). LH2 stations' twins
    come from their ideal LH1-equivalent angles: from the plane angles they converge far
    from the board off the optical axis."""
    lh2 = any(m.generation == 2 for m in problem.models)
    return in_threads(partial(twin_path, board, angles, problem, ideal_lh1=lh2),
                      len(problem.station_ids))


@dataclass(frozen=True)
class FewDiodeInitialiser:
    """The :class:`~lhgraph.estimation.init.Initialiser` for few-diode boards (see the module
    docstring). ``turn_sigma`` (rad/sqrt(s)) is the Viterbi's random walk; ``cross_sigma_rad``
    the spread of two stations' views of one orientation (the second pass), compared over
    at most ``cross_max_gap_s`` (widened by the turning over the time between the views:
    :func:`cross_station_cost`; tracking, with the stations known, compares over 0.5 s,
    which bridges the sparse stretches of a deck log); ``partial_sigma_rad`` and
    ``partial_max_gap_s``: the second pass also weighs each twin against the other
    stations' hits within that time, however few (:func:`partial_view_cost`; the spread of
    a sweep's diodes about their mean, predicted from the twin, compared at that sigma:
    on the 10 simulated decks, with the redundancy estimate of the motion prior, it leaves
    a median 12 board states off the true orientation by more than 5 deg after the solve
    instead of 96, in 6 LM iterations instead of 14.5);
    ``max_gap_s``
    and ``velocity_span_s`` as in the default initialiser; the paths' rms is floored at
    ``rms_floor_rad`` for the Kabsch weights (4 points leave only 2 redundant equations, so a
    fit's own rms says little); ``twist_per_path``: the initial twists from each station's
    own path (:func:`~lhgraph.estimation.init.pnp_kabsch.world_states`; None: when a station
    is LH2, whose stations see the board at once: on the real LH1 log, where they take
    turns, the merged path's twists converge in fewer iterations, 33 against 52)."""

    max_gap_s: float = 0.05
    velocity_span_s: float = 0.01
    turn_sigma: float = 0.3
    cross_sigma_rad: float = 0.15
    cross_max_gap_s: float = 0.05
    rms_floor_rad: float = 1e-4
    twist_per_path: bool | None = None
    partial_sigma_rad: float = 3e-4
    partial_max_gap_s: float = 0.05

    def __call__(self, board: Board, angles: Angles, problem: GraphProblem) -> Initialisation:
        twins = station_twins(board, angles, problem)
        # pass 1: each station's twins by their own fit; stations joined on those paths
        paths = [chosen_path(tw, tw.emission, self.turn_sigma) for tw in twins]
        L0, overlap = join_paths(board, problem, self._floored(paths), self.max_gap_s)
        # pass 2: the twins that agree with the other stations' views
        paths = self._agreeing_paths(twins, L0, problem)
        L0, overlap = join_paths(board, problem, self._floored(paths), self.max_gap_s)
        return self._states(paths, L0, problem, overlap)

    def with_stations(self, board: Board, angles: Angles, problem: GraphProblem,
                      T_world_lh: Array) -> Initialisation:
        """Board states with every station known at ``T_world_lh`` (S, 4, 4) by slot
        (tracking): the twins that agree with the other stations' views, triangulated."""
        twins = station_twins(board, angles, problem)
        return self._states(self._agreeing_paths(twins, T_world_lh, problem), T_world_lh,
                            problem, [])

    def _agreeing_paths(self, twins: list[TwinPath], T_world_lh: Array, problem: GraphProblem
                        ) -> list[tuple[Array, Array, Array]]:
        return [chosen_path(tw, tw.emission + cross_station_cost(
            twins, T_world_lh, slot, self.cross_sigma_rad, self.cross_max_gap_s,
            self.turn_sigma) + partial_view_cost(twins, problem, T_world_lh, slot,
                                                 self.partial_sigma_rad,
                                                 self.partial_max_gap_s), self.turn_sigma)
            for slot, tw in enumerate(twins)]

    def _states(self, paths: list[tuple[Array, Array, Array]], T_world_lh: Array,
                problem: GraphProblem, overlap: list[int]) -> Initialisation:
        if not any(len(p[0]) for p in paths):
            raise SolverError("no station saw 4 diodes of the board on both axes within a "
                              "sweep or two: no planar pose to start from")
        paths = triangulated(paths, T_world_lh, self.max_gap_s)
        per_path = self.twist_per_path
        if per_path is None:
            per_path = any(m.generation == 2 for m in problem.models)
        X0, V0 = world_states(paths, T_world_lh, problem.state_time, self.velocity_span_s,
                              per_path)
        return Initialisation(T_world_lh, X0, V0, overlap)

    def _floored(self, paths: list[tuple[Array, Array, Array]]
                 ) -> list[tuple[Array, Array, Array]]:
        return [(t, T, np.maximum(rms, self.rms_floor_rad)) for t, T, rms in paths]
