"""The paper's simulation protocol run with the paper's method (``solve_paper``).

Simulates every capture of ``configs/paper_simulation.toml`` (10 setups x 5 measurements,
quantisation noise only), calibrates it with :func:`lhgraph.estimation.baseline.solve_paper`
and prints
the paper's Table III layout (MAE and average per-setup SD of X, Y, Z in mm and alpha, beta,
gamma in degrees) next to the paper's own figures, plus the median run time per capture.

    python -m benchmarks paper_protocol_baseline [--limit N] [--jobs 2] [--warm-start]
        [--reconstruction full|half|merge] [--kabsch-points board|sensors]
        [--output docs/results/baseline_paper_protocol.md] [--force]

SD = sample standard deviation (ddof 1) of the signed error over a setup's measurements,
averaged over the setups (as the paper does); MAE = mean over all captures of |error|.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from benchmarks import command, prog
from lhgraph.errors import LhgraphError
from lhgraph.estimation.baseline import PaperOptions, solve_paper
from lhgraph.io.files import check_writable
from lhgraph.sim.simulate import SimulationConfig, paper_protocol, simulate
from lhgraph.workflow.study import (
    COLUMNS,
    PAPER_MAE,
    PAPER_SD,
    protocol_statistics,
    signed_errors,
)

ROOT = Path(__file__).resolve().parent.parent


def run_one(name: str, config: SimulationConfig, options: PaperOptions) -> dict:
    """Simulate and calibrate one capture; signed errors of each non-reference station."""
    capture = simulate(config)
    models = {k: s.model for k, s in capture.truth.stations.items()}
    tic = time.perf_counter()
    try:
        result = solve_paper(capture.board, capture.angles, models, options=options)
    except LhgraphError as exc:
        return {"name": name, "error": str(exc), "seconds": time.perf_counter() - tic}
    seconds = time.perf_counter() - tic
    return {"name": name, "signed": signed_errors(capture.truth, result.stations),
            "seconds": seconds,
            "status": result.status, "rms_urad": result.residuals.rms_urad()}


def fmt(values: list[float] | np.ndarray) -> list[str]:
    return [f"{v:.1f}" if i < 3 else f"{v:.2f}" for i, v in enumerate(values)]


def table(rows: list[tuple[str, list[str]]], header: list[str]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join([label, *cells]) + " |" for label, cells in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.splitlines()[0])
    ap.add_argument("--protocol", default=str(ROOT / "configs" / "paper_simulation.toml"))
    ap.add_argument("--limit", type=int, default=None, help="only the first N captures")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--warm-start", action="store_true")
    ap.add_argument("--reconstruction", default="full", choices=["full", "half", "merge"])
    ap.add_argument("--kabsch-points", default="board", choices=["board", "sensors"])
    ap.add_argument("--output", default=str(ROOT / "docs" / "results" /
                                            "baseline_paper_protocol.md"))
    ap.add_argument("--force", action="store_true", help="overwrite the output file")
    args = ap.parse_args(argv)
    try:
        check_writable(args.output, args.force)
        captures = paper_protocol(args.protocol)
    except LhgraphError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.limit is not None:
        captures = captures[:args.limit]
    options = PaperOptions(reconstruction=args.reconstruction, warm_start=args.warm_start,
                           kabsch_points=args.kabsch_points)

    tic = time.perf_counter()
    results = Parallel(n_jobs=args.jobs, verbose=5)(
        delayed(run_one)(name, cfg, options) for name, cfg in captures)
    wall = time.perf_counter() - tic

    failed = [r for r in results if "error" in r]
    ok = [r for r in results if "error" not in r]
    signed = np.concatenate([r["signed"] for r in ok]) if ok else np.empty((0, 6))
    setups: dict[str, list[np.ndarray]] = {}
    for r in ok:
        setups.setdefault(r["name"].split("/")[0], []).append(r["signed"])
    stats = protocol_statistics([r["name"] for r in ok], [r["signed"] for r in ok])
    mae, sd = stats.mae, stats.sd
    seconds = np.array([r["seconds"] for r in results])

    header = ["", *COLUMNS]
    main_table = table([("MAE (ours)", fmt(mae)), ("MAE (paper)", fmt(PAPER_MAE)),
                        ("Average SD (ours)", fmt(sd)), ("Average SD (paper)", fmt(PAPER_SD))],
                       header)
    per_setup = table([(name, fmt(np.mean(np.abs(np.concatenate(v)), axis=0)))
                       for name, v in setups.items()], ["setup (MAE)", *COLUMNS])
    norms = np.linalg.norm(signed[:, :3], axis=1)
    text = "\n".join([
        "# Paper baseline on the paper's simulation protocol",
        "",
        f"Produced by `{command(__file__, argv)}` on {platform.node()} ({os.cpu_count()} cores, "
        f"{args.jobs} workers), {time.strftime('%Y-%m-%d %H:%M')}.",
        "",
        f"Captures: {len(results)} of {len(paper_protocol(args.protocol))} "
        f"({len(failed)} failed); options: reconstruction={options.reconstruction}, "
        f"warm_start={options.warm_start}, kabsch_points={options.kabsch_points}, "
        f"outlier_mads={options.outlier_mads:g}.",
        "",
        main_table,
        "",
        f"Position error norm: median {np.median(norms):.1f} mm, max {np.max(norms):.1f} mm. "
        f"Run time per capture: median {np.median(seconds):.1f} s (max {np.max(seconds):.1f} s); "
        f"wall time {wall / 60:.1f} min. Median per-hit residual RMS "
        f"{np.median([r['rms_urad'] for r in ok]):.0f} µrad.",
        "",
        "Per setup:",
        "",
        per_setup,
        "",
        *(f"- failed: {r['name']}: {r['error']}" for r in failed),
    ]) + "\n"
    print(text)
    check_writable(args.output, args.force)
    Path(args.output).write_text(text)
    print(f"written to {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
