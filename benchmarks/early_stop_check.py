"""How far the graph solver's early stop leaves the stations from full convergence.

LM stops when the stations are *estimated* to be within ``step_tolerance_sigma`` (0.05)
standard deviations of where the iteration converges (docs/graph.md, Stopping). This script
solves 2 s captures of six layouts (two seeds each) with the defaults and again run to a
1e-12 relative error change, and reports the largest per-coordinate difference of station 1
in units of its standard deviation, with the iterations each run took.

    python -m benchmarks early_stop_check [--output docs/results/early_stop.md] [--force]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from benchmarks import command, prog
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.files import check_writable
from lhgraph.sim.simulate import load_simulation_config, simulate

ROOT = Path(__file__).resolve().parent.parent
LAYOUTS = ("default", "facing", "ninety", "fast", "far", "realistic")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--output", default=str(ROOT / "docs/results/early_stop.md"))
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    full_options = GraphOptions.of(step_tolerance_sigma=0.0, relative_tolerance=1e-12)
    lines = ["# Early stop vs full convergence", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"{time.strftime('%Y-%m-%d')}; 2 s captures, station 1.", "",
             "| layout | seed | iterations (default) | iterations (full) | largest difference "
             "(sigma) |", "|---|---|---|---|---|"]
    worst = []
    for name in LAYOUTS:
        config = load_simulation_config(ROOT / f"configs/simulation/{name}.toml")
        for seed in (1, 2):
            sim = simulate(dataclasses.replace(config, duration_s=2.0), seed)
            early = solve_graph(sim.board, sim.angles)
            full = solve_graph(sim.board, sim.angles, options=full_options)
            sigma = np.sqrt(np.diag(full.stations.stations[1].covariance))
            difference = se3_log(inverse(early.stations.pose(1)) @ full.stations.pose(1))
            worst.append(float(np.max(np.abs(difference) / sigma)))
            lines.append(f"| {name} | {seed} | {early.iterations} | {full.iterations} "
                         f"({full.status}) | {worst[-1]:.3f} |")
    lines += ["", f"Largest over all captures: {max(worst):.3f} sigma (tolerance 0.05).", ""]
    text = "\n".join(lines)
    print(text)
    out.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
