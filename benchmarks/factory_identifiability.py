"""Identifiability of the stations' factory terms (issue: station self-calibration, first
step): how well each capture determines each term, and what it trades against the poses.

For each capture the default graph solve runs with ``factory_information = true``
(:mod:`lhgraph.estimation.graph.factory_information`: the terms' Gauss-Newton information at
the result, every graph variable free). Captures: simulated, the paper's 32-diode board
waved for 8 s (``realistic.toml``: LH1 factory terms of a real pair), the Crazyflie deck
waved by hand for 30 s (``deck.toml``) and the same deck flown level (a circle, 5 deg of
rotation), and an LH2 room of 4 (``lh2_room4.toml``); real, the shared Crazyflie logs and
hive's data8.11 when ``../shared`` has them (imported as `compare_pairs` does; no licence:
read from ../shared only). Per capture and term: its sigma with every graph variable held
("alone"), with the poses free ("free"), with every term free too ("joint"; inf: the capture
cannot tell it from the others or the poses), its largest correlation with a station-pose
coordinate, and the largest station shift per mrad of its error left unmodelled. Writes
docs/results/factory_identifiability.md. ~4 min.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks.compare_pairs import DATA, PAIRS, ROOT, imported, solve_imported
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.result import SolveResult
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIGS = ROOT / "configs" / "simulation"
OPTIONS = GraphOptions.of(factory_information=True)


def simulated(name: str, duration_s: float, **motion: object) -> SolveResult:
    """Solve a simulated capture of ``configs/simulation/NAME.toml`` (seed 1)."""
    cfg = load_simulation_config(CONFIGS / f"{name}.toml")
    cfg = dataclasses.replace(cfg, duration_s=duration_s,
                              motion=dataclasses.replace(cfg.motion, **motion))
    sim = simulate(cfg, 1)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    return solve_graph(sim.board, sim.angles, models, OPTIONS)


def table(name: str, result: SolveResult) -> list[str]:
    """The capture's rows."""
    f = result.factory_information or {}
    rows = []
    for i, term in enumerate(f.get("terms", [])):
        alone, free, joint = (f[k][i] * 1e3 for k in
                              ("sigma_alone_rad", "sigma_free_rad", "sigma_joint_rad"))
        corr = f["pose_correlation"][i]
        rows.append(f"| {name} | {term} | {alone:.4g} | {free:.4g} | {joint:.4g} | "
                    + (f"{corr:.3f} ({f['pose_coordinate'][i]})" if np.isfinite(corr) else "-")
                    + f" | {f['station_shift_mm_per_mrad'][i]:.2f} |")
    if f.get("unused"):
        rows.append(f"| {name} | not in the model here: {', '.join(f['unused'])} | | | | | |")
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks factory_identifiability",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path,
                        default=ROOT / "docs" / "results" / "factory_identifiability.md")
    args = parser.parse_args(argv)
    lines = ["# Identifiability of the factory terms", "",
             "Command: `python -m benchmarks factory_identifiability`  ",
             f"Default graph solve with `factory_information = true`; {date.today()}. Sigmas "
             "in mrad (white noise model at the result); shift: the largest station position "
             "shift (mm) per mrad of the term's error left unmodelled.", "",
             "| capture | term | sigma alone | sigma free | sigma joint | largest pose "
             "correlation | shift mm/mrad |", "|---|---|---|---|---|---|---|"]
    captures = [
        ("sim: paper board wave 8 s (LH1)", lambda: simulated("realistic", 8.0)),
        ("sim: deck hand-held 30 s (LH1)", lambda: simulated("deck", 30.0)),
        ("sim: deck flight 30 s (LH1)", lambda: simulated(
            "deck", 30.0, pattern="circle", speed_mps=0.5, rotation_amplitude_deg=5.0)),
        ("sim: LH2 room of 4, 20 s", lambda: simulated("lh2_room4", 20.0)),
    ]
    with tempfile.TemporaryDirectory(prefix="lhgraph-factory-") as tmp:
        logs = {path: kind for pair in PAIRS.values() for kind, path in pair}
        for i, (path, kind) in enumerate(logs.items()):
            if (DATA / path).exists():
                captures.append((f"real: {path}", lambda path=path, kind=kind, i=i: solve_imported(
                    imported(kind, DATA / path, Path(tmp) / f"log{i}"), OPTIONS)))
            else:
                lines.append(f"| real: {path} | skipped: data absent | | | | | |")
        for name, run in captures:
            rows = table(name, run())
            lines += rows
            print(name, len(rows), "terms", flush=True)
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
