"""Where the Crazyflie logs' short baseline comes from, and how good the mocap's reference is.

    python -m benchmarks scale_evidence [--output FILE] [--force]

Against the stations resected on each log's Qualisys path (benchmarks/anchored_stations.py)
our station 1 is 0.4-0.8 % too close to station 0. A receiver too small for its board file
would shrink everything alike; this looks at the parts. Per shared Crazyflie log, from our
default solve and the anchored stations (the marker body's lever solved):

1. **Ratios, ours over the mocap's**: each station's range to the receiver (median over the
   hits), the receiver path's spread (rms distance from its centroid) and the baseline
   (station 1's distance from station 0). One receiver scale error gives one ratio for all.
2. **The receiver's apparent size**: for two diodes hit in one sweep, the measured angle
   difference against the one predicted from the mocap's geometry (anchored stations, the
   mocap's positions) and from ours; the slope (robust least squares through zero, 5 MAD
   outliers dropped), with a standard error from 20 consecutive chunks. A slope of 1 + k at
   the mocap's ranges: the diodes sit a fraction k farther apart than the board file says
   (or every angle difference reads that much wide).
3. **An angle gain**: the gain ``g`` (a station reporting angles ``g`` times the model's)
   whose removal fits the anchored resection best, per station (lever held at its solved
   value; each gain's Cauchy cost over that station's hits at 3 median residuals, the
   minimum by a parabola through its neighbours). Light alone cannot pin a gain: it trades
   against the baseline.
4. **The reference's own spread**: station 1 (in station 0's frame) resected from each
   quarter of the log, against the whole log's; the whole's standard error,
   ``sqrt(sum |q_i - w|^2 / (Q (Q - 1)))``, and our difference from the reference in the
   combined sigma (our honest sigma along it and that standard error, summed in
   quadrature).
5. **What a gain would do**: every angle of the log divided by :data:`GAIN_TRIED` before
   our solve and the anchoring; station 1 against the anchored one, and the pair's
   difference.

Writes docs/results/scale_evidence.md. Data: Crazyflie (no licence: read from ../shared
only). ~4 min.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import replace
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import begin, write_results
from benchmarks.anchored_stations import (
    LOGS,
    PAIRS,
    AnchoringHits,
    anchored,
    anchoring_hits,
    cells,
    geometry,
    station_1,
)
from benchmarks.compare_pairs import DEG, solve_imported, solved_logs
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.layout_compare import compare_layouts
from lhgraph.estimation.resection import Resection, tracked_board_poses
from lhgraph.estimation.result import SolveResult
from lhgraph.geometry.transforms import rotation_angle
from lhgraph.io.angles import load_angles, save_angles
from lhgraph.io.stations import Station, Stations
from lhgraph.model.station import predict

GAINS = np.array([0.997, 1.0, 1.002, 1.004, 1.006, 1.008, 1.010])
GAIN_TRIED = 1.003
"""About the median of the gains the anchored resection prefers (section 3)."""
QUARTERS = 4
CHUNKS = 20
SAME_SWEEP_S = 1e-3
"""Hits of one station and axis closer than this in time belong to one sweep."""
DIODE_PAIRS = ((0, 2), (1, 3), (0, 1), (2, 3))
"""The deck's diode pairs compared: two along its 30 mm side, two along its 15 mm side."""


def ratios(hits: AnchoringHits, lever_m: np.ndarray, T_mocap_lh: dict[int, np.ndarray],
           result: SolveResult) -> list[float]:
    """Ours over the mocap's: each station's median range, the path's spread, the baseline."""
    p_mocap = tracked_board_poses(hits.T_mocap_tracked, lever_m)[:, :3, 3]
    p_ours = result.trajectory.at(hits.time)[:, :3, 3]
    out = [float(np.median(np.linalg.norm(p_ours - result.stations.pose(k)[:3, 3], axis=1)
                           / np.linalg.norm(p_mocap - T_mocap_lh[k][:3, 3], axis=1)))
           for k in sorted(T_mocap_lh)]

    def spread(p: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))

    baseline = np.linalg.norm(station_1(geometry(result.stations))[:3, 3]) / np.linalg.norm(
        station_1(T_mocap_lh)[:3, 3])
    return [*out, spread(p_ours) / spread(p_mocap), float(baseline)]


def sweep_pairs(hits: AnchoringHits) -> np.ndarray:
    """``(M, 2)`` indices of two hits of one sweep on the diode pairs :data:`DIODE_PAIRS`."""
    new = np.ones(len(hits.time), dtype=bool)
    new[1:] = ((np.diff(hits.time) >= SAME_SWEEP_S) | (np.diff(hits.station) != 0)
               | (np.diff(hits.axis) != 0))
    sweep = np.cumsum(new)
    found = []
    for i, j in DIODE_PAIRS:
        first = {s: n for n, s in zip(np.flatnonzero(hits.sensor == i),
                                       sweep[hits.sensor == i], strict=True)}
        found += [(first[sweep[n]], n) for n in np.flatnonzero(hits.sensor == j)
                  if sweep[n] in first]
    return np.array(found, dtype=int).reshape(-1, 2)


def robust_slope(measured: np.ndarray, predicted: np.ndarray) -> tuple[float, float]:
    """The slope through zero of ``measured`` on ``predicted`` (5 MAD outliers dropped,
    refitted five times) and its standard error from :data:`CHUNKS` consecutive chunks."""
    k = 1.0
    for _ in range(5):
        r = measured - k * predicted
        keep = np.abs(r - np.median(r)) < 5 * 1.4826 * np.median(np.abs(r - np.median(r)))
        k = float(measured[keep] @ predicted[keep] / (predicted[keep] @ predicted[keep]))
    chunks = [c for c in np.array_split(np.flatnonzero(keep), CHUNKS) if len(c)]
    ks = [measured[c] @ predicted[c] / (predicted[c] @ predicted[c]) for c in chunks]
    return k, float(np.std(ks, ddof=1) / np.sqrt(len(ks)))


def apparent_size(hits: AnchoringHits, solved: Resection, result: SolveResult
                  ) -> dict[tuple[str, int], tuple[float, float]]:
    """:func:`robust_slope` of the measured angle differences on the predicted ones, by
    ``("mocap" | "ours", station)``: the mocap's predictions are the anchored resection's
    (``solved``, of all of ``hits``: its residuals plus the measured angles), ours from the
    result's stations and path."""
    T_ours = result.trajectory.at(hits.time)
    ours = np.empty(len(hits.angle))
    for k in hits.models:
        m = hits.station == k
        ours[m] = predict(result.stations.pose(k), T_ours[m], hits.s_board[m], hits.axis[m],
                          hits.models[k])
    predicted = {"mocap": solved.residual_rad + hits.angle, "ours": ours}
    pairs = sweep_pairs(hits)
    measured = hits.angle[pairs[:, 1]] - hits.angle[pairs[:, 0]]
    out = {}
    for name, pred in predicted.items():
        diff = pred[pairs[:, 1]] - pred[pairs[:, 0]]
        for k in sorted(hits.models):
            sel = hits.station[pairs[:, 0]] == k
            out[(name, k)] = robust_slope(measured[sel], diff[sel])
    return out


def best_gains(hits: AnchoringHits, lever_m: np.ndarray) -> dict[int, float]:
    """Each station's angle gain that fits the anchored resection best (:data:`GAINS`,
    parabola through the least cost and its neighbours; at the grid's end, the end)."""
    residuals = [hits.resect(angle_gain=g, lever_m=lever_m).residual_rad for g in GAINS]
    scale = 3 * float(np.median(np.abs(residuals[GAINS.tolist().index(1.0)])))
    costs = {k: [] for k in hits.models}
    for r in residuals:
        for k in costs:
            costs[k].append(float(np.sum(np.log1p((r[hits.station == k] / scale) ** 2))))
    best = {}
    for k, c in costs.items():
        i = int(np.argmin(c))
        if 0 < i < len(GAINS) - 1:
            a, b, _ = np.polyfit(GAINS[i - 1:i + 2], c[i - 1:i + 2], 2)
            best[k] = float(-b / (2 * a))
        else:
            best[k] = float(GAINS[i])
    return best


def reference_spread(hits: AnchoringHits, lever_m: np.ndarray,
                     T_mocap_lh: dict[int, np.ndarray]) -> tuple[float, float, float, float]:
    """Station 1 from each quarter of the log against the whole log's: the largest position
    (m) and rotation (rad) difference, and the whole's standard errors (m, rad)."""
    whole = station_1(T_mocap_lh)
    edges = np.quantile(hits.time, np.linspace(0.0, 1.0, QUARTERS + 1))
    dp, dr = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        q = station_1(hits.resect((hits.time >= lo) & (hits.time <= hi),
                                  lever_m=lever_m).T_ref_lh)
        dp.append(float(np.linalg.norm(q[:3, 3] - whole[:3, 3])))
        dr.append(float(rotation_angle(q[:3, :3].T @ whole[:3, :3])))
    n = QUARTERS * (QUARTERS - 1)
    return (max(dp), max(dr), float(np.sqrt(np.sum(np.square(dp)) / n)),
            float(np.sqrt(np.sum(np.square(dr)) / n)))


def with_gain(work: Path, gain: float) -> tuple[np.ndarray, np.ndarray]:
    """Station 1 (station 0's frame), ours and anchored, from the imported log ``work`` with
    every angle divided by ``gain`` (in a copy beside it)."""
    copy = work.with_name(f"{work.name}-gain")
    shutil.copytree(work, copy)
    angles = load_angles(work / "angles.csv")
    save_angles(replace(angles, angle=angles.angle / gain), copy / "angles.csv",
                overwrite=True)
    result = solve_imported(copy, GraphOptions())
    return (station_1(geometry(result.stations)),
            station_1(anchored(copy, result.stations, result.trajectory).T_mocap_lh))


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "Where the short baseline comes from")
    lines += [f"{date.today()}; per shared Crazyflie log our default solve against the "
              "stations resected on its Qualisys path (benchmarks/scale_evidence.py, "
              "docs/crazyflie.md).", ""]
    ratio_rows, size_rows, gain_rows, spread_rows, tried_rows = [], [], [], [], []
    tried: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    with tempfile.TemporaryDirectory(prefix="lhgraph-scale-") as tmp:
        for log, work, result in solved_logs(LOGS, Path(tmp)):
            if work is None or result is None:
                ratio_rows.append(f"| {log} | skipped: data absent |" + " |" * 3)
                continue
            hits = anchoring_hits(work, result.stations, result.trajectory)
            solved = hits.resect(solve_lever=True)
            lever, T_ref = solved.lever_m, solved.T_ref_lh
            r = ratios(hits, lever, T_ref, result)
            ratio_rows.append(f"| {log} | " + " | ".join(f"{v:.4f}" for v in r) + " |")
            print(ratio_rows[-1], flush=True)
            size = apparent_size(hits, solved, result)
            size_rows.append(f"| {log} | " + " | ".join(
                f"{size[(n, k)][0]:.4f} ± {size[(n, k)][1]:.4f}"
                for n in ("mocap", "ours") for k in sorted(T_ref)) + " |")
            gains = best_gains(hits, lever)
            gain_rows.append(f"| {log} | " + " | ".join(f"{gains[k]:.4f}"
                                                       for k in sorted(gains)) + " |")
            max_dp, max_dr, se_p, se_r = reference_spread(hits, lever, T_ref)
            zero = np.zeros((6, 6))
            pinned = Stations(0, {k: Station(T, covariance=zero, covariance_white=zero)
                                  for k, T in T_ref.items()})
            d = compare_layouts(pinned, result.stations, reference=0).differences[0]
            spread_rows.append(
                f"| {log} | {max_dp * 1e3:.1f} | {max_dr * DEG:.3f} | {se_p * 1e3:.1f} | "
                f"{se_r * DEG:.3f} | {d.position_m * 1e3:.1f} | "
                f"{d.position_m / np.hypot(d.sigma_position_m, se_p):.1f} | "
                f"{d.rotation_rad * DEG:.3f} | {d.sigma_rotation_rad * DEG:.4f} | "
                f"{d.rotation_rad / d.sigma_rotation_rad:.1f} | "
                f"{d.rotation_rad / np.hypot(d.sigma_rotation_rad, se_r):.1f} |")
            tried[log] = with_gain(work, GAIN_TRIED)
            tried_rows.append(f"| {log} | {cells(*tried[log])} |")
    lines += ["## 1. Ours over the mocap's", "",
              "| log | station 0's range | station 1's range | path spread | baseline |",
              "|---|---|---|---|---|", *ratio_rows, "",
              "## 2. The receiver's apparent size (angle differences in one sweep)", "",
              "Slope of the measured differences on the predicted ones ± standard error.", "",
              "| log | mocap, station 0 | mocap, station 1 | ours, station 0 "
              "| ours, station 1 |", "|---|---|---|---|---|", *size_rows, "",
              "## 3. The angle gain the anchored resection prefers", "",
              "| log | station 0 | station 1 |", "|---|---|---|", *gain_rows, "",
              "## 4. The reference's own spread, and ours against it", "",
              f"Station 1 (station 0's frame) from each of {QUARTERS} quarters against the "
              "whole log; ours against the whole log's, in our honest sigma alone and "
              "combined with the reference's standard error.", "",
              "| log | largest quarter difference (mm) | (deg) | reference's standard error "
              "(mm) | (deg) | ours - anchored (mm) | in combined sigmas | ours - anchored "
              "(deg) | our honest sigma (deg) | in ours | in combined sigmas |",
              "|---|---|---|---|---|---|---|---|---|---|---|", *spread_rows, "",
              f"## 5. Every angle divided by {GAIN_TRIED}", "",
              "Station 1, ours - anchored (both from the divided angles): position (mm), "
              "along the baseline (mm), rotation (deg); then the pairs, ours.", "",
              "| log | position | along | rotation |", "|---|---|---|---|", *tried_rows]
    for a, b in PAIRS:
        if a in tried and b in tried:
            lines.append(f"| pair {a} / {b} | {cells(tried[a][0], tried[b][0])} |")
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
