"""The motion prior's strength against the shared recordings: is the adapted prior where the
real data wants it, and is the Crazyflie logs' short baseline its doing?

    python -m benchmarks motion_prior_scan [--output FILE] [--force]

The graph links consecutive receiver states by a white-noise-acceleration prior whose power
spectral densities (``accel_psd_pos`` m^2/s^3, ``accel_psd_rot`` rad^2/s^3) the solve adapts
to the solved motion (docs/graph.md; on few-diode data by the prior's redundancy, with no
floor). A prior too tight smooths the path: a shrunk path with the same angles puts the
stations closer, the signature of the short baseline (docs/crazyflie.md). So each shared log
is solved with the adapted prior and with fixed ones (``accel_psd_pos`` = 0.1, 1, 10, 100,
``accel_psd_rot`` ten times that; adaptation off):

1. every Crazyflie log: station 1 (in station 0's frame) against the stations resected on
   the log's Qualisys path (benchmarks/anchored_stations.py): position difference (mm), its
   part along the baseline (mm, negative: too short), rotation difference (deg);
2. every same-generation pair, and hive's data8.11 / data8.17: station 1's difference
   between the two recordings at each prior (mm, deg).

Writes docs/results/motion_prior_scan.md. Data: Crazyflie, hive (no licence: read from
../shared only). ~4 min.
"""

from __future__ import annotations

import tempfile
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import begin, write_results
from benchmarks.anchored_stations import LOGS, PAIRS, anchored, difference, geometry, station_1
from benchmarks.compare_pairs import DATA, imported, solve_imported, solved_logs
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.result import SolveResult

FIXED_PSD_POS = (0.1, 1.0, 10.0, 100.0)
"""The fixed linear PSDs tried (m^2/s^3); the angular one is ten times each (rad^2/s^3), the
ratio of the defaults."""
HIVE_BAGS = ("hive-env8/data8.11.bag", "hive-env8/data8.17.bag")


def priors() -> dict[str, GraphOptions]:
    """The graph options of each prior tried, by its label: the adapted default first."""
    out = {"adapted": GraphOptions()}
    for q in FIXED_PSD_POS:
        out[f"{q:g}"] = GraphOptions().with_values(adapt_motion_prior=False, accel_psd_pos=q,
                                                   accel_psd_rot=10.0 * q)
    return out


def cell(A: np.ndarray, B: np.ndarray) -> str:
    """Poses ``A - B`` as one cell: position (mm) / along the baseline (mm) / rotation
    (deg), :func:`~benchmarks.anchored_stations.difference`."""
    dp, along, dr = difference(A, B)
    return f"{dp:.1f} / {along:+.1f} / {dr:.3f}"


def adapted_psd(result: SolveResult) -> str:
    """The linear PSD a solve used (m^2/s^3), as a cell."""
    return f"{result.diagnostics['accel_psd_pos']:.3g}"


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "The motion prior's strength on the shared recordings")
    lines += [f"{date.today()}; station 1 in station 0's frame; priors: the adapted default "
              "and fixed ones (`accel_psd_pos` m^2/s^3, `accel_psd_rot` ten times it, "
              "adaptation off); benchmarks/motion_prior_scan.py.", "",
              "## 1. Against the mocap-anchored stations", "",
              "ours - anchored: position (mm) / along the baseline (mm) / rotation (deg).", "",
              "| log | anchored distance (m) | adapted psd_pos | adapted | "
              + " | ".join(f"psd_pos {q:g}" for q in FIXED_PSD_POS) + " |",
              "|---|---|---|---|" + "---|" * len(FIXED_PSD_POS)]
    ours: dict[tuple[str, str], np.ndarray] = {}
    options = priors()
    with tempfile.TemporaryDirectory(prefix="lhgraph-psd-") as tmp:
        for log, work, result in solved_logs(LOGS, Path(tmp)):
            if work is None or result is None:
                lines.append(f"| {log} | skipped: data absent |" + " |" * (1 + len(options)))
                continue
            ref = station_1(anchored(work, result.stations, result.trajectory).T_mocap_lh)
            row = [log, f"{np.linalg.norm(ref[:3, 3]):.4f}", adapted_psd(result)]
            for label, o in options.items():
                solved = result if label == "adapted" else solve_imported(work, o)
                ours[log, label] = station_1(geometry(solved.stations))
                row.append(cell(ours[log, label], ref))
            lines.append("| " + " | ".join(row) + " |")
            print(lines[-1], flush=True)
        lines += ["", "## 2. Pairs of recordings of unmoved stations", "",
                  "Station 1's difference between the two recordings (first - second): "
                  "position (mm) / along the baseline (mm) / rotation (deg).", "",
                  "| pair | " + " | ".join(options) + " |", "|---|" + "---|" * len(options)]
        for a, b in PAIRS:
            if all((a, label) in ours and (b, label) in ours for label in options):
                lines.append(f"| {a} / {b} | " + " | ".join(
                    cell(ours[a, label], ours[b, label])
                    for label in options) + " |")
        if all((DATA / bag).exists() for bag in HIVE_BAGS):
            folders = [imported("hive", DATA / bag, Path(tmp) / f"hive{i}")
                       for i, bag in enumerate(HIVE_BAGS)]
            cols, psds = [], []
            for o in options.values():
                solved = [solve_imported(f, o) for f in folders]
                psds.append(adapted_psd(solved[0]) + ", " + adapted_psd(solved[1]))
                cols.append(cell(*(station_1(geometry(s.stations)) for s in solved)))
            lines.append(f"| {HIVE_BAGS[0]} / {HIVE_BAGS[1]} | " + " | ".join(cols) + " |")
            motion = GraphOptions().motion
            lines += ["", f"hive's adapted psd_pos: {psds[0]} (the floor, `min_psd_factor` "
                      f"times the default: {motion.min_psd_factor * motion.accel_psd_pos:g})."]
        else:
            lines.append("| hive data8.11 / data8.17 | skipped: data absent |"
                         + " |" * (len(options) - 1))
        print("\n".join(lines[-4:]), flush=True)
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
