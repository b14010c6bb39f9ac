"""Station self-calibration (`factory_terms`): perturbed factory terms recovered in
simulation, and what solving them does on the shared recordings of unmoved stations.

Part 1, simulated (seeds 1-5): the paper's board waved 8 s (``realistic.toml``, LH1; terms
phase, tilt, curve, gibmag), the Crazyflie deck waved 20 s (``deck.toml``, LH1; the same
terms) and an LH2 room of 4 for 10 s (``lh2_room4.toml``; tilt, gibmag). Each solve is given
decoded values 2 mrad (1 sigma, per term and axis) off the truth; solved with the decoded
values held and with the terms solved (prior 3 mrad, the default): the median station error,
the mean NEES (honest covariance, 6 dof), the fraction of solved terms within 2 of their
sigmas of the truth and the median |error| / sigma.

Part 2, real (when ``../shared`` has them; no licence: read only): each pair of recordings
of unmoved stations (`compare_pairs`' pairs) solved with the decoded values held and with
each term set solved: station 1's difference between the two recordings (mm, deg, and in
combined honest sigmas), and how well the two recordings agree on the terms themselves (the
median over stations, terms and axes of their difference in combined sigmas, and the median
shift from OOTX): terms the data determines come out alike from both recordings. Writes
docs/results/factory_self_calibration.md. ~3 min.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np

import benchmarks._single_thread  # noqa: F401  (one BLAS thread per process)
from benchmarks import write_results
from benchmarks.compare_pairs import DATA, PAIRS, ROOT, imported, solve_imported
from benchmarks.deck_benchmark import EXACT_DECK
from benchmarks.joint_captures import nees
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.layout_compare import compare_layouts
from lhgraph.estimation.metrics import station_errors
from lhgraph.estimation.result import SolveResult
from lhgraph.sim.factory_errors import with_factory_errors
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIGS = ROOT / "configs" / "simulation"
LH1_TERMS = "phase,tilt,curve,gibmag"
LH2_TERMS = "tilt,gibmag"
SIMULATED = (("paper board wave 8 s (LH1)", "realistic", 8.0, LH1_TERMS),
             ("deck hand-held 20 s (LH1)", "deck", 20.0, LH1_TERMS),
             ("LH2 room of 4, 10 s", "lh2_room4", 10.0, LH2_TERMS))
REAL_TERMS = {"LH2": (LH2_TERMS, "tilt"), "LH1": (LH1_TERMS, "curve", "tilt,gibmag"),
              "hive": (LH1_TERMS, "curve", "tilt,gibmag")}
"""The term sets tried on each pair (by the pair name's first word)."""
PERTURBATION_RAD = 2e-3
DEG = 57.29577951308232


def simulated_row(name: str, config: str, duration_s: float, terms: str) -> str:
    """Part 1's row of one capture over seeds 1-5."""
    cfg = dataclasses.replace(load_simulation_config(CONFIGS / f"{config}.toml"),
                              duration_s=duration_s)
    figures: dict[str, list[float]] = {k: [] for k in
                                       ("held_mm", "solved_mm", "held_nees", "solved_nees",
                                        "z", "held_s", "solved_s")}
    for seed in range(1, 6):
        sim = simulate(cfg, seed)
        truth = {k: s.model for k, s in sim.truth.stations.items()}
        given = with_factory_errors(truth, terms.split(","), PERTURBATION_RAD,
                                    np.random.default_rng(seed))
        for label, options in (("held", EXACT_DECK),
                               ("solved", EXACT_DECK.with_values(factory_terms=terms))):
            tic = time.perf_counter()
            result = solve_graph(sim.board, sim.angles, given, options)
            figures[f"{label}_s"].append(time.perf_counter() - tic)
            errors = station_errors(sim.truth, result.stations)
            figures[f"{label}_mm"] += [e.position_norm_m * 1e3 for e in errors]
            figures[f"{label}_nees"] += [nees(sim.truth, result.stations, e.station)
                                         for e in errors]
        for sid, solved in (result.factory_terms or {}).items():
            for key, v in solved.items():
                err = np.subtract(v["solved_rad"], getattr(truth[sid].calibration, key))
                figures["z"] += list(np.abs(err) / np.array(v["sigma_rad"]))
    z = np.array(figures["z"])
    med = {k: float(np.median(v)) for k, v in figures.items()}
    mean_nees = {k: float(np.mean(figures[f"{k}_nees"])) for k in ("held", "solved")}
    return (f"| {name} | {terms} | {med['held_mm']:.2f} | {med['solved_mm']:.2f} | "
            f"{mean_nees['held']:.1f} | {mean_nees['solved']:.1f} | "
            f"{np.mean(z <= 2):.2f} ({len(z)}) | {np.median(z):.2f} | "
            f"{med['held_s']:.1f} / {med['solved_s']:.1f} |")


def term_agreement(a: SolveResult, b: SolveResult) -> tuple[float, float]:
    """The median over stations, terms and axes of the two results' solved-term difference
    in combined honest sigmas, and of their shift from OOTX (mrad)."""
    z, shift = [], []
    for sid, terms in (a.factory_terms or {}).items():
        for key, va in terms.items():
            vb = b.factory_terms[sid][key]
            z += list(np.abs(np.subtract(va["solved_rad"], vb["solved_rad"]))
                      / np.hypot(va["sigma_rad"], vb["sigma_rad"]))
            shift += list(np.abs(va["shift_rad"]) * 1e3) + list(np.abs(vb["shift_rad"]) * 1e3)
    return float(np.median(z)), float(np.median(shift))


def real_rows(tmp: Path) -> list[str]:
    """Part 2's rows (one per pair and term set)."""
    rows = []
    for name, logs in PAIRS.items():
        if not all((DATA / path).exists() for _, path in logs):
            rows.append(f"| {name} | skipped: data absent | | | | | | |")
            continue
        works = [imported(kind, DATA / path, tmp / f"{name[:3]}{i}")
                 for i, (kind, path) in enumerate(logs)]
        for terms in ("",) + REAL_TERMS[name.split()[0]]:
            options = GraphOptions.of(factory_terms=terms)
            a, b = (solve_imported(w, options) for w in works)
            d = compare_layouts(a.stations, b.stations).differences[0]
            agree = term_agreement(a, b) if terms else None
            rows.append(
                f"| {name} | {terms or 'none (held at OOTX)'} | {d.position_m * 1e3:.1f} | "
                f"{d.rotation_rad * DEG:.3f} | {d.sigma_position_m * 1e3:.2f} / "
                f"{d.sigma_rotation_rad * DEG:.4f} | {d.position_m / d.sigma_position_m:.1f} / "
                f"{d.rotation_rad / d.sigma_rotation_rad:.1f} | "
                + (f"{agree[0]:.1f} | {agree[1]:.1f} |" if agree else "- | - |"))
            print(name, terms or "none", flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks factory_self_calibration",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path,
                        default=ROOT / "docs" / "results" / "factory_self_calibration.md")
    parser.add_argument("--skip-real", action="store_true", help="part 1 only")
    args = parser.parse_args(argv)
    tic = time.perf_counter()
    lines = ["# Station self-calibration: solved factory terms", "",
             "Command: `python -m benchmarks factory_self_calibration`  ",
             f"{date.today()}; prior 3 mrad (`factory_sigma_rad`, the default) centred on the "
             "decoded values.", "",
             "## 1. Simulated: decoded values 2 mrad off the truth, seeds 1-5", "",
             "Station error: median over seeds and stations; NEES: mean (honest covariance, "
             "6 dof, expected 6); terms within 2 sigma: the fraction of solved terms (per "
             "station and axis; their count in brackets) within 2 of their honest sigmas of "
             "the truth (expected 0.95); solve time: median.", "",
             "| capture | terms solved | station mm, held | station mm, solved | NEES held | "
             "NEES solved | terms within 2 sigma | median abs error / sigma | solve s "
             "(held / solved) |", "|---|---|---|---|---|---|---|---|---|"]
    for spec in SIMULATED:
        lines.append(simulated_row(*spec))
        print(spec[0], flush=True)
    if not args.skip_real:
        lines += ["", "## 2. Real: pairs of recordings of unmoved stations", "",
                  "Station 1's difference between the pair's two solves, its combined honest "
                  "sigma and the difference in it (target: within 2 sigma); the terms' "
                  "agreement: the median over stations, terms and axes of the two solves' "
                  "difference in combined sigmas (about 0.7 when the data determines them), "
                  "and the median shift from OOTX.", "",
                  "| pair | terms solved | dp mm | dR deg | sigma mm / deg | dp / dR in sigma "
                  "| terms' difference in sigma | median shift from OOTX mrad |",
                  "|---|---|---|---|---|---|---|---|"]
        with tempfile.TemporaryDirectory(prefix="lhgraph-selfcal-") as tmp:
            lines += real_rows(Path(tmp))
    return write_results(args.output, lines, tic)


if __name__ == "__main__":
    raise SystemExit(main())
