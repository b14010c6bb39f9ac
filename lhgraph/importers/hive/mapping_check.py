"""Verification of the axis mapping on the data: single-station PnP of the tracker on sweep
pairs under each candidate :class:`~lhgraph.importers.hive.conventions.AxisMapping`
(:func:`check_mappings`); the right mapping fits with a small residual and every hit sensor
facing the station (docs/hive.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.init.pnp_nonplanar import single_station_pnp
from lhgraph.importers.hive.bag import HiveBag
from lhgraph.importers.hive.conventions import CANDIDATE_MAPPINGS, AxisMapping
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]


def sweep_pairs(bag: HiveBag, max_gap_s: float = 0.015) -> list[tuple[int, int]]:
    """Sweep numbers ``(h, v)`` of a horizontal sweep followed, within ``max_gap_s``, by a
    vertical sweep of the same station (one measurement of both angles)."""
    L = bag.light
    sweeps, first = np.unique(L["sweep"], return_index=True)
    st, ax, t = L["station"][first], L["hive_axis"][first], L["time"][first]
    nxt = np.arange(1, len(sweeps))
    ok = ((st[:-1] == st[nxt]) & (ax[:-1] == 0) & (ax[nxt] == 1)
          & (t[nxt] - t[:-1] < max_gap_s))
    return [(int(sweeps[i]), int(sweeps[i + 1])) for i in np.flatnonzero(ok)]


@dataclass(frozen=True)
class PairFit:
    """Single-station PnP fits of sweep pairs: ``station``, ``time`` (s, first sweep),
    ``T_lh_board`` (M, 4, 4), ``rms_rad`` over all hits of the pair and ``facing`` (fraction
    of the hit sensors whose normal faces the station in the fitted pose)."""

    station: NDArray[np.int64]
    time: Array
    T_lh_board: Array
    rms_rad: Array
    facing: Array


def fit_sweep_pairs(bag: HiveBag, pairs: list[tuple[int, int]], mapping: AxisMapping,
                    models: dict[int, StationModel] | None = None, n_starts: int = 16
                    ) -> PairFit:
    """Tracker pose in each station's frame for each sweep pair, by
    :func:`single_station_pnp` on all the pair's hits mapped with ``mapping``."""
    L = bag.light
    board = bag.board
    axis, angle = mapping.apply(L["hive_axis"], L["angle"])
    order = np.argsort(L["sweep"], kind="stable")
    sweeps, start = np.unique(L["sweep"][order], return_index=True)
    stop = np.r_[start[1:], len(order)]
    span = {int(s): order[a:b] for s, a, b in zip(sweeps, start, stop, strict=True)}
    M = len(pairs)
    out = PairFit(np.empty(M, dtype=np.int64), np.empty(M), np.full((M, 4, 4), np.nan),
                  np.full(M, np.nan), np.full(M, np.nan))
    for i, (h, v) in enumerate(pairs):
        rows = np.concatenate([span[h], span[v]])
        lh = int(L["station"][rows[0]])
        out.station[i], out.time[i] = lh, L["time"][rows[0]]
        if len(rows) < 7:
            continue
        k = board.index_of(L["sensor"][rows])
        model = (models or {}).get(lh)
        T, rms, facing = single_station_pnp(board.positions[k], board.normals[k], axis[rows],
                                            angle[rows], model, n_starts)
        out.T_lh_board[i], out.rms_rad[i], out.facing[i] = T, rms, facing
    return out


@dataclass(frozen=True)
class MappingCheck:
    """Per candidate mapping: median PnP rms (rad), mean facing fraction, median distance (m)
    and fraction of fits in front of the station."""

    mapping: AxisMapping
    median_rms_rad: float
    facing: float
    median_distance_m: float


def check_mappings(bag: HiveBag, n_pairs: int = 40, min_hits: int = 12, seed: int = 0,
                   mappings: tuple[AxisMapping, ...] = CANDIDATE_MAPPINGS
                   ) -> list[MappingCheck]:
    """Score candidate axis mappings by single-station PnP on ``n_pairs`` random sweep pairs
    with at least ``min_hits`` hits (ideal model, board from the bag)."""
    L = bag.light
    counts = np.bincount(L["sweep"])
    pairs = [p for p in sweep_pairs(bag) if counts[p[0]] + counts[p[1]] >= min_hits]
    rng = np.random.default_rng(seed)
    pick = sorted(rng.choice(len(pairs), min(n_pairs, len(pairs)), replace=False))
    pairs = [pairs[i] for i in pick]
    out = []
    for m in mappings:
        f = fit_sweep_pairs(bag, pairs, m)
        ok = np.isfinite(f.rms_rad)
        out.append(MappingCheck(m, float(np.median(f.rms_rad[ok])), float(np.mean(f.facing[ok])),
                                float(np.median(np.linalg.norm(f.T_lh_board[ok, :3, 3],
                                                               axis=1)))))
    return out
