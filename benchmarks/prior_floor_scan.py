"""How the floor of the adapted motion prior (``GraphOptions.min_psd_factor``) trades accuracy.

On every capture of the paper protocol the variance-component estimate wants a prior far
stiffer than the floor (chi2/dof ~0.02-0.04 at the floor), so the floor sets the prior. This
script solves the 50 protocol captures and the default layout at four speeds (6 seeds each,
seeds 200-205: not the graph benchmark's) for several floors and reports the median and
mean position error of station 1 and the mean NEES.

    python -m benchmarks prior_floor_scan [--floors 0.05,0.1,0.2,0.3,1.0] [--jobs 2]
        [--output docs/results/prior_floor_scan.md] [--force]
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from benchmarks import command, prog
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.files import check_writable
from lhgraph.sim.simulate import (
    SimulationConfig,
    load_simulation_config,
    paper_protocol,
    simulate,
)

ROOT = Path(__file__).resolve().parent.parent
SPEEDS = (0.2, 0.5, 1.0, 2.0)


def errors(config: SimulationConfig, seed: int | None, floors: list[float]
           ) -> list[tuple[float, float]]:
    """(position error mm, NEES) of station 1 for each floor, on one simulated capture."""
    sim = simulate(config, seed)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    T_true = sim.truth.relative_to_reference().pose(1)
    out = []
    for floor in floors:
        result = solve_graph(sim.board, sim.angles, models, GraphOptions.of(min_psd_factor=floor))
        est = result.stations.relative_to_reference()
        xi = se3_log(inverse(T_true) @ est.pose(1))
        out.append((float(np.linalg.norm(est.pose(1)[:3, 3] - T_true[:3, 3]) * 1e3),
                    float(xi @ np.linalg.solve(est.stations[1].covariance, xi))))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--floors", default="0.05,0.1,0.2,0.3,1.0")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--output", default=str(ROOT / "docs/results/prior_floor_scan.md"))
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    floors = [float(x) for x in args.floors.split(",")]
    base = load_simulation_config(ROOT / "configs/simulation/default.toml")
    sets = {"paper protocol (50 captures)": [
        (c, None) for _, c in paper_protocol(ROOT / "configs/paper_simulation.toml")]}
    for v in SPEEDS:
        config = dataclasses.replace(base, motion=dataclasses.replace(base.motion, speed_mps=v))
        sets[f"default layout, {v} m/s (6 seeds)"] = [(config, s) for s in range(200, 206)]
    lines = ["# Motion-prior floor scan", "",
             f"Command: `{command(__file__, argv)}`"
             f"  ", f"{time.strftime('%Y-%m-%d')}", "",
             "| captures | " + " | ".join(f"floor {f:g}: median / mean mm, NEES" for f in floors)
             + " |", "|---|" + "---|" * len(floors)]
    for name, jobs in sets.items():
        rows = np.array(Parallel(n_jobs=args.jobs)(delayed(errors)(c, s, floors)
                                                   for c, s in jobs))  # (n, floors, 2)
        cells = [f"{np.median(rows[:, i, 0]):.3f} / {np.mean(rows[:, i, 0]):.3f}, "
                 f"{np.mean(rows[:, i, 1]):.2f}" for i in range(len(floors))]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
