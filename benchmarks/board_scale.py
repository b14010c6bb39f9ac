"""The board's metric scale solved from the IMU (`board_scale_sigma`): simulated Crazyflie
deck captures whose board file is 1 % too large, and the shared real logs.

Part 1, simulated (``configs/simulation/deck.toml``, 60 s, seeds 1-3, the simulated 100 Hz
IMU): station 1's error with the true board, with the 1 % board held and with its scale
solved (prior 2 %), the solved scale against the truth (1 / 1.01 - 1) in its sigmas. Part 2
(``--real``; the shared Crazyflie logs with their IMU, when ``../shared`` has them; no
licence: read only): the scale each log's solve finds, against the mocap's (+0.04 to +0.9 %,
results/crossing_beam_ratios.md). Writes docs/results/board_scale.md. ~1 min (``--real``:
~15 min more).
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import dataclasses
import tempfile
import time
from datetime import date
from pathlib import Path

from benchmarks import write_results
from benchmarks.compare_pairs import DATA, PAIRS, ROOT, imported
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.metrics import station_errors
from lhgraph.model.board import Board
from lhgraph.sim.simulate import load_simulation_config, simulate, simulate_imu
from lhgraph.workflow.solve import run_config
from lhgraph.workflow.solve_config import SolveConfig

OPTIONS = GraphOptions.of(board_scale_sigma=0.02)
TRUE_K = 1 / 1.01 - 1


def simulated(seed: int) -> str:
    """Part 1's row of one seed."""
    cfg = dataclasses.replace(load_simulation_config(ROOT / "configs/simulation/deck.toml"),
                              duration_s=60.0)
    sim = simulate(cfg, seed)
    imu = simulate_imu(sim, seed=seed).stream
    models = {k: s.model for k, s in sim.truth.stations.items()}
    b = sim.board
    wrong = Board(b.ids, b.positions * 1.01, b.normals, b.name)
    cells = []
    for board, options in ((b, GraphOptions()), (wrong, GraphOptions()), (wrong, OPTIONS)):
        result = solve_graph(board, sim.angles, models, options, imu=imu)
        cells.append(f"{station_errors(sim.truth, result.stations)[0].position_norm_m * 1e3:.2f}")
    k = result.board_scale
    return (f"| {seed} | " + " | ".join(cells) + f" | {k['correction'] * 100:+.3f} +- "
            f"{k['sigma'] * 100:.3f} | {(k['correction'] - TRUE_K) / k['sigma']:+.1f} |")


def real(tmp: Path) -> list[str]:
    """Part 2's rows."""
    rows = []
    logs = {path: kind for pair in PAIRS.values() for kind, path in pair if kind == "crazyflie"}
    for i, path in enumerate(logs):
        if not (DATA / path).exists():
            rows.append(f"| {path} | skipped: data absent | | |")
            continue
        w = imported("crazyflie", DATA / path, tmp / f"log{i}")
        result = run_config(SolveConfig(board=w / "board.toml", angles=w / "angles.csv",
                                        calibration=w / "ootx.toml", imu=w / "imu.csv",
                                        graph=OPTIONS))
        k = result.board_scale
        rows.append(f"| {path} | {k['correction'] * 100:+.2f} +- {k['sigma'] * 100:.2f} | "
                    f"{len(result.warnings)} |")
        print(path, flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks board_scale",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, default=ROOT / "docs/results/board_scale.md")
    parser.add_argument("--real", action="store_true", help="also the shared real logs")
    args = parser.parse_args(argv)
    tic = time.perf_counter()
    lines = ["# The board's scale solved from the IMU", "",
             "Command: `python -m benchmarks board_scale" + (" --real" if args.real else "")
             + f"`  \n{date.today()}; prior 2 % (`board_scale_sigma = 0.02`)", "",
             "## Simulated deck, 60 s, board file 1 % too large", "",
             "Station 1's position error (mm); the solved scale correction (%, truth "
             f"{TRUE_K * 100:+.3f} %) and its error in its honest sigmas.", "",
             "| seed | true board | 1 % board held | 1 % board, scale solved | scale % | "
             "error / sigma |", "|---|---|---|---|---|---|"]
    for seed in (1, 2, 3):
        lines.append(simulated(seed))
        print("seed", seed, flush=True)
    if args.real:
        lines += ["", "## Real Crazyflie logs with their IMU", "",
                  "The scale correction each solve finds (%) and its warnings; the mocap says "
                  "the deck is +0.04 to +0.9 % larger than its file (crossing_beam_ratios.md).",
                  "", "| log | scale % | warnings |", "|---|---|---|"]
        with tempfile.TemporaryDirectory(prefix="lhgraph-scale-") as tmp:
            lines += real(Path(tmp))
    return write_results(args.output, lines, tic)


if __name__ == "__main__":
    raise SystemExit(main())
