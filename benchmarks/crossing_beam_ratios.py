"""Crossing-beam accuracy on every shared Crazyflie log: our geometry against cfclient's.

Issue #39's accuracy target: on each shared Bitcraze log the median crossing-beam position
error with our station geometry, divided by the median with cfclient's own geometry (the
log's ``system-config.yaml``), at most 0.5. Each log is imported (``lhgraph import
crazyflie``) and solved with the default graph method and its factory calibration (the
Python API, as ``lhgraph solve``); the log's ``correctedAngle`` (the deck firmware's
factory-corrected angles) becomes crossing-beam positions through each geometry, judged
against the log's Qualisys recording after the best rigid fit and time search
(``crazyflie_evaluation``'s measure (b)).

A second fit, the best similarity (rotation, translation and one scale; Umeyama's closed
form at the rigid fit's time offsets), reports the scale by which the mocap's positions
exceed the geometry's and the median error left after it: a geometry whose size is wrong
shows a scale away from 1 and an error that drops once it is allowed. The last column is an
oracle: the log solved again with the deck's sensor positions multiplied by that scale (what
a receiver scale known from elsewhere, e.g. an accelerometer, would give at best), judged by
the rigid fit. Data: Crazyflie (no licence: read from ../shared only). ~1 min.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import dataclass
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks.compare_pairs import imported_logs, solve_imported
from benchmarks.crazyflie_evaluation import _mocap_at, aligned_errors, crossing_beam_positions
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.io.angles import load_angles
from lhgraph.io.files import read_csv_columns
from lhgraph.io.stations import Stations, load_stations
from lhgraph.model.board import load_board, make_board, save_board
from lhgraph.workflow.solve import run_config
from lhgraph.workflow.solve_config import SolveConfig

ROOT = Path(__file__).resolve().parents[1]
LOGS = ("lh1_crossingBeam_move/log02", "lh1_crossingBeam_flight/log00",
        "lh2_crossingBeam_move/log00", "lh2_crossingBeam_move/log01")
TARGET_RATIO = 0.5


def similarity_fit(p: np.ndarray, q: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares ``q ~ s R p + t`` of matched points ``(N, 3)`` (Umeyama): ``(s, R, t)``."""
    mp, mq = p.mean(axis=0), q.mean(axis=0)
    P, Q = p - mp, q - mq
    U, S, Vt = np.linalg.svd(Q.T @ P / len(p))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / np.mean(np.sum(P**2, axis=1)))
    return s, R, mq - s * R @ mp


@dataclass(frozen=True)
class MocapFrame:
    """An imported log's Qualisys recording aligned to a geometry: the mocap samples' log
    ``time`` (s, shifted by the best start and end offsets) and ``position`` (N, 3, m,
    Qualisys frame); the best rigid fit ``T_mocap_world`` of the geometry's crossing-beam
    positions ``beam_time``, ``beam_position`` (world) onto the mocap; ``rigid_errors`` (m)
    after it."""

    time: np.ndarray
    position: np.ndarray
    T_mocap_world: np.ndarray
    beam_time: np.ndarray
    beam_position: np.ndarray
    rigid_errors: np.ndarray


def mocap_frame(work: Path, stations: Stations) -> MocapFrame:
    """The imported log ``work``'s mocap aligned in time and space to ``stations`` through the
    log's correctedAngle as crossing-beam positions (``crazyflie_evaluation``'s measure
    (b))."""
    angles = load_angles(work / "angles.csv")
    mocap = read_csv_columns(work / "mocap.csv",
                             [("time", float), ("x", float), ("y", float), ("z", float)])
    t_m = mocap["time"]
    p_m = np.stack([mocap["x"], mocap["y"], mocap["z"]], axis=1)
    t, p = crossing_beam_positions(angles, stations)
    e, d0, d1 = aligned_errors(t, p, t_m, p_m)
    shifted = t_m + d0 + (d1 - d0) * (t_m - t_m[0]) / (t_m[-1] - t_m[0])
    q = _mocap_at(shifted, p_m, t)
    ok = np.all(np.isfinite(q), axis=1)
    return MocapFrame(shifted, p_m, weighted_kabsch(p[ok], q[ok]), t, p, e)


def judged(work: Path, stations: Stations) -> dict[str, float]:
    """Median crossing-beam error (mm) of ``stations`` on the imported log ``work`` after
    the best rigid fit, and the similarity fit's scale and median error (mm)."""
    m = mocap_frame(work, stations)
    q = _mocap_at(m.time, m.position, m.beam_time)
    ok = np.all(np.isfinite(q), axis=1)
    p = m.beam_position
    s, R, tr = similarity_fit(p[ok], q[ok])
    es = np.linalg.norm(s * p[ok] @ R.T + tr - q[ok], axis=1)
    return {"rigid_mm": float(np.median(m.rigid_errors)) * 1e3, "scale": s,
            "similarity_mm": float(np.median(es)) * 1e3}


def solved_with_scaled_board(work: Path, scale: float) -> Stations:
    """The imported log ``work`` solved (default graph method, its factory calibration) with
    the board's sensor positions multiplied by ``scale``."""
    board = load_board(work / "board.toml")
    scaled = save_board(make_board(board.positions * scale, board.normals, board.ids),
                        work / "board-scaled.toml", overwrite=True)
    return run_config(SolveConfig(board=scaled, angles=work / "angles.csv",
                                  calibration=work / "ootx.toml")).stations


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks crossing_beam_ratios",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path,
                        default=ROOT / "docs" / "results" / "crossing_beam_ratios.md")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    lines = ["# Crossing-beam accuracy on every shared Crazyflie log", "",
             "Command: `python -m benchmarks crossing_beam_ratios`  ",
             f"{date.today()}; each log imported and solved with the default graph method; "
             "median crossing-beam error (mm, the log's correctedAngle) after the best rigid "
             "fit to the Qualisys positions; the ratio ours / cfclient's (target "
             f"<= {TARGET_RATIO}); the similarity fit's scale (mocap / geometry) and the "
             "median error left after it; ours solved with the deck scaled by that scale "
             "(oracle).", "",
             "| log | cfclient mm | ours mm | ratio | cfclient scale | ours scale "
             "| cfclient after scale mm | ours after scale mm | ours, deck scaled (oracle) mm "
             "| its ratio |", "|---|---|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="lhgraph-beams-") as tmp:
        for log, work in imported_logs(LOGS, Path(tmp)):
            if work is None:
                lines.append(f"| {log} | skipped: data absent | | | | | | | | |")
                continue
            theirs = judged(work, load_stations(work / "stations-cfclient.toml"))
            ours = judged(work, solve_imported(work, GraphOptions()).stations)
            oracle = judged(work, solved_with_scaled_board(work, ours["scale"]))["rigid_mm"]
            lines.append(
                f"| {log} | {theirs['rigid_mm']:.1f} | {ours['rigid_mm']:.1f} | "
                f"{ours['rigid_mm'] / theirs['rigid_mm']:.2f} | {theirs['scale']:.4f} | "
                f"{ours['scale']:.4f} | {theirs['similarity_mm']:.1f} | "
                f"{ours['similarity_mm']:.1f} | {oracle:.1f} | "
                f"{oracle / theirs['rigid_mm']:.2f} |")
            print(lines[-1], flush=True)
    lines += ["", f"Run time: {(time.perf_counter() - start) / 60:.1f} min.", ""]
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
