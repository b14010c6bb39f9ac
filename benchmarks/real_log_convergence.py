"""Where the real Crazyflie LH1 log's solve spends its time, and how far it is from converged
when it stops (issue #14's run-time target: a 120 s deck log in <= 5 s).

    python -m benchmarks real_log_convergence [--caps 20 40 60 120] [--perturb-mm 1 3 10]
        [--runs 5] [--output docs/results/real_log_convergence.md]

1. ``lhgraph import crazyflie`` of the shared LH1 log into a temporary folder, and the whole
   ``lhgraph solve`` process on it (start-up, imports, files, solve, writing) ``--runs``
   times: issue #14's figure, median and range.
2. The default graph solve (the deck, the log's ``ootx.toml``) with the LM iteration limit
   set to each of ``--caps``, and once with the stricter stopping rule of before 2026-12-04
   (the board-step test on 95 % of the states' steps instead of their median, limit 120):
   iterations taken, status, in-process seconds, final error and station 1's distance from
   the stricter run's station 1 (position mm, rotation deg), i.e. how much the answer still
   moves after the default stop.
3. The default solve once more under ``cProfile``: the seconds in GTSAM's elimination, its
   linearisation (and, inside it, the Python factor callbacks of
   :class:`~lhgraph.estimation.graph.evaluator.FactorEvaluator`), the back-substitution,
   the retraction and everything else, per iteration.
4. What still moves: the default solve once more, recording after every accepted step how
   many board states turned by more than 1 mrad and 0.1 rad, the largest turn and how far
   station 1 moved (where the iterations past the first ten go).
5. How well LM's answer is determined: the default graph (the same noise levels) run to
   convergence, then LM again from that answer with station 1 moved by each of
   ``--perturb-mm`` along its x axis: iterations, final error and the distance of the new
   answer from the first (when LM finds a lower error elsewhere, the landscape is flat there
   and the answer depends on where LM starts, whatever the covariance says).

Skips (exit 0, one line) without the shared data.
"""

from __future__ import annotations

import argparse
import cProfile
import platform
import pstats
import tempfile
import time
from pathlib import Path

import gtsam
import numpy as np

from benchmarks import prog
from benchmarks.crazyflie_real_solve import LOGS, lhgraph
from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.noise import NoiseAdaptation
from lhgraph.estimation.graph.optimizer import LMParams, levenberg_marquardt
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.resolve import STEP_TOLERANCE_SIGMA, prepare, resolve_options
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.variables import BOARD_POSE, STATION_POSE, initial_values
from lhgraph.estimation.init.few_diode import FewDiodeInitialiser
from lhgraph.estimation.problem import build_problem
from lhgraph.geometry.transforms import rotation_angle
from lhgraph.io.angles import load_angles
from lhgraph.io.files import check_writable
from lhgraph.model.board import load_board
from lhgraph.workflow.inputs import station_models

ROOT = Path(__file__).resolve().parents[1]
LOG = LOGS["lh1"]
STAGES = {"elimination": "eliminateMultifrontal", "linearisation": "linearize",
          "back-substitution": "optimize", "retraction": "retract"}
"""Table row -> the name of the GTSAM built-in whose time it is."""
DEFAULT_CAP = GraphOptions().optimizer.max_iterations


def builtin_seconds(stats: pstats.Stats, name: str) -> float:
    """Total seconds of the profiled GTSAM built-in called ``name``."""
    return sum(v[3] for k, v in stats.stats.items() if k[2].endswith(f"gtsam.{name}>"))


def callback_seconds(stats: pstats.Stats) -> float:
    """Cumulative seconds of the evaluator's GTSAM callbacks (the closures called ``error``
    in evaluator.py)."""
    return sum(v[3] for k, v in stats.stats.items()
               if k[0].endswith("graph/evaluator.py") and k[2] == "error")


def default_graph(board, angles, models, cap: int):
    """The default solve's graph, evaluator, initial values, LM parameters (limit ``cap``)
    and options, as ``solve_graph`` builds them for this log."""
    options = GraphOptions.of(max_iterations=cap)
    angles, facts = prepare(angles, options, models)
    options = resolve_options(options, facts).options
    problem = build_problem(board, angles, models, angles.stations()[0])
    graph, ev = build_graph(problem, options)
    values = initial_values(ev.layout, FewDiodeInitialiser()(board, angles, problem))
    return graph, ev, values, LMParams.from_options(options), options


class StepRecorder:
    """The noise hook of the default solve, recording after every accepted LM step how far
    the board states turned (rad) and station 1 moved (m) since the step before."""

    def __init__(self, hook: NoiseAdaptation, layout):
        self.hook, self.keys = hook, layout.keys(BOARD_POSE)
        self.rows: list[tuple[int, int, float, float]] = []
        self._last = None

    def __call__(self, values: gtsam.Values, linearized=None) -> bool:
        R = np.stack([values.atPose3(k).rotation().matrix() for k in self.keys])
        p1 = values.atPose3(STATION_POSE.key(1)).translation()
        if self._last is not None:
            R0, q1 = self._last
            turn = np.arccos(np.clip((np.einsum("kij,kij->k", R0, R) - 1.0) / 2.0, -1, 1))
            self.rows.append((int(np.sum(turn > 1e-3)), int(np.sum(turn > 0.1)),
                              float(turn.max()), float(np.linalg.norm(p1 - q1))))
        self._last = (R, p1)
        return self.hook(values, linearized)


def still_moving(board, angles, models, cap: int, every: int = 5) -> list[str]:
    """Table rows of step 4 (section 3): per accepted step of the default solve (every
    ``every``-th and the last), how many board states still turn and how far station 1
    moves."""
    graph, ev, values, params, options = default_graph(board, angles, models, cap)
    recorder = StepRecorder(NoiseAdaptation(graph, ev, options), ev.layout)
    levenberg_marquardt(graph, values, ev.cost, ev.layout, params, recorder)
    rows = []
    for i, (n_mrad, n_big, largest, moved) in enumerate(recorder.rows, start=2):
        if i % every == 0 or i == len(recorder.rows) + 1:
            rows.append(f"| {i} | {n_mrad} | {n_big} | {np.degrees(largest):.1f} | "
                        f"{moved * 1e3:.3f} |")
    return rows


def perturbed(board, angles, models, perturb_mm: list[float], cap: int) -> list[str]:
    """Table rows of step 5 (section 4): LM to convergence (limit ``cap``), then again from
    its answer with station 1 moved by each distance (mm) along its own x axis."""
    graph, ev, values, params, options = default_graph(board, angles, models, cap)
    first = levenberg_marquardt(graph, values, ev.cost, ev.layout, params,
                                NoiseAdaptation(graph, ev, options))
    key = STATION_POSE.key(1)
    P0 = first.values.atPose3(key)
    rows = [f"| none (the default solve run to convergence) | {first.iterations} | "
            f"{first.status.value} | {first.final_error:.1f} | 0.00 |"]
    for mm in perturb_mm:
        start = gtsam.Values(first.values)
        start.update(key, P0.compose(gtsam.Pose3(gtsam.Rot3(), np.array([mm * 1e-3, 0, 0]))))
        fit = levenberg_marquardt(graph, start, ev.cost, ev.layout, params)
        moved = np.linalg.norm(fit.values.atPose3(key).translation() - P0.translation()) * 1e3
        rows.append(f"| {mm:g} mm | {fit.iterations} | {fit.status.value} | "
                    f"{fit.final_error:.1f} | {moved:.2f} |")
        print(rows[-1], flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.splitlines()[0])
    ap.add_argument("--caps", type=int, nargs="+", default=[20, 40, 60, 120])
    ap.add_argument("--perturb-mm", type=float, nargs="+", default=[1.0, 3.0, 10.0])
    ap.add_argument("--runs", type=int, default=5, help="whole-process runs of lhgraph solve")
    ap.add_argument("--output", type=Path,
                    default=ROOT / "docs/results/real_log_convergence.md")
    args = ap.parse_args(argv)
    if not LOG.is_file():
        print(f"skipped: {LOG} not found")
        return 0
    check_writable(args.output, overwrite=True)
    with tempfile.TemporaryDirectory() as tmp:
        imp = Path(tmp)
        lhgraph("import", "crazyflie", str(LOG), "--system-config",
                str(LOG.with_name("system-config.yaml")), "--output", str(imp), "--force")
        angles = load_angles(imp / "angles.csv")
        board = load_board(imp / "board.toml")
        models = station_models(imp / "ootx.toml")
        whole = sorted(lhgraph("solve", "--board", str(imp / "board.toml"), "--angles",
                               str(imp / "angles.csv"), "--calibration", str(imp / "ootx.toml"),
                               "--output", str(imp / "stations.toml"), "--force", "--quiet")[1]
                       for _ in range(args.runs))
        print(f"whole process: median {np.median(whole):.2f} s", flush=True)
    variants = [(f"limit {cap}", GraphOptions.of(max_iterations=cap)) for cap in sorted(args.caps)]
    variants.append(("95 % of the states' steps, limit 120",
                     GraphOptions.of(max_iterations=120, board_step_quantile=0.95,
                                     step_tolerance_sigma=STEP_TOLERANCE_SIGMA)))
    runs = []
    for label, options in variants:
        tic = time.perf_counter()
        result = solve_graph(board, angles, models, options)
        seconds = time.perf_counter() - tic
        runs.append((label, result, seconds))
        print(f"{label}: {result.iterations} iterations, {result.status}, {seconds:.1f} s",
              flush=True)
    T_last = runs[-1][1].stations.relative_to_reference().pose(1)
    lines = ["# The real Crazyflie LH1 log: convergence and where the time goes", "",
             "Command: `python -m benchmarks real_log_convergence`  ",
             f"Machine: {platform.machine()}, Python {platform.python_version()}; "
             f"{time.strftime('%Y-%m-%d')}  ",
             f"Log: `{LOG.parent.name}/{LOG.name}` ({len(angles)} hits), the default graph "
             "solve with the LM iteration limit set to each cap, and with the stricter "
             "stopping rule. Distance: station 1 (relative to station 0) from the stricter "
             "rule's.", "",
             f"Whole `lhgraph solve` process on the imported files (start-up, imports, files, "
             f"solve, writing; target <= 5 s): median **{np.median(whole):.2f} s** of "
             f"{len(whole)} runs (min {whole[0]:.2f}, max {whole[-1]:.2f}).", "",
             "## 1. The answer against the iteration limit and the stopping rule", "",
             "| run | iterations | status | seconds | final error | position from the "
             "stricter rule's mm | rotation deg | per iteration s |",
             "|---|---|---|---|---|---|---|---|"]
    for label, result, seconds in runs:
        T = result.stations.relative_to_reference().pose(1)
        dpos = np.linalg.norm(T[:3, 3] - T_last[:3, 3]) * 1e3
        drot = np.degrees(rotation_angle(T_last[:3, :3].T @ T[:3, :3]))
        lines.append(f"| {label} | {result.iterations} | {result.status} | {seconds:.1f} | "
                     f"{result.final_error:.1f} | {dpos:.2f} | {drot:.4f} | "
                     f"{result.timings_s['optimise'] / result.iterations:.3f} |")
    profile = cProfile.Profile()
    profile.enable()
    result = solve_graph(board, angles, models)
    profile.disable()
    stats = pstats.Stats(profile)
    total = result.timings_s["total"]
    n = result.iterations
    lines += ["", f"## 2. Where the default solve's time goes ({n} iterations, {total:.1f} s "
              "in-process under cProfile)", "", "| stage | seconds | per iteration s | share |",
              "|---|---|---|---|"]
    rows = {stage: builtin_seconds(stats, name) for stage, name in STAGES.items()}
    rows["initialise"] = result.timings_s["initialise"]
    rows["everything else"] = total - sum(rows.values())
    callbacks = callback_seconds(stats)
    for stage, seconds in rows.items():
        lines.append(f"| {stage} | {seconds:.2f} | {seconds / n:.3f} | {seconds / total:.0%} |")
        if stage == "linearisation":
            lines.append(f"| of which Python factor callbacks | {callbacks:.2f} | "
                         f"{callbacks / n:.3f} | {callbacks / total:.0%} |")
    lines += ["", "## 3. What still moves: the board states and station 1 after each accepted "
              f"step (the default solve, its {DEFAULT_CAP}-iteration limit)", "",
              "A state turns when its rotation changed since the step before; station 1's move "
              "is its position's.", "",
              "| step | states turning > 1 mrad | > 0.1 rad | largest turn deg | station 1 "
              "moved mm |", "|---|---|---|---|---|"]
    lines += still_moving(board, angles, models, DEFAULT_CAP)
    lines += ["", "## 4. LM again from its own answer with station 1 moved", "",
              "| station 1 moved | iterations | status | final error | new answer from the "
              "first, mm |", "|---|---|---|---|---|"]
    lines += perturbed(board, angles, models, args.perturb_mm, max(args.caps))
    lines.append("")
    args.output.write_text("\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
