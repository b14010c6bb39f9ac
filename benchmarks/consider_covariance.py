"""The factory terms' own uncertainty in the station covariance ("consider" covariance): would
it make the honest sigma cover the shared pairs of recordings of unmoved stations?

    python -m benchmarks consider_covariance [--sigma-mrad S] [--output FILE] [--force]

Issue #39's item 3 asks the sigma to account for the model parameters' own uncertainty. The
stations are solved with the decoded (OOTX) factory terms held; a term wrong by its prior
spread moves them. Per recording of compare_pairs' pairs (imported and solved as there):

1. station 1's sensitivity to each factory term ``K = d(station 1 pose) / d(term)`` (6 per
   term, axis and station, tangent ``[rotation, translation]`` in its own frame): the
   linearised shift of the solve's own system (``factory_information``,
   ``station_shift_per_rad``: every graph variable free, the reference's terms too), checked
   on each recording against a re-solve with its largest term moved by 1 mrad;
2. the consider covariance ``K S K^T`` with ``S`` the terms' prior (``--sigma-mrad``,
   default the graph's ``factory_sigma_rad``, independent per term, axis and station),
   added to the honest covariance two ways: as if each recording's terms were wrong
   independently (``C_a + K_a S K_a^T`` and ``C_b + K_b S K_b^T``), and as what it is for
   two recordings of the same stations decoded from the same OOTX, one error common to
   both (their difference ``C_a + C_b + (K_a - K_b) S (K_a - K_b)^T``);
3. the pair's difference in combined honest and combined consider sigmas
   (:func:`lhgraph.estimation.layout_compare.compare_layouts`).

Terms: phase, tilt, curve and gibmag of both axes (gibphase is an angle whose error matters
only through gibmag; LH2's model has no curve). Writes docs/results/consider_covariance.md.
Data: Crazyflie, hive (no licence: read from ../shared only). ~5 min on the 2-core machine.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import re
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import command, results_parser, write_results
from benchmarks.compare_pairs import (
    DATA,
    DEG,
    PAIRS,
    TIGHT,
    imported,
    imported_inputs,
    solve_imported,
    start_at,
)
from lhgraph.estimation.graph.families.factory import with_term_deltas
from lhgraph.estimation.graph.options import FactoryOptions, GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.layout_compare import compare_layouts
from lhgraph.estimation.result import SolveResult
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.files import check_writable
from lhgraph.io.stations import Stations

TERMS = ("phase", "tilt", "curve", "gibmag")
STEP_RAD = 1e-3
STATION = 1
TERM = re.compile(r"station (\d+) (\w+)\[(\d)\]")


@dataclass(frozen=True)
class Sensitivity:
    """One recording's solve (``stations``, honest covariance), station 1's linearised
    sensitivity ``K`` (6, n) to the terms ``labels`` (``0.phase[1]``), and the check of its
    largest column: the position shift (mm) of a re-solve with that term moved by
    :data:`STEP_RAD` against the linearised one."""

    stations: Stations
    K: np.ndarray
    labels: list[str]
    check: tuple[str, float, float]


def sensitivity(folder: Path) -> Sensitivity:
    """The imported log ``folder`` solved with the factory terms' information and station 1's
    sensitivity to each term of :data:`TERMS`; its largest term re-solved."""
    result = solve_imported(folder, GraphOptions.of(factory_information=True))
    info = result.factory_information
    shift = np.array(info["station_shift_per_rad"][STATION])
    chosen = [(j, m) for j, name in enumerate(info["terms"])
              if (m := TERM.fullmatch(name)) and m[2] in TERMS]
    K = shift[:, [j for j, _ in chosen]]
    labels = [f"{m[1]}.{m[2]}[{m[3]}]" for _, m in chosen]
    largest = int(np.argmax(np.linalg.norm(K[3:], axis=0)))
    _, m = chosen[largest]
    return Sensitivity(result.stations, K, labels,
                       (labels[largest], float(np.linalg.norm(K[3:, largest])) * STEP_RAD * 1e3,
                        resolved_shift_mm(folder, result, int(m[1]), m[2], int(m[3]))))


def resolved_shift_mm(folder: Path, first: SolveResult, station: int, term: str, axis: int
                      ) -> float:
    """Station 1's position shift (mm) per :data:`STEP_RAD` of one term of ``station``: the
    central difference of ``folder``'s log solved again with the term moved by plus and
    minus the step, both started from its first solve ``first`` (white covariance, the
    stopping rule tightened a hundredfold: its tolerance would otherwise show in the
    difference)."""
    board, angles, models = imported_inputs(folder)
    start = start_at(first)
    poses = []
    for sign in (1.0, -1.0):
        delta = np.zeros(2)
        delta[axis] = sign * STEP_RAD
        moved = dict(models)
        moved[station] = with_term_deltas(models[station], (term,), delta)
        poses.append(solve_graph(board, angles, moved, TIGHT, initialiser=start
                                 ).stations.pose(STATION))
    xi = se3_log(inverse(poses[1]) @ poses[0]) / 2
    return float(np.linalg.norm(xi[3:])) * 1e3


def widened(stations: Stations, C: np.ndarray) -> Stations:
    """``stations`` with station 1's honest covariance widened by ``C``."""
    s = stations.stations[STATION]
    return replace(stations, stations={**stations.stations,
                                       STATION: replace(s, covariance=s.covariance + C)})


Consider = Callable[[Sensitivity, Sensitivity, float], tuple[Stations, Stations]]


def independent(a: Sensitivity, b: Sensitivity, sigma: float) -> tuple[Stations, Stations]:
    """Each recording's terms wrong on their own: ``K S K^T`` added to each."""
    return (widened(a.stations, sigma**2 * a.K @ a.K.T),
            widened(b.stations, sigma**2 * b.K @ b.K.T))


def common(a: Sensitivity, b: Sensitivity, sigma: float) -> tuple[Stations, Stations]:
    """One error of the terms in both (the same stations, the same OOTX): their difference
    moves by ``(K_a - K_b) delta``, added to the first."""
    if a.labels != b.labels:
        raise SystemExit("the pair's recordings have different factory terms")
    D = a.K - b.K
    return widened(a.stations, sigma**2 * D @ D.T), b.stations


def station_difference(a: Stations, b: Stations):
    """Station 1's entry of :func:`compare_layouts`."""
    return next(x for x in compare_layouts(a, b).differences if x.station == STATION)


def sigma_for(a: Sensitivity, b: Sensitivity, consider: Consider, target: float = 2.0
              ) -> tuple[str, str]:
    """The terms' spread (mrad) at which the pair's station-1 difference is ``target``
    combined consider sigmas, in position and in rotation ("" when the honest sigma alone
    covers it, "> 30" when no spread up to 30 mrad does), the smallest of a log grid from
    0.01 to 30 mrad."""
    grid = np.geomspace(1e-5, 3e-2, 120)
    ratios = np.array([(d.position_sigmas, d.rotation_sigmas) for d in (
        station_difference(*consider(a, b, sigma)) for sigma in grid)])
    base = station_difference(a.stations, b.stations)
    cells = []
    for r, honest in zip(ratios.T, (base.position_sigmas, base.rotation_sigmas), strict=True):
        if honest <= target:
            cells.append("")
            continue
        ok = np.flatnonzero(r <= target)
        cells.append(f"{grid[ok[0]] * 1e3:.2f}" if len(ok) else "> 30")
    return cells[0], cells[1]


def pair_cells(a: Sensitivity, b: Sensitivity, sigma: float, consider: Consider) -> str:
    """``consider sigma | in consider sigmas`` of the pair under ``consider``."""
    c = station_difference(*consider(a, b, sigma))
    return (f"{c.sigma_position_m * 1e3:.2f} / {c.sigma_rotation_rad * DEG:.4f} | "
            f"{c.position_sigmas:.1f} / {c.rotation_sigmas:.1f}")


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
                rows.append(f"| {name} | skipped: data absent | | | | | | | | |")
                continue
            found = []
            for i, (kind, path) in enumerate(logs):
                s = sensitivity(imported(kind, DATA / path, Path(tmp) / f"{n}{i}"))
                found.append(s)
                share = np.sum((s.K[3:] * sigma) ** 2, axis=0)
                worst = np.argsort(share)[::-1][:3]
                term, linear, solved = s.check
                top.append(f"| {path} | " + ", ".join(
                    f"{s.labels[j]} {np.sqrt(share[j]) * 1e3:.1f}" for j in worst)
                    + f" | {np.sqrt(share.sum()) * 1e3:.1f} | {term}: {linear:.2f} / "
                    f"{solved:.2f} |")
                print(top[-1], flush=True)
            a, b = found
            d = station_difference(a.stations, b.stations)
            rows.append(
                f"| {name} | {d.position_m * 1e3:.1f} / {d.rotation_rad * DEG:.3f} | "
                f"{d.sigma_position_m * 1e3:.2f} / {d.sigma_rotation_rad * DEG:.4f} | "
                f"{d.position_sigmas:.1f} / {d.rotation_sigmas:.1f} | "
                f"{pair_cells(a, b, sigma, independent)} | "
                + " / ".join(x or "-" for x in sigma_for(a, b, independent)) + " | "
                f"{pair_cells(a, b, sigma, common)} | "
                + " / ".join(x or "-" for x in sigma_for(a, b, common)) + " |")
            print(rows[-1], flush=True)
    lines = ["# The factory terms' uncertainty in the station covariance", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"{date.today()}; terms {', '.join(TERMS)} of both axes and stations, each "
             f"uncertain by {args.sigma_mrad:g} mrad (1 sigma, independent); station 1 in "
             "the reference's frame; combined sigmas of the two recordings; the spread "
             "giving 2 sigmas in mrad, position / rotation (-: the honest sigma covers it "
             "already). Independent: each recording's terms wrong on their own; common: one "
             "error of the decoded terms in both recordings (the same stations, the same "
             "OOTX), which moves their difference by `(K_a - K_b) delta` only.", "",
             "## Pairs of recordings of unmoved stations", "",
             "| pair | difference (mm / deg) | honest sigma | in honest sigmas "
             "| independent: consider sigma | in consider sigmas | spread giving 2 sigmas "
             "| common: consider sigma | in consider sigmas | spread giving 2 sigmas |",
             "|---|---|---|---|---|---|---|---|---|---|", *rows, "",
             "## The terms that move station 1 most", "",
             f"Position sigma (mm) each adds at {args.sigma_mrad:g} mrad; all terms together; "
             "the largest term's linearised position shift at 1 mrad against a re-solve "
             "with it moved by 1 mrad (mm).", "",
             "| recording | largest three | all | linearised / re-solved |",
             "|---|---|---|---|", *top]
    return write_results(out, lines, start)


if __name__ == "__main__":
    raise SystemExit(main())
