"""The shared Crazyflie logs' stations anchored to their Qualisys recordings: a reference
geometry that owes nothing to our receiver path, and every geometry judged against it.

    python -m benchmarks anchored_stations [--output FILE] [--force]

Pairs of recordings of unmoved stations say whether two solves agree, not which is right.
Each Bitcraze log also records the deck's position with Qualisys, so each station can be
resected from a known path (:mod:`lhgraph.estimation.resection`): the board's position at
every hit is the mocap's (less the marker body's lever, solved with the stations), its
orientation ours (the graph's path, rotated into the Qualisys frame by the rigid fit of the
crossing-beam positions: a degree of orientation error moves a diode 15 mm from the centre by
0.3 mm), and each station's six pose parameters are fitted to its angles with the decoded
factory model, nothing else estimated. Per log:

1. the fit: hits used, median absolute residual; station 1's distance from station 0;
2. our default solve (`lhgraph solve`'s graph) and cfclient's geometry (the log's
   `system-config.yaml`) against the anchored one: station 1 in station 0's frame, the
   position difference (mm), its part along the baseline (mm; negative: too short) and the
   rotation difference (deg);
3. the marker body's lever (board frame) and how far station 1 moves when it is held at
   zero (the marker body's origin taken as the deck's centre);
4. the stations' heights above the receiver's first mocap sample, Qualisys z as up (the
   height a z-up export whose origin is the receiver at its first rest should give).

Then per same-generation pair, station 1's difference between the two logs, anchored and
ours. Writes docs/results/anchored_stations.md. Data: Crazyflie (no licence: read from
../shared only). ~2 min.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, replace
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import begin, write_results
from benchmarks.compare_pairs import DEG, solved_logs
from benchmarks.crazyflie_evaluation import _mocap_at
from benchmarks.crossing_beam_ratios import mocap_frame
from lhgraph.estimation.layout_compare import compare_layouts
from lhgraph.estimation.receiver_scale import receiver_scale_covariance
from lhgraph.estimation.resection import Resection, resect_stations, tracked_board_poses
from lhgraph.estimation.result import SolveResult
from lhgraph.geometry.transforms import inverse, rotation_angle
from lhgraph.io.angles import load_angles
from lhgraph.io.stations import Station, Stations, load_stations, save_stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import load_board

LOGS = ("lh1_crossingBeam_move/log02", "lh1_crossingBeam_flight/log00",
        "lh2_crossingBeam_move/log00", "lh2_crossingBeam_move/log01")
PAIRS = (("lh1_crossingBeam_move/log02", "lh1_crossingBeam_flight/log00"),
         ("lh2_crossingBeam_move/log00", "lh2_crossingBeam_move/log01"))


@dataclass(frozen=True)
class Anchored:
    """One log's stations resected in the Qualisys frame: ``T_mocap_lh`` by station with the
    marker body's lever solved (``lever_m``, its origin in the board frame, m), and
    ``T_mocap_lh_held`` with it held at the deck's centre; the hits used and their median
    absolute residual (rad, lever solved), also by ``(station, axis)``; the mocap's first
    sample (m)."""

    T_mocap_lh: dict[int, np.ndarray]
    T_mocap_lh_held: dict[int, np.ndarray]
    lever_m: np.ndarray
    hits: int
    median_residual_rad: float
    first_sample_m: np.ndarray
    median_residual_by_axis_rad: dict[tuple[int, int], float]


@dataclass(frozen=True)
class AnchoringHits:
    """An imported log's hits where the mocap saw the receiver, ready to resect: the tracked
    point's poses ``T_mocap_tracked`` (N, 4, 4; the mocap's position, the path's
    orientation rotated into the Qualisys frame), each hit's diode ``s_board`` (N, 3, board
    frame, m), its station, axis and angle (rad), the stations' factory models and their
    starting poses (Qualisys frame), and the mocap's first sample (m); the hits' ``time``
    (s) and ``sensor`` index."""

    T_mocap_tracked: np.ndarray
    s_board: np.ndarray
    station: np.ndarray
    axis: np.ndarray
    angle: np.ndarray
    models: dict
    starts: dict[int, np.ndarray]
    first_sample_m: np.ndarray
    time: np.ndarray
    sensor: np.ndarray

    def resect(self, select: np.ndarray | slice = slice(None), angle_gain: float = 1.0,
               solve_lever: bool = False, lever_m: np.ndarray | None = None) -> Resection:
        """The stations resected from the hits ``select``, their angles divided by
        ``angle_gain`` (a station that reports angles that much too wide); the lever solved,
        held at ``lever_m`` (board frame, m) or, neither given, at zero."""
        T = self.T_mocap_tracked[select]
        if lever_m is not None:
            T = tracked_board_poses(T, lever_m)
        return resect_stations(T, self.s_board[select],
                               self.station[select], self.axis[select],
                               self.angle[select] / angle_gain, self.models, self.starts,
                               solve_lever=solve_lever)


def anchoring_hits(work: Path, stations: Stations, path: Trajectory) -> AnchoringHits:
    """The imported log ``work``'s hits to resect on its mocap path; the alignment from
    ``stations`` (a solve of the log, with its factory models), the board's orientations from
    ``path`` (theirs, solved or tracked)."""
    frame = mocap_frame(work, stations)
    angles = load_angles(work / "angles.csv")
    p = _mocap_at(frame.time, frame.position, angles.time)
    seen = np.all(np.isfinite(p), axis=1)
    a = angles.select(seen)
    T = frame.T_mocap_world @ path.at(a.time)
    T[:, :3, 3] = p[seen]
    return AnchoringHits(T, load_board(work / "board.toml").positions[a.sensor], a.lighthouse,
                         a.axis, a.angle, {k: stations.stations[k].model
                                           for k in stations.indices()},
                         {k: frame.T_mocap_world @ stations.pose(k)
                          for k in stations.indices()},
                         frame.position[np.argmin(frame.time)], a.time, a.sensor)


def anchored(work: Path, stations: Stations, path: Trajectory) -> Anchored:
    """The imported log ``work``'s stations resected on its mocap path (:func:`anchoring_hits`
    for the arguments)."""
    hits = anchoring_hits(work, stations, path)
    solved = hits.resect(solve_lever=True)
    held = hits.resect()
    by_axis = {(int(k), int(a)): float(np.median(np.abs(
        solved.residual_rad[(hits.station == k) & (hits.axis == a)])))
        for k, a in sorted(set(zip(hits.station.tolist(), hits.axis.tolist(), strict=True)))}
    return Anchored(solved.T_ref_lh, held.T_ref_lh, solved.lever_m, len(hits.angle),
                    solved.median_abs_residual_rad, hits.first_sample_m, by_axis)


def save_anchored(work: Path, stations: Stations, path: Trajectory) -> tuple[Anchored, Path]:
    """The imported log ``work``'s anchored stations (:func:`anchored`, lever solved) and the
    stations TOML ``work/stations-anchored.toml`` (Qualisys frame, ``stations``' models) they
    were written to."""
    ref = anchored(work, stations, path)
    written = save_stations(Stations(0, {k: Station(T, model=stations.stations[k].model)
                                         for k, T in ref.T_mocap_lh.items()}),
                            work / "stations-anchored.toml", overwrite=True)
    return ref, written


def station_1(T: dict[int, np.ndarray]) -> np.ndarray:
    """Station 1's pose in station 0's frame."""
    return inverse(T[0]) @ T[1]


def difference(A: np.ndarray, B: np.ndarray) -> tuple[float, float, float]:
    """Poses ``A - B``: position (mm), its part along ``B``'s baseline from the origin (mm),
    rotation (deg)."""
    d = A[:3, 3] - B[:3, 3]
    u = B[:3, 3] / np.linalg.norm(B[:3, 3])
    return (float(np.linalg.norm(d)) * 1e3, float(d @ u) * 1e3,
            float(rotation_angle(A[:3, :3].T @ B[:3, :3])) * DEG)


def cells(A: np.ndarray, B: np.ndarray) -> str:
    """``difference(A, B)`` as three table cells."""
    dp, along, dr = difference(A, B)
    return f"{dp:.1f} | {along:+.1f} | {dr:.3f}"


def geometry(stations: Stations) -> dict[int, np.ndarray]:
    """``T_world_lh`` by station."""
    return {k: stations.pose(k) for k in stations.indices()}


def in_sigmas(log: str, ref: Anchored, result: SolveResult) -> str:
    """A table row: ``result``'s stations against the anchored stations ``ref`` in the
    result's own sigmas (:func:`~lhgraph.estimation.layout_compare.compare_layouts`, the
    anchored stations given no uncertainty of their own), also with the honest covariance
    less its receiver-scale share."""
    zero = np.zeros((6, 6))
    pinned = Stations(0, {k: Station(T, covariance=zero, covariance_white=zero)
                          for k, T in ref.T_mocap_lh.items()})
    ours = result.stations
    d = compare_layouts(pinned, ours, reference=0).differences[0]
    scale = (result.options or {}).get("uncertainty", {}).get("receiver_scale_sigma") or 0.0
    blocks = Stations(ours.reference, {k: replace(s, covariance=s.covariance
                                                  - receiver_scale_covariance(s.T_world_lh,
                                                                              scale))
                                       for k, s in ours.stations.items()})
    b = compare_layouts(pinned, blocks, reference=0).differences[0]
    return (f"| {log} | {d.position_m * 1e3:.1f} | {d.sigma_position_m * 1e3:.2f} | "
            f"{d.position_sigmas:.1f} | {scale:g} | {b.sigma_position_m * 1e3:.2f} | "
            f"{b.position_sigmas:.1f} | {d.sigma_white_position_m * 1e3:.2f} | "
            f"{d.position_m / d.sigma_white_position_m:.0f} | {d.rotation_rad * DEG:.3f} | "
            f"{d.sigma_rotation_rad * DEG:.4f} | {d.rotation_sigmas:.1f} |")


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "The Crazyflie logs' stations anchored to the mocap")
    lines += [f"{date.today()}; each station resected on the log's Qualisys path "
             "(benchmarks/anchored_stations.py, docs/crazyflie.md); station 1 in station 0's "
             "frame; differences: position (mm), its part along the baseline (mm, negative: "
             "too short), rotation (deg).", "",
             "| log | hits | median residual (µrad) | anchored distance (m) "
             "| ours - anchored | | | cfclient - anchored | | | marker lever (mm) "
             "| lever held at 0: shift (mm) | heights, anchored (m) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    sigmas: list[str] = []
    ours_by_log: dict[str, np.ndarray] = {}
    anchored_by_log: dict[str, np.ndarray] = {}
    with tempfile.TemporaryDirectory(prefix="lhgraph-anchored-") as tmp:
        for log, work, result in solved_logs(LOGS, Path(tmp)):
            if work is None or result is None:
                lines.append(f"| {log} | skipped: data absent |" + " |" * 11)
                continue
            ref = anchored(work, result.stations, result.trajectory)
            truth = station_1(ref.T_mocap_lh)
            ours = station_1(geometry(result.stations))
            theirs = station_1(geometry(load_stations(work / "stations-cfclient.toml")))
            ours_by_log[log], anchored_by_log[log] = ours, truth
            shift = np.linalg.norm(station_1(ref.T_mocap_lh_held)[:3, 3] - truth[:3, 3]) * 1e3
            lever = ", ".join(f"{v * 1e3:+.0f}" for v in ref.lever_m)
            heights = " / ".join(f"{T[2, 3] - ref.first_sample_m[2]:.3f}"
                                 for _, T in sorted(ref.T_mocap_lh.items()))
            lines.append(f"| {log} | {ref.hits} | {ref.median_residual_rad * 1e6:.0f} | "
                         f"{np.linalg.norm(truth[:3, 3]):.4f} | {cells(ours, truth)} | "
                         f"{cells(theirs, truth)} | {lever} | {shift:.1f} | {heights} |")
            print(lines[-1], flush=True)
            sigmas.append(in_sigmas(log, ref, result))
    lines += ["", "## Ours against the anchored stations in our own sigmas", "",
              "Station 1 (in station 0's frame): the difference over the sigma our result "
              "reports along it, honest (the verdict's; with the receiver scale's share of "
              "the resolved `receiver_scale_sigma`, and without it) and white "
              "(docs/uncertainty.md).", "",
              "| log | position (mm) | honest sigma (mm) | in honest sigmas "
              "| receiver_scale_sigma | honest less the scale's share (mm) | in those sigmas "
              "| white sigma (mm) | in white sigmas | rotation (deg) | honest sigma (deg) "
              "| in honest sigmas |", "|---|---|---|---|---|---|---|---|---|---|---|---|",
              *sigmas]
    lines += ["", "## Pairs of logs of unmoved stations", "",
              "Station 1's difference between the two logs (first - second).", "",
              "| pair | anchored | | | ours | | |", "|---|---|---|---|---|---|---|"]
    for a, b in PAIRS:
        if a in anchored_by_log and b in anchored_by_log:
            lines.append(f"| {a} / {b} | {cells(anchored_by_log[a], anchored_by_log[b])} | "
                         f"{cells(ours_by_log[a], ours_by_log[b])} |")
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
