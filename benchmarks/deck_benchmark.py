"""Few-diode calibration on simulated Crazyflie deck logs (configs/simulation/deck.toml).

    python -m benchmarks deck_benchmark [--seeds 10] [--jobs 2]
        [--output docs/results/deck.md] [--force]

1. Accuracy: 120 s deck captures (two LH1 stations 4 m apart, hand-held motion, the real
   log's character: ~3.5 diodes per sweep, about half the cycles logged, both sweeps of a
   cycle stamped together), one per seed: station 1's position and rotation error, the NEES
   of its 6x6 covariance (expected 6), the board states whose orientation is more than
   5 deg from the true one (a run of states left on the planar mirror branch), iterations,
   solve time, warnings.
2. Run time: the whole `lhgraph solve` process (Python start-up, bytecode imports, CSV and
   TOML, the factory calibration as ootx.toml) on the first seed's capture, median of 3.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from benchmarks import command, prog
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.geometry.transforms import inverse, rotation_angle, se3_log
from lhgraph.io.files import check_writable
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs/simulation/deck.toml"
EXACT_DECK = GraphOptions.of(receiver_scale_sigma=0.0)
"""A simulated deck's board file is exact: its solves carry no receiver-scale uncertainty (on
real decks the default does, docs/uncertainty.md), so the NEES judges the graph alone."""
STATE_OFF_DEG = 5.0
"""A board state this far from the true orientation is counted as off (on the mirror branch:
the runs found are 20-130 deg off, the rest under 2 deg)."""


def run_one(seed: int) -> dict:
    """Simulate one deck capture, solve it, and return station 1's errors, NEES and time."""
    sim = simulate(load_simulation_config(CONFIG), seed)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    tic = time.perf_counter()
    result = solve_graph(sim.board, sim.angles, models, EXACT_DECK)
    seconds = time.perf_counter() - tic
    T_true = sim.truth.relative_to_reference().pose(1)
    est = result.stations.relative_to_reference()
    T_est = est.pose(1)
    xi = se3_log(inverse(T_true) @ T_est)
    path = result.trajectory
    R_true = (inverse(sim.truth.pose(0)) @ sim.trajectory.at(path.time))[:, :3, :3]
    turned = rotation_angle(np.swapaxes(R_true, -1, -2) @ path.T_world_board[:, :3, :3])
    key = sim.angles.extra["sweep"] * 4 + sim.angles.lighthouse
    return {"seed": seed, "hits": len(sim.angles),
            "diodes": float(np.mean(np.unique(key, return_counts=True)[1])),
            "pos_mm": float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]) * 1e3),
            "rot_deg": float(np.degrees(rotation_angle(T_true[:3, :3].T @ T_est[:3, :3]))),
            "nees": float(xi @ np.linalg.solve(est.stations[1].covariance, xi)),
            "sigma_mm": float(np.sqrt(np.max(np.linalg.eigvalsh(
                est.stations[1].covariance[3:, 3:]))) * 1e3),
            "states": len(turned),
            "states_off": int(np.sum(turned > np.radians(STATE_OFF_DEG))),
            "seconds": seconds, "iterations": result.iterations, "status": result.status,
            "warnings": result.warnings}


def whole_process(seed: int, runs: int = 3) -> list[float]:
    """Wall time of `lhgraph solve` on the files of one deck capture (bytecode compiled)."""
    sim = simulate(load_simulation_config(CONFIG), seed)
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "lhgraph")], check=True)
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        write_simulation(sim, tmp)
        save_calibration({k: StationCalibration(s.model.calibration)
                          for k, s in sim.truth.stations.items()}, f"{tmp}/ootx.toml")
        for _ in range(runs):
            tic = time.perf_counter()
            subprocess.run([sys.executable, "-m", "lhgraph", "solve", "--board",
                            f"{tmp}/board.toml", "--angles", f"{tmp}/angles.csv",
                            "--calibration", f"{tmp}/ootx.toml", "--output", f"{tmp}/out.toml",
                            "--force", "--quiet"], check=True)
            times.append(time.perf_counter() - tic)
    return times


def seeds_in_parallel(path: str, description: str, output: Path, run: Callable[[int], dict],
                      argv: list[str] | None) -> tuple[argparse.Namespace, Path, list[dict]]:
    """The command line ``argv`` of the deck benchmark in file ``path`` (``--seeds``,
    ``--jobs``, ``--output`` default ``output``, ``--force``), the checked output path and
    ``run(seed)`` of every seed, run ``--jobs`` at a time."""
    parser = argparse.ArgumentParser(prog=prog(path), description=description)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--output", default=str(output))
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    rows = Parallel(n_jobs=args.jobs)(delayed(run)(s) for s in range(1, args.seeds + 1))
    return args, out, rows


def write_report(out: Path, lines: list[str]) -> int:
    """Write the report's lines to ``out`` (folders made) and print them; exit code 0."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


def main(argv: list[str] | None = None) -> int:
    args, out, rows = seeds_in_parallel(__file__, __doc__.split("\n")[0],
                                        ROOT / "docs/results/deck.md", run_one, argv)
    cli = whole_process(1)
    pos = np.array([r["pos_mm"] for r in rows])
    rot = np.array([r["rot_deg"] for r in rows])
    nees = np.array([r["nees"] for r in rows])
    off = np.array([r["states_off"] for r in rows])
    lines = ["# Few-diode calibration: simulated Crazyflie deck logs", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}; {time.strftime('%Y-%m-%d')}  ",
             f"Config: `configs/simulation/deck.toml` (120 s), seeds 1-{args.seeds}", "",
             "## 1. Accuracy (station 1 relative to station 0)", "",
             f"- median position error **{np.median(pos):.2f} mm** (mean {pos.mean():.2f}, max "
             f"{pos.max():.2f}); median rotation error **{np.median(rot):.3f} deg** (mean "
             f"{rot.mean():.3f}, max {rot.max():.3f}); target <= 3 mm / 0.05 deg",
             f"- NEES (6 dof): median **{np.median(nees):.1f}**, mean {nees.mean():.1f} "
             f"(target [3, 12], i.e. [0.5, 2] x 6)",
             f"- board states more than {STATE_OFF_DEG:g} deg from the true orientation: median "
             f"**{np.median(off):.0f}** of a median {np.median([r['states'] for r in rows]):.0f} "
             f"(max {off.max()})", "",
             "| seed | hits | diodes/sweep | pos mm | rot deg | NEES | sigma mm | states off | "
             "iterations | solve s | status | warnings |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['seed']} | {r['hits']} | {r['diodes']:.2f} | {r['pos_mm']:.2f} | "
              f"{r['rot_deg']:.3f} | {r['nees']:.1f} | {r['sigma_mm']:.2f} | "
              f"{r['states_off']} | {r['iterations']} | {r['seconds']:.1f} | {r['status']} | "
              f"{'; '.join(r['warnings']) or '-'} |" for r in rows]
    lines += ["", "## 2. Run time", "",
              f"- `solve_graph` in-process (with {args.jobs} solves in parallel on the "
              f"machine's cores): median {np.median([r['seconds'] for r in rows]):.1f} s",
              f"- whole `lhgraph solve` process on seed 1's capture (start-up, imports, CSV, "
              f"TOML, solve, writing): median **{np.median(cli):.1f} s** of {len(cli)} runs "
              f"(min {min(cli):.1f}); target <= 5 s", ""]
    return write_report(out, lines)


if __name__ == "__main__":
    raise SystemExit(main())
