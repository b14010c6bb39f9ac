"""Does the answer depend on where the solve starts? The shared recordings solved from scratch
and again from their own answer.

    python -m benchmarks start_dependence [--output FILE] [--force]

Per recording of compare_pairs' pairs (imported as there; their ``ootx.toml``; the default
graph options):

1. the default solve from scratch (the initialiser's start), honest covariance;
2. the same data solved again, started from that answer (the receiver path and the stations:
   :class:`~lhgraph.estimation.station_watch.CalibrationStart`, what a solve with an earlier
   calibration as its start and the station watch begin from);
3. the first solve again with the stopping rule tightened a hundredfold (station step
   tolerance and relative error decrease): how far the default stop is from LM's end.

Station 1's distance from the first answer (position mm, rotation deg) and the angle noise
each settled on (the noise adaptation's robust spread of the residuals, which stops changing
once within a dead band, docs/graph.md), beside the first answer's white and honest sigmas.
Data: Crazyflie, hive (no licence: read from ../shared only). ~4 min on the 2-core machine.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import tempfile
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import begin, write_results
from benchmarks.compare_pairs import (
    DATA,
    DEG,
    TIGHT,
    imported,
    imported_inputs,
    recordings,
    start_at,
)
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.result import SolveResult
from lhgraph.geometry.transforms import inverse, se3_log

STATION = 1


def distance(a: SolveResult, b: SolveResult) -> str:
    """Station 1 of ``b`` from ``a``'s: ``mm | deg`` cells."""
    xi = se3_log(inverse(a.stations.pose(STATION)) @ b.stations.pose(STATION))
    return f"{np.linalg.norm(xi[3:]) * 1e3:.2f} | {np.linalg.norm(xi[:3]) * DEG:.4f}"


def sigma(cov: np.ndarray) -> str:
    """The largest position (mm) and rotation (deg) 1-sigma of a 6x6 covariance."""
    return (f"{np.sqrt(np.linalg.eigvalsh(cov[3:, 3:]).max()) * 1e3:.2f} / "
            f"{np.sqrt(np.linalg.eigvalsh(cov[:3, :3]).max()) * DEG:.4f}")


def row(folder: Path, name: str) -> str:
    """The table row of the imported recording ``folder``."""
    board, angles, models = imported_inputs(folder)
    first = solve_graph(board, angles, models, GraphOptions())
    again = solve_graph(board, angles, models, GraphOptions.of(covariance="white"),
                        initialiser=start_at(first))
    tight = solve_graph(board, angles, models, TIGHT)
    s = first.stations.stations[STATION]
    noise = [r.diagnostics["angle_sigma_rad"] * 1e6 for r in (first, again, tight)]
    return (f"| {name} | {first.iterations} / {again.iterations} / {tight.iterations} | "
            f"{distance(first, again)} | {distance(first, tight)} | "
            + " / ".join(f"{x:.1f}" for x in noise)
            + f" | {sigma(s.covariance_white)} | {sigma(s.covariance)} |")


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "Does the answer depend on where the solve starts?")
    rows = []
    with tempfile.TemporaryDirectory(prefix="lhgraph-start-") as tmp:
        for n, (kind, path) in enumerate(recordings()):
            if not (DATA / path).exists():
                rows.append(f"| {path} | skipped: data absent | | | | | | |")
                continue
            rows.append(row(imported(kind, DATA / path, Path(tmp) / str(n)), path))
            print(rows[-1], flush=True)
    lines += [f"{date.today()}; the default graph solve of each recording (1: from scratch), "
              "again from its own answer (2) and from scratch with the stopping rule "
              "tightened a hundredfold (3); station 1 (relative to the reference) from "
              "answer 1; the angle noise each settled on (µrad); answer 1's sigmas (largest "
              "1-sigma, mm / deg).", "",
              "| recording | iterations 1 / 2 / 3 | 2 from 1: mm | deg | 3 from 1: mm | deg "
              "| angle noise 1 / 2 / 3 | white sigma | honest sigma |",
              "|---|---|---|---|---|---|---|---|---|", *rows]
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
