"""How close the graph comes to the information in the data: station 1's error against a
Cramér–Rao-type bound at the true poses, per family of simulated captures (issue #17, a first
measurement; the bound itself is checked against a Monte-Carlo spread in
tests/test_bound.py).

    python -m benchmarks crlb [--seeds 6] [--protocol 10] [--jobs 2]
        [--motion-prior-estimate chi2|redundancy]
        [--output docs/results/crlb.md] [--force]

**The bound.** For each capture, the Fisher information of the graph's own measurement model
evaluated at the truth (the true board poses and body twists at the state times, the true
station poses), under the simulator's own noise:

- per diode: the pulse centre from two edges quantised at ``sample_rate_hz`` (each uniform
  over a tick: variance tick^2 / 24 for their mean) plus the family's Gaussian
  ``angle_sigma_rad``;
- per sweep, common to its diodes: the sync edge quantised alike (tick^2 / 12), i.e. the
  graph's sweep-offset variables with that prior;
- the board's motion: the graph's white-noise-on-acceleration prior, its strength set so that
  the true motion's chi2 per degree of freedom is 1 (the oracle strength, no tuned floor).

Reflections are left out of the bound (a bound for the direct hits). The inverse of the
information (eliminated as the solver does) gives station 1's 6x6 covariance; the bound on
its position error is ``sqrt(trace(P_pos))``, the rms of the error's length an efficient
estimator would reach. **Efficiency** = bound / actual error of the default solve, per
capture; per family the median and the quartiles, and the ratio of the median error to the
median bound, beside the solve's mean NEES (6 dof). Also given: the *known-path* bound, the
same information with the board's poses and twists held at the truth (what knowing the
path exactly would allow: a floor no estimator of the path can reach).

Caveats, both measured: the bound treats every quantisation error as independent, but the
simulator's are not (its sync edges sit on a regular 8.333 ms grid, so their fractional
sample phase, and with it the per-sweep offset, repeats every three slots); where the
quantisation dominates, the solve beats this "bound". The family *i.i.d.* (default layout,
48 MHz sampling, 50 µrad Gaussian per hit) has the noise the bound assumes. And the motion
prior at the true motion's strength is the graph's own model of the motion: the simulator's
motion is smooth and deterministic, which a white-noise-on-acceleration prior of any strength
describes only roughly.

Families: the first ``--protocol`` captures of the paper protocol
(configs/paper_simulation.toml), and ``--seeds`` seeds of configs/simulation/fast, ninety
(stations 90° apart), far, facing, default with 3 % reflections, and the i.i.d. family.
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
from lhgraph.estimation.bound import information_bound, true_values
from lhgraph.estimation.graph.options import PRIOR_ESTIMATES, GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.problem import build_problem
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.files import check_writable
from lhgraph.sim.config import paper_protocol
from lhgraph.sim.simulate import SimulatedCapture, load_simulation_config, simulate

ROOT = Path(__file__).resolve().parents[1]
ROTOR_RAD_S = 2 * np.pi * 60.0


def bounds(sim: SimulatedCapture) -> tuple[float, float, float]:
    """Station 1's position bound (m, rms length) with the motion prior at the true motion's
    strength, and with the board's path known (:mod:`lhgraph.estimation.bound`), under the
    simulator's noise (module docstring); and that strength, as a factor on the default
    PSDs."""
    tick_rad = ROTOR_RAD_S / sim.config.sample_rate_hz
    options = GraphOptions.of(
        angle_sigma_rad=float(np.sqrt(tick_rad**2 / 24 + sim.config.noise.angle_sigma_rad**2)),
        sweep_offset_sigma_rad=tick_rad / np.sqrt(12))
    angles = sim.angles.select(np.flatnonzero(~sim.reflected))
    models = {k: s.model for k, s in sim.truth.stations.items()}
    problem = build_problem(sim.board, angles, models, 0)
    truth = true_values(sim.motion.pose, sim.truth, problem.state_time)
    bound = information_bound(problem, truth, options)
    known = information_bound(problem, truth, options, known_path=True)
    return bound.position_rms_m(1), known.position_rms_m(1), bound.psd_factor


def run(family: str, config, seed: int | None, estimate: str) -> dict[str, float]:
    """One capture: the solve's error and NEES (the default options but the motion prior's
    ``estimate``), and the bound."""
    sim = simulate(config, seed)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    result = solve_graph(sim.board, sim.angles, models,
                         GraphOptions.of(motion_prior_estimate=estimate))
    truth = sim.truth.relative_to_reference().pose(1)
    est = result.stations.relative_to_reference().stations[1]
    xi = se3_log(inverse(truth) @ est.T_world_lh)
    bound_m, known_m, psd_factor = bounds(sim)
    return {"family": family,
            "error_mm": float(np.linalg.norm(est.T_world_lh[:3, 3] - truth[:3, 3])) * 1e3,
            "bound_mm": bound_m * 1e3,
            "known_mm": known_m * 1e3, "psd_factor": psd_factor,
            "solve_psd_factor": float(result.diagnostics["accel_psd_pos"]
                                      / GraphOptions().motion.accel_psd_pos),
            "nees": float(xi @ np.linalg.solve(est.covariance, xi)),
            "solve_sigma_mm": float(np.sqrt(np.trace(est.covariance[3:, 3:]))) * 1e3}


def families(protocol: int, seeds: int) -> list[tuple[str, object, int | None]]:
    """(family, config, seed) of every capture."""
    jobs = [("paper protocol", c, None)
            for _, c in paper_protocol(ROOT / "configs/paper_simulation.toml")[:protocol]]
    sim_dir = ROOT / "configs/simulation"
    default = load_simulation_config(sim_dir / "default.toml")
    named = {"fast": load_simulation_config(sim_dir / "fast.toml"),
             "wide (90°)": load_simulation_config(sim_dir / "ninety.toml"),
             "far": load_simulation_config(sim_dir / "far.toml"),
             "facing": load_simulation_config(sim_dir / "facing.toml"),
             "3 % reflections": dataclasses.replace(default, noise=dataclasses.replace(
                 default.noise, reflection_fraction=0.03)),
             "i.i.d. (48 MHz, 50 µrad Gaussian)": dataclasses.replace(
                 default, sample_rate_hz=48e6,
                 noise=dataclasses.replace(default.noise, angle_sigma_rad=5e-5))}
    for name, config in named.items():
        jobs += [(name, config, s) for s in range(300, 300 + seeds)]
    return jobs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--protocol", type=int, default=10)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--output", default=str(ROOT / "docs/results/crlb.md"))
    parser.add_argument("--force", action="store_true")
    parser.add_argument("--motion-prior-estimate", choices=PRIOR_ESTIMATES,
                        default=GraphOptions().motion.motion_prior_estimate,
                        help="GraphOptions.motion_prior_estimate of the solves")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    t0 = time.perf_counter()
    rows = Parallel(n_jobs=args.jobs)(delayed(run)(f, c, s, args.motion_prior_estimate)
                                      for f, c, s in families(args.protocol, args.seeds))
    lines = ["# Station 1 against the Cramér–Rao bound at the truth", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"{time.strftime('%Y-%m-%d')}. Bound and efficiency as defined in the script's "
             "docstring (the graph's measurement model at the true poses, the simulator's "
             "quantisation and Gaussian noise, the motion prior at the true motion's "
             "strength); error = `solve_graph` with the default options, "
             f"`motion_prior_estimate = \"{args.motion_prior_estimate}\"`.", "",
             "| family | captures | median error mm | median bound mm | median error / "
             "median bound | efficiency median (quartiles) | known-path bound mm (median) | "
             "solve's own sigma mm (median) | mean NEES (6 dof) | motion PSD factor: "
             "true motion / solve (medians) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for family in dict.fromkeys(r["family"] for r in rows):
        rs = [r for r in rows if r["family"] == family]
        err = np.array([r["error_mm"] for r in rs])
        bound = np.array([r["bound_mm"] for r in rs])
        eff = bound / err
        q1, q2, q3 = np.percentile(eff, [25, 50, 75])
        lines.append(f"| {family} | {len(rs)} | {np.median(err):.3f} | {np.median(bound):.3f} "
                     f"| {np.median(err) / np.median(bound):.2f} | {q2:.2f} ({q1:.2f}-{q3:.2f})"
                     f" | {np.median([r['known_mm'] for r in rs]):.3f}"
                     f" | {np.median([r['solve_sigma_mm'] for r in rs]):.3f} | "
                     f"{np.mean([r['nees'] for r in rs]):.1f} | "
                     f"{np.median([r['psd_factor'] for r in rs]):.2g} / "
                     f"{np.median([r['solve_psd_factor'] for r in rs]):.2g} |")
        print(lines[-1], flush=True)
    lines += ["", f"Run time: {(time.perf_counter() - t0) / 60:.1f} min."]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
