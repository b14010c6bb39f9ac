"""The factory terms' own uncertainty in the station covariance ("consider" covariance): would
it make the honest sigma cover the shared pairs of recordings of unmoved stations?

    python -m benchmarks consider_covariance [--sigma-mrad S] [--output FILE] [--force]

Issue #39's item 3 asks the sigma to account for the model parameters' own uncertainty. The
stations are solved with the decoded (OOTX) factory terms held; a term wrong by its prior
spread moves them. Per recording of compare_pairs' pairs (imported and solved as there):

1. station 1's sensitivity to each factory term ``K = d(station 1 pose) / d(term)`` (6 per
   term and axis, tangent ``[rotation, translation]`` in its own frame), by a forward
   difference of 1 mrad: the log solved again with that term of one station (the
   reference's too: its terms turn the frame the other is seen in) moved, started from the
   first solution, white covariance;
2. the consider covariance ``C = C_honest + K S K^T`` with ``S`` the terms' prior
   (``--sigma-mrad``, default the graph's ``factory_sigma_rad``, independent per term,
   axis and station): the sigma a result would report if the terms were uncertain by that
   much and not solved;
3. the pair's difference in combined honest and combined consider sigmas
   (:func:`lhgraph.estimation.layout_compare.compare_layouts`).

Terms: phase, tilt, curve and gibmag of both axes (gibphase is an angle whose error matters
only through gibmag). Writes docs/results/consider_covariance.md. Data: Crazyflie, hive (no
licence: read from ../shared only). ~10 min on the 2-core machine.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import tempfile
import time
from dataclasses import replace
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import command, results_parser, write_results
from benchmarks.compare_pairs import DATA, DEG, PAIRS, imported, solve_imported
from lhgraph.estimation.graph.families.factory import with_term_deltas
from lhgraph.estimation.graph.options import FactoryOptions, GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.layout_compare import compare_layouts
from lhgraph.estimation.station_watch import CalibrationStart
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.angles import load_angles
from lhgraph.io.files import check_writable
from lhgraph.io.stations import Stations
from lhgraph.model.board import load_board
from lhgraph.model.calibration import load_calibration
from lhgraph.workflow.inputs import models_of

TERMS = ("phase", "tilt", "curve", "gibmag")
STEP_RAD = 1e-3
STATION = 1


def sensitivity(folder: Path) -> tuple[Stations, np.ndarray, list[str]]:
    """The imported log ``folder`` solved (default options, honest covariance) and station
    1's sensitivity ``K`` (6, n) to each term, axis and station (column labels)."""
    board, angles = load_board(folder / "board.toml"), load_angles(folder / "angles.csv")
    models = models_of(load_calibration(folder / "ootx.toml"))
    honest = solve_imported(folder, GraphOptions()).stations
    white = GraphOptions().with_values(covariance="white")
    base = solve_graph(board, angles, models, white)
    start = CalibrationStart(base.stations, base.stations.reference, base.trajectory.time,
                             base.trajectory.T_world_board)
    T0 = base.stations.pose(STATION)
    columns, labels = [], []
    for k in sorted(models):
        for term in TERMS:
            for axis in (0, 1):
                delta = np.zeros(2)
                delta[axis] = STEP_RAD
                moved = dict(models)
                moved[k] = with_term_deltas(models[k], (term,), delta)
                r = solve_graph(board, angles, moved, white, initialiser=start)
                columns.append(se3_log(inverse(T0) @ r.stations.pose(STATION)) / STEP_RAD)
                labels.append(f"{k}.{term}[{axis}]")
    return honest, np.stack(columns, axis=1), labels


def with_consider(stations: Stations, K: np.ndarray, sigma_rad: float) -> Stations:
    """``stations`` with station 1's covariance widened by ``K S K^T``."""
    s = stations.stations[STATION]
    C = s.covariance + sigma_rad**2 * K @ K.T
    return replace(stations, stations={**stations.stations, STATION: replace(s, covariance=C)})


def sigma_for(results: list[tuple[Stations, np.ndarray]], target: float = 2.0
              ) -> tuple[str, str]:
    """The terms' spread (mrad) at which the pair's station-1 difference is ``target``
    combined consider sigmas, in position and in rotation ("" when the honest sigma alone
    covers it), the smallest of a log grid from 0.01 to 30 mrad that does."""
    grid = np.geomspace(1e-5, 3e-2, 200)
    ratios = []
    for sigma in grid:
        d = next(x for x in compare_layouts(*(with_consider(h, K, sigma) for h, K in results)
                                            ).differences if x.station == STATION)
        ratios.append((d.position_sigmas, d.rotation_sigmas))
    cells = []
    for j in (0, 1):
        r = np.array([x[j] for x in ratios])
        if r[0] <= target:
            cells.append("")
            continue
        i = int(np.argmax(r <= target))
        cells.append(f"{grid[i] * 1e3:.2f}" if r[i] <= target else "> 30")
    return cells[0], cells[1]


def main(argv: list[str] | None = None) -> int:
    parser = results_parser(__file__, __doc__)
    parser.add_argument("--sigma-mrad", type=float,
                        default=FactoryOptions().factory_sigma_rad * 1e3,
                        help="the factory terms' prior spread (mrad)")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    sigma = args.sigma_mrad * 1e-3
    start = time.perf_counter()
    rows, top = [], []
    with tempfile.TemporaryDirectory(prefix="lhgraph-consider-") as tmp:
        for n, (name, logs) in enumerate(PAIRS.items()):
            if not all((DATA / path).exists() for _, path in logs):
                rows.append(f"| {name} | skipped: data absent | | | | | | |")
                continue
            results = []
            for i, (kind, path) in enumerate(logs):
                honest, K, labels = sensitivity(imported(kind, DATA / path,
                                                         Path(tmp) / f"{n}{i}"))
                results.append((honest, K))
                share = np.sum((K[3:] * sigma) ** 2, axis=0)
                worst = np.argsort(share)[::-1][:3]
                top.append(f"| {path} | " + ", ".join(
                    f"{labels[j]} {np.sqrt(share[j]) * 1e3:.1f}" for j in worst)
                    + f" | {np.sqrt(share.sum()) * 1e3:.1f} |")
                print(top[-1], flush=True)
            plain = compare_layouts(results[0][0], results[1][0])
            wide = compare_layouts(*(with_consider(h, K, sigma) for h, K in results))
            d = next(x for x in plain.differences if x.station == STATION)
            c = next(x for x in wide.differences if x.station == STATION)
            rows.append(f"| {name} | {d.position_m * 1e3:.1f} / {d.rotation_rad * DEG:.3f} | "
                        f"{d.sigma_position_m * 1e3:.2f} / {d.sigma_rotation_rad * DEG:.4f} | "
                        f"{d.position_sigmas:.1f} / {d.rotation_sigmas:.1f} | "
                        f"{c.sigma_position_m * 1e3:.2f} / {c.sigma_rotation_rad * DEG:.4f} | "
                        f"{c.position_sigmas:.1f} / {c.rotation_sigmas:.1f} | "
                        + " / ".join(x or "-" for x in sigma_for(results)) + " |")
            print(rows[-1], flush=True)
    lines = ["# The factory terms' uncertainty in the station covariance", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"{date.today()}; terms {', '.join(TERMS)} of both axes and stations, each "
             f"uncertain by {args.sigma_mrad:g} mrad (1 sigma, independent); station 1 in "
             "the reference's frame; combined sigmas of the two recordings.", "",
             "## Pairs of recordings of unmoved stations", "",
             "| pair | difference (mm / deg) | honest sigma | in honest sigmas "
             "| consider sigma | in consider sigmas | terms' spread giving 2 sigmas, "
             "position / rotation (mrad) |", "|---|---|---|---|---|---|---|", *rows, "",
             "## The terms that move station 1 most", "",
             f"Position sigma (mm) each adds at {args.sigma_mrad:g} mrad; the last column all "
             "terms together.", "", "| recording | largest three | all |", "|---|---|---|",
             *top]
    return write_results(out, lines, start)


if __name__ == "__main__":
    raise SystemExit(main())
