"""Several captures in one solve and an earlier result as a prior (issue #41 items 1, 2).

    python -m benchmarks joint_captures [--seeds 3] [--output docs/results/joint_captures.md]

1. **Room of 8 LH2 stations, three captures** (configs/simulation/lh2_room8.toml, 30 s,
   the board carried once round the room): three captures (three seeds), each keeping the
   hits of 3-4 neighbouring stations only (:data:`ROOM_SUBSETS`: 0-3, 3-5, 5-7 and 0, so
   that no capture sees every station and each pair of captures shares one); each solved
   alone (its own reference, timed) and the three jointly (``join_captures``, shared
   stations, one board path each; timed): every station's error against the truth, the
   NEES of its honest 6x6 covariance, the joint time over the sum of the separate ones.
   Targets: each station within 2 mm / 0.05 deg, NEES in range, time ratio <= 1.5.
2. **A prior against the joint solve** (configs/simulation/realistic.toml, pairs of 8 s
   captures of one room, seeds 1/2, 3/4, ...): capture B solved with A's result as a prior
   (``--prior``) against A and B solved jointly: station 1's difference in units of the
   joint honest covariance (6-dof Mahalanobis; target <= 0.5), and each one's sigma.
3. **The shared hive bags 8.11 and 8.17** (same layout; no licence: read from ../shared
   only): each alone, jointly and 8.17 with 8.11 as its prior: station 1's honest position
   sigma, and each result's distance from the joint answer in its own sigma along the
   difference (target: the joint sigma smaller than each alone, each alone within 2 sigma).

The solves run through the Python API (the default graph options, as ``lhgraph solve``).
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks.compare_pairs import DATA, imported
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.metrics import station_errors
from lhgraph.estimation.result import SolveResult
from lhgraph.estimation.station_prior import station_priors
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.angles import Angles, load_angles
from lhgraph.io.captures import join_captures
from lhgraph.io.stations import Stations
from lhgraph.model.board import load_board
from lhgraph.model.calibration import load_calibration
from lhgraph.sim.simulate import load_simulation_config, simulate
from lhgraph.workflow.inputs import models_of

ROOT = Path(__file__).resolve().parent.parent
ROOM8 = ROOT / "configs" / "simulation" / "lh2_room8.toml"
PAIR_CONFIG = ROOT / "configs" / "simulation" / "realistic.toml"
HIVE = ("hive-env8/data8.11.bag", "hive-env8/data8.17.bag")
ROOM_SUBSETS = ((0, 1, 2, 3), (3, 4, 5), (5, 6, 7, 0))
"""The stations each simulated room capture keeps."""


def timed(board, angles: Angles, models, **kwargs) -> tuple[SolveResult, float]:
    """A graph solve and its wall time (s)."""
    tic = time.perf_counter()
    result = solve_graph(board, angles, models, **kwargs)
    return result, time.perf_counter() - tic


def nees(truth: Stations, estimate: Stations, k: int) -> float:
    """6-dof NEES of station ``k`` (honest covariance), both in the estimate's reference
    frame."""
    ref = estimate.reference
    T_true = inverse(truth.pose(ref)) @ truth.pose(k)
    xi = se3_log(inverse(T_true) @ estimate.pose(k))
    return float(xi @ np.linalg.solve(estimate.stations[k].covariance, xi))


def room(seed: int) -> dict:
    """Part 1 for one seed."""
    config = load_simulation_config(ROOM8)
    parts = []
    for c, keep in enumerate(ROOM_SUBSETS):
        sim = simulate(config, 10 * seed + c)
        parts.append(sim.angles.select(np.isin(sim.angles.lighthouse, keep)))
    models = {k: s.model for k, s in sim.truth.stations.items()}
    separate = [timed(sim.board, p, models)[1] for p in parts]
    joined, spans, _ = join_captures(parts, [f"part {i}" for i in range(3)])
    result, joint_s = timed(sim.board, joined, models)
    errors = {e.station: e for e in station_errors(sim.truth, result.stations)}
    return {"seed": seed, "seen": [sorted(s.hits) for s in spans],
            "pos_mm": {k: e.position_norm_m * 1e3 for k, e in errors.items()},
            "rot_deg": {k: float(np.degrees(e.rotation_rad)) for k, e in errors.items()},
            "nees": {k: nees(sim.truth, result.stations, k) for k in errors},
            "separate_s": sum(separate), "joint_s": joint_s}


def mahalanobis(a: np.ndarray, b: np.ndarray, cov: np.ndarray) -> float:
    """6-dof distance of pose ``b`` from ``a`` in ``cov`` (``a``'s tangent space)."""
    d = se3_log(inverse(a) @ b)
    return float(np.sqrt(d @ np.linalg.solve(cov, d)))


def sigma_mm(result: Stations, k: int = 1) -> float:
    """Station ``k``'s honest position sigma (mm, root of the covariance's trace)."""
    return float(np.sqrt(np.trace(result.stations[k].covariance[3:, 3:])) * 1e3)


def along_sigma(a: Stations, b: Stations, k: int = 1) -> tuple[float, float]:
    """Station ``k``'s position difference b - a (mm) and its size in ``a``'s honest sigma
    along the difference."""
    d = b.pose(k)[:3, 3] - a.pose(k)[:3, 3]
    n = float(np.linalg.norm(d))
    if n == 0.0:
        return 0.0, 0.0
    u = d / n
    cov = a.stations[k].covariance[3:, 3:]
    R = a.pose(k)[:3, :3]
    s = float(np.sqrt(u @ (R @ cov @ R.T) @ u))
    return n * 1e3, n / s


def pair(seed: int) -> dict:
    """Part 2 for one pair of captures (seeds ``seed`` and ``seed + 1``)."""
    config = load_simulation_config(PAIR_CONFIG)
    a, b = simulate(config, seed), simulate(config, seed + 1)
    models = {k: s.model for k, s in a.truth.stations.items()}
    first = solve_graph(a.board, a.angles, models).stations
    alone = solve_graph(b.board, b.angles, models).stations
    prior = station_priors(first, first.reference)
    chained = solve_graph(b.board, b.angles, models, prior=prior).stations
    joined, _, _ = join_captures([a.angles, b.angles], ["a", "b"])
    joint = solve_graph(a.board, joined, models).stations
    return {"seed": seed, "d_sigma": mahalanobis(joint.pose(1), chained.pose(1),
                                                  joint.stations[1].covariance),
            "sigma": {"A": sigma_mm(first), "B": sigma_mm(alone), "B | A": sigma_mm(chained),
                      "A + B": sigma_mm(joint)}}


def hive(work: Path) -> list[str]:
    """Part 3: the table rows (or a skip line)."""
    if not all((DATA / p).exists() for p in HIVE):
        return ["Skipped: the hive bags are absent."]
    folders = [imported("hive", DATA / p, work / f"h{i}") for i, p in enumerate(HIVE)]
    board = load_board(folders[0] / "board.toml")
    models = models_of(load_calibration(folders[0] / "ootx.toml"))
    angles = [load_angles(f / "angles.csv") for f in folders]
    alone = [solve_graph(board, a, models) for a in angles]
    joined, _, _ = join_captures(angles, [p for p in HIVE])
    joint, joint_s = timed(board, joined, models)
    prior = station_priors(alone[0].stations, alone[0].stations.reference)
    chained = solve_graph(board, angles[1], models, prior=prior).stations
    rows = ["| result | station 1 honest sigma (mm) | from the joint answer (mm) "
            "| in its own sigma | in the joint sigma |", "|---|---|---|---|---|"]
    for name, st in (("8.11 alone", alone[0].stations), ("8.17 alone", alone[1].stations),
                     ("8.17 with 8.11 as prior", chained), ("8.11 + 8.17 joint",
                                                             joint.stations)):
        d_mm, own = along_sigma(st, joint.stations)
        _, in_joint = along_sigma(joint.stations, st)
        rows.append(f"| {name} | {sigma_mm(st):.2f} | {d_mm:.2f} | {own:.2f} | "
                    f"{in_joint:.2f} |")
    rows += ["", f"Joint solve of both bags: {joint_s:.1f} s."]
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks joint_captures",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds of parts 1 and 2")
    parser.add_argument("--output", type=Path,
                        default=ROOT / "docs" / "results" / "joint_captures.md")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    lines = ["# Several captures in one solve, an earlier result as a prior", "",
             f"Command: `python -m benchmarks joint_captures --seeds {args.seeds}`  ",
             f"{date.today()}; the default graph options; 2-core machine.", "",
             "## 1. Room of 8 LH2 stations, three captures of 3-4 stations each", "",
             "| seed | stations per capture | worst station mm | worst deg | NEES mean "
             "(6 dof) | NEES max | separate solves s | joint s | ratio |",
             "|---|---|---|---|---|---|---|---|---|"]
    for seed in range(1, args.seeds + 1):
        r = room(seed)
        seen = " / ".join(",".join(map(str, s)) for s in r["seen"])
        n = np.array(list(r["nees"].values()))
        lines.append(f"| {seed} | {seen} | {max(r['pos_mm'].values()):.2f} | "
                     f"{max(r['rot_deg'].values()):.3f} | {n.mean():.1f} | {n.max():.1f} | "
                     f"{r['separate_s']:.1f} | {r['joint_s']:.1f} | "
                     f"{r['joint_s'] / r['separate_s']:.2f} |")
        print(lines[-1], flush=True)
    lines += ["", "## 2. B with A's result as a prior against the joint A + B (simulated)",
              "", "| seeds | B with prior A from A + B (joint sigmas, 6 dof) | sigma A mm "
              "| B | B with prior A | A + B |", "|---|---|---|---|---|---|"]
    for i in range(args.seeds):
        r = pair(1 + 2 * i)
        s = r["sigma"]
        lines.append(f"| {r['seed']}/{r['seed'] + 1} | {r['d_sigma']:.2f} | {s['A']:.2f} | "
                     f"{s['B']:.2f} | {s['B | A']:.2f} | {s['A + B']:.2f} |")
        print(lines[-1], flush=True)
    lines += ["", "## 3. hive data8.11 and data8.17 (same layout)", ""]
    with tempfile.TemporaryDirectory(prefix="lhgraph-joint-") as tmp:
        lines += hive(Path(tmp))
    lines += ["", f"Run time: {(time.perf_counter() - start) / 60:.1f} min.", ""]
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
