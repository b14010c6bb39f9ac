"""Issue #16's simulated IMU figures beside the deck's (``deck_imu.py``): the solve time with
an IMU and fast against slow motion.

    python -m benchmarks imu_targets [--seeds 6] [--runs 5] [--jobs 2]
        [--output docs/results/imu_targets.md]

1. **Time**: the default 8 s capture (``configs/simulation/default.toml``, seed 1) with a
   simulated 1 kHz IMU (``lhgraph.sim.imu`` defaults otherwise), written as files; the whole
   ``lhgraph solve`` process (start-up, imports, files, solve, writing) with and without
   ``--imu imu.csv``, ``--runs`` of each interleaved, medians and their ratio (target:
   <= 1.5).
2. **Fast against slow motion**: the default layout with the 1 kHz IMU, *slow* (0.5 m/s, the
   board rocked by up to 20 deg) and *fast* (2.5 m/s, up to 45 deg: the rocking scales with
   the speed, so the turns are ~5x faster too), ``--seeds`` captures each, solved without and
   with the IMU (the defaults, and with ``gyro_preintegration``, the twist factors):
   station 1's median position and
   rotation error, the mean NEES of its 6x6 covariance (expected 6), and the ratio fast /
   slow of the median position error with the IMU (target: <= 1.5).
3. **Stations facing each other, a one-sided board**
   (``configs/simulation/facing_planar_imu.toml``: 170 deg apart, the 32-diode paper board
   never seen by both at once, a 1 kHz IMU): ``--seeds`` captures solved without the IMU
   (how many the light alone cannot join) and with it (the initialiser bridges the turns by
   dead reckoning, :mod:`lhgraph.estimation.imu.bridge`): with the defaults (GTSAM's
   combined IMU factors), and with the twist factors and ``gyro_preintegration`` (which
   ties the rotations across the turns) at their default noise and at the simulated
   part's (``SIMULATED_NOISE``): station 1's median position and rotation error and mean
   NEES (target: <= 2 mm / 0.05 deg).
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from benchmarks import prog
from lhgraph.errors import SolverError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.geometry.transforms import inverse, rotation_angle, se3_log
from lhgraph.io.files import check_writable
from lhgraph.io.imu import save_imu
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.sim.imu import ImuConfig
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs/simulation/default.toml"
FACING = ROOT / "configs/simulation/facing_planar_imu.toml"
IMU = ImuConfig(rate_hz=1000.0)
PREINTEGRATED = GraphOptions.of(gyro_preintegration=True)
SIMULATED_NOISE = GraphOptions.of(gyro_preintegration=True, gyro_sigma_rad_s=IMU.gyro_sigma_rad_s,
                               accel_sigma_mps2=2.5 * IMU.accel_sigma_mps2)
"""The IMU factors' noise set to the simulated part's instead of the defaults (set for the
real deck's vibration): its gyro noise per reading, and 2.5x its accelerometer noise (the
factor reads one sample per step, at the step's middle)."""
MOTIONS = {"slow": (0.5, 20.0), "fast": (2.5, 45.0)}
"""Family: (mean speed m/s, rocking amplitude deg)."""


def config(speed_mps: float, rocking_deg: float):
    base = load_simulation_config(CONFIG)
    return dataclasses.replace(base, imu=IMU, motion=dataclasses.replace(
        base.motion, speed_mps=speed_mps, rotation_amplitude_deg=rocking_deg))


def whole_process_seconds(runs: int) -> tuple[float, float]:
    """Median seconds of ``lhgraph solve`` without and with ``--imu`` (runs interleaved)."""
    sim = simulate(config(*MOTIONS["slow"]), 1)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        write_simulation(sim, d / "sim")
        save_imu(sim.imu.stream, d / "imu.csv")
        save_calibration({k: StationCalibration(s.model.calibration)
                          for k, s in sim.truth.stations.items()}, d / "ootx.toml")
        base = [sys.executable, "-m", "lhgraph", "solve", "--board", str(d / "sim/board.toml"),
                "--angles", str(d / "sim/angles.csv"), "--calibration", str(d / "ootx.toml"),
                "--output", str(d / "out.toml"), "--force", "--quiet"]
        times: dict[bool, list[float]] = {False: [], True: []}
        for _ in range(runs):
            for with_imu in (False, True):
                tic = time.perf_counter()
                subprocess.run(base + (["--imu", str(d / "imu.csv")] if with_imu else []),
                               check=True)
                times[with_imu].append(time.perf_counter() - tic)
    return statistics.median(times[False]), statistics.median(times[True])


def station_figures(sim, result) -> dict:
    """Station 1's position (mm) and rotation (deg) error, NEES and sigma (mm)."""
    T_true = sim.truth.relative_to_reference().pose(1)
    est = result.stations.relative_to_reference()
    T_est = est.pose(1)
    xi = se3_log(inverse(T_true) @ T_est)
    return {"pos_mm": float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]) * 1e3),
            "rot_deg": float(np.degrees(rotation_angle(T_true[:3, :3].T @ T_est[:3, :3]))),
            "nees": float(xi @ np.linalg.solve(est.stations[1].covariance, xi))}


def errors(family: str, seed: int) -> dict:
    """Station 1's errors and NEES without and with the IMU on one capture."""
    sim = simulate(config(*MOTIONS[family]), seed)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    out = {"family": family, "seed": seed}
    for name, imu, options in (("light", None, None), ("imu", sim.imu.stream, None),
                               ("preintegrated", sim.imu.stream, PREINTEGRATED)):
        f = station_figures(sim, solve_graph(sim.board, sim.angles, models, options, imu=imu))
        out[name] = (f["pos_mm"], f["rot_deg"], f["nees"])
    return out


def facing(seed: int, options: GraphOptions) -> tuple[bool, float, float, float]:
    """One facing capture: whether the light alone solved it, and with the IMU (``options``)
    station 1's position (mm) and rotation (deg) error and NEES."""
    sim = simulate(load_simulation_config(FACING), seed)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    try:
        solve_graph(sim.board, sim.angles, models)
        light = True
    except SolverError:
        light = False
    f = station_figures(sim, solve_graph(sim.board, sim.angles, models, options,
                                         imu=sim.imu.stream))
    return light, f["pos_mm"], f["rot_deg"], f["nees"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--output", type=Path, default=ROOT / "docs/results/imu_targets.md")
    args = ap.parse_args(argv)
    check_writable(args.output, overwrite=True)
    light_s, imu_s = whole_process_seconds(args.runs)
    rows = Parallel(n_jobs=args.jobs)(delayed(errors)(f, s) for f in MOTIONS
                                      for s in range(1, args.seeds + 1))
    lines = ["# Simulated IMU figures: solve time, fast against slow motion", "",
             f"Command: `python -m benchmarks imu_targets --seeds {args.seeds} --runs "
             f"{args.runs}`  ",
             f"Machine: {platform.machine()}, Python {platform.python_version()}; "
             f"{time.strftime('%Y-%m-%d')}. Default layout, 8 s, a simulated 1 kHz IMU.", "",
             "## 1. Whole `lhgraph solve` process, seed 1", "",
             f"- without `--imu`: median {light_s:.2f} s; with it: {imu_s:.2f} s "
             f"(of {args.runs} runs each, interleaved): ratio **{imu_s / light_s:.2f}** "
             "(target <= 1.5)", "",
             "## 2. Station 1 by motion, without and with the IMU", "",
             "Three solves per capture: light only / with the IMU (the defaults: GTSAM's "
             "combined IMU factors) / with the IMU and `gyro_preintegration = true` (the "
             "twist factors).", "",
             "| motion | captures | median position error mm | median rotation error deg | "
             "mean NEES (6 dof) |", "|---|---|---|---|---|"]
    medians = {}
    for family, (speed, rock) in MOTIONS.items():
        rs = [r for r in rows if r["family"] == family]
        solves = [np.array([r[k] for r in rs]) for k in ("light", "imu", "preintegrated")]
        medians[family] = [np.median(x[:, 0]) for x in solves[1:]]
        lines.append(f"| {family} ({speed:g} m/s, {rock:g} deg) | {len(rs)} | "
                     + " / ".join(f"{np.median(x[:, 0]):.3f}" for x in solves) + " | "
                     + " / ".join(f"{np.median(x[:, 1]):.4f}" for x in solves) + " | "
                     + " / ".join(f"{np.mean(x[:, 2]):.1f}" for x in solves) + " |")
    lines += ["", "Fast / slow, median position error with the IMU: **"
              f"{medians['fast'][0] / medians['slow'][0]:.2f}** (with the preintegrated gyro "
              f"{medians['fast'][1] / medians['slow'][1]:.2f}; target <= 1.5)."]
    lines += ["", "## 3. Stations facing each other, a one-sided board, the 1 kHz IMU", "",
              f"`{FACING.relative_to(ROOT)}`, seeds 1-{args.seeds}; target <= 2 mm / 0.05 deg, "
              "NEES in [3, 12].", ""]
    for name, options in (("the defaults (GTSAM's combined IMU factors)", GraphOptions()),
                          ("the twist factors with the preintegrated gyro, default IMU noise",
                           PREINTEGRATED),
                          ("the twist factors with the preintegrated gyro, the simulated "
                           "part's IMU noise (gyro "
                           f"{IMU.gyro_sigma_rad_s:g} rad/s, accelerometer "
                           f"{2.5 * IMU.accel_sigma_mps2:g} m/s^2)", SIMULATED_NOISE)):
        faced = np.array(Parallel(n_jobs=args.jobs)(delayed(facing)(s, options)
                                                    for s in range(1, args.seeds + 1)))
        lines.append(f"- {name}: the light alone solved {int(faced[:, 0].sum())} of "
                     f"{len(faced)}; with the IMU station 1's median error "
                     f"**{np.median(faced[:, 1]):.2f} mm / {np.median(faced[:, 2]):.3f} deg**"
                     ", per capture "
                     + ", ".join(f"{p:.2f} mm / {r:.3f} deg" for p, r in faced[:, 1:3])
                     + f"; mean NEES **{np.mean(faced[:, 3]):.1f}** (6 expected).")
    args.output.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
