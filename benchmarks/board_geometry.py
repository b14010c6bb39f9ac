"""Solving the board's sensor positions with the stations (``sensor_offset_sigma_m``,
``lhgraph solve --board-output``) on simulated captures whose board file is wrong.

    python -m benchmarks board_geometry [--seeds 6] [--errors-mm 0,0.25,0.5,1]
        [--keep-scale] [--jobs 2] [--output docs/results/board_geometry.md] [--force]

For each seed (default layout, configs/simulation/default.toml, 8 s) and each board error
(every sensor of the paper32 board moved by a Gaussian of that standard deviation per axis,
fixed per seed, less the part that scales the board unless ``--keep-scale``: the offsets'
scale mode is held at zero by the solve, so the board's size must be right in the file),
the graph solves the capture with the wrong board file twice: as it is, and with the
sensor offsets on (prior 0.3 mm, as ``--board-output`` sets). Reported per error: station
1's median position and rotation error, its mean NEES (6 dof), the board's rms
sensor-position error (file, and solved: after removing the best rigid motion, the board
frame's own gauge), the residual rms and the solve time (medians over the seeds). Error 0
shows what the extra unknowns cost on an exact board.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import time
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from benchmarks import command, prog
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.files import check_writable
from lhgraph.model.board import with_sensor_offsets
from lhgraph.sim.simulate import load_simulation_config, simulate
from lhgraph.workflow.solve_config import SENSOR_OFFSET_SIGMA_M

ROOT = Path(__file__).resolve().parents[1]


def rigid_rms(a: np.ndarray, b: np.ndarray) -> float:
    """rms distance (m) between point sets ``a`` and ``b`` (N, 3) after the best rigid fit."""
    T = weighted_kabsch(a, b)
    return float(np.sqrt(np.mean(np.sum((a @ T[:3, :3].T + T[:3, 3] - b) ** 2, axis=1))))


def run(seed: int, error_m: float, keep_scale: bool) -> dict[str, dict[str, float]]:
    """One capture solved with the board ``error_m`` off, without and with sensor offsets;
    without ``keep_scale`` the errors' scale part (a board larger or smaller than the file's,
    which no capture can tell from larger or smaller distances) is taken out."""
    sim = simulate(load_simulation_config(ROOT / "configs/simulation/default.toml"), seed)
    rng = np.random.default_rng(1000 + seed)
    offsets = rng.normal(0.0, error_m, sim.board.positions.shape)
    if not keep_scale:  # the file's size right: no part of the errors scales the board
        centred = sim.board.positions - sim.board.positions.mean(axis=0)
        offsets -= np.sum(centred * offsets) / np.sum(centred**2) * centred
    wrong = with_sensor_offsets(sim.board, offsets)
    truth = sim.truth.relative_to_reference().pose(1)
    out = {}
    for name, sigma in (("file as it is", 0.0), ("sensor offsets solved", SENSOR_OFFSET_SIGMA_M)):
        tic = time.perf_counter()
        r = solve_graph(wrong, sim.angles, options=GraphOptions.of(sensor_offset_sigma_m=sigma))
        seconds = time.perf_counter() - tic
        est = r.stations.relative_to_reference().stations[1]
        xi = se3_log(inverse(truth) @ est.T_world_lh)
        solved = (wrong.positions if r.sensor_offset_m is None
                  else wrong.positions + r.sensor_offset_m)
        out[name] = {"pos_mm": float(np.linalg.norm(est.T_world_lh[:3, 3] - truth[:3, 3])) * 1e3,
                     "rot_deg": float(np.degrees(np.linalg.norm(xi[:3]))),
                     "nees": float(xi @ np.linalg.solve(est.covariance, xi)),
                     "board_mm": rigid_rms(solved, sim.board.positions) * 1e3,
                     "rms_urad": r.residuals.rms_urad(), "seconds": seconds}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--errors-mm", default="0,0.25,0.5,1")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--keep-scale", action="store_true",
                        help="leave the errors' scale part in (the board's size wrong too)")
    parser.add_argument("--output", default=str(ROOT / "docs/results/board_geometry.md"))
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    errors = [float(x) * 1e-3 for x in args.errors_mm.split(",")]
    t0 = time.perf_counter()
    lines = ["# Solving the board's sensor positions (simulated, wrong board files)", "",
             f"Command: `{command(__file__, argv)}`"
             f"  ", f"{time.strftime('%Y-%m-%d')}; configs/simulation/default.toml (8 s), seeds "
             f"1-{args.seeds}; every sensor moved by a Gaussian of the given spread per axis"
             + ("" if args.keep_scale else ", less the part that scales the board (its size "
                "stays the file's)") + "; "
             "board error after the best rigid fit to the true board; medians over the seeds "
             "(NEES: mean, 6 dof).", "",
             "| board error per axis (mm) | solve | station 1 mm | deg | NEES | board rms "
             "error mm | residual rms µrad | solve s |", "|---|---|---|---|---|---|---|---|"]
    for error_m in errors:
        rows = Parallel(n_jobs=args.jobs)(delayed(run)(s, error_m, args.keep_scale)
                                          for s in range(1, args.seeds + 1))
        for name in rows[0]:
            v = {k: np.array([r[name][k] for r in rows]) for k in rows[0][name]}
            lines.append(f"| {error_m * 1e3:g} | {name} | {np.median(v['pos_mm']):.3f} | "
                         f"{np.median(v['rot_deg']):.4f} | {np.mean(v['nees']):.1f} | "
                         f"{np.median(v['board_mm']):.3f} | {np.median(v['rms_urad']):.1f} | "
                         f"{np.median(v['seconds']):.2f} |")
            print(lines[-1], flush=True)
    lines += ["", f"Run time: {(time.perf_counter() - t0) / 60:.1f} min."]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
