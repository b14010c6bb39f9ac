"""What the spread of station 1 over 8 s slices of the hive recording is not: time shifts of
station 1's hits, motion-prior settings and per-diode angle biases, each against the
whole-bag solve.

    python3 benchmarks/hive_slice_spread.py [--bag PATH] [--output FILE.md] [--force]

Imports ``data8.11.bag`` (read from ../shared, never copied; sync-bit offsets corrected)
into a temporary folder, then for each variant solves the whole bag and three 8 s slices
4 s apart from the motion start (gib -1, curve +1, as ``hive_evaluation.py`` picks) and
reports station 1's position difference per slice (in station 1's own frame: x along its
line of sight), their spread about the slices' own mean, the slices' reported 1-sigma, and
the whole-bag residual rms; then, from the default whole-bag solve, how much of the residual
repeats at each diode (per station and axis: the rms of the diodes' mean residuals against
their spread about it). Writes the
markdown to ``--output`` (default docs/results/hive_slice_spread.md) and prints it.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.result import Residuals
from lhgraph.importers.hive import import_hive
from lhgraph.io.angles import Angles, load_angles
from lhgraph.io.files import check_writable
from lhgraph.model.board import load_board
from lhgraph.model.station import Convention
from lhgraph.workflow.inputs import station_models
from lhgraph.workflow.window import motion_start

REPO = Path(__file__).resolve().parents[1]
BAG = REPO.parent / "shared/data/hive-env8/data8.11.bag"
VARIANTS: dict[str, tuple[float, GraphOptions]] = {
    "default": (0.0, GraphOptions()),
    "station 1 hits +2 ms": (2e-3, GraphOptions()),
    "station 1 hits +4 ms": (4e-3, GraphOptions()),
    "station 1 hits -2 ms": (-2e-3, GraphOptions()),
    "motion-prior floor 0.02": (0.0, GraphOptions(min_psd_factor=0.02)),
    "fixed prior 3 m^2/s^3, 30 rad^2/s^3": (0.0, GraphOptions(
        adapt_motion_prior=False, accel_psd_pos=3.0, accel_psd_rot=30.0)),
    "diode biases, prior 20 µrad": (0.0, GraphOptions(diode_bias_sigma_rad=2e-5)),
    "diode biases, prior 50 µrad": (0.0, GraphOptions(diode_bias_sigma_rad=5e-5)),
}


def shifted(angles: Angles, station: int, shift_s: float) -> Angles:
    """``angles`` with ``station``'s hits ``shift_s`` later, rows in time order."""
    t = angles.time + shift_s * (angles.lighthouse == station)
    order = np.argsort(t, kind="stable")
    out = angles.select(order)
    out.time = t[order]
    return out


def diode_means(res: Residuals, min_hits: int = 50) -> list[tuple[int, int, int, float, float]]:
    """Per (station, axis): the diodes with ``min_hits`` inlier residuals, the rms over them of
    their mean residual and the median of their standard deviation (µrad)."""
    ok = res.weight > 0.5
    rows = []
    for station in np.unique(res.lighthouse).tolist():
        for axis in (0, 1):
            means, spreads = [], []
            for sensor in np.unique(res.sensor).tolist():
                r = res.residual_rad[ok & (res.lighthouse == station) & (res.axis == axis)
                                     & (res.sensor == sensor)]
                if len(r) >= min_hits:
                    means.append(r.mean())
                    spreads.append(r.std())
            rows.append((station, axis, len(means), float(np.sqrt(np.mean(np.square(means))))
                         * 1e6, float(np.median(spreads)) * 1e6))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bag", type=Path, default=BAG)
    parser.add_argument("--output", default=str(REPO / "docs/results/hive_slice_spread.md"))
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args()
    if not args.bag.is_file():
        print(f"{args.bag}: not there, nothing measured")
        return 0
    out = check_writable(args.output, args.force)
    with tempfile.TemporaryDirectory() as tmp:
        import_hive(args.bag, tmp)
        board = load_board(Path(tmp) / "board.toml")
        angles = load_angles(Path(tmp) / "angles.csv")
        models = station_models(Path(tmp) / "ootx.toml", Convention(-1, 1))
    t0 = motion_start(angles)
    lines = ["# The hive recording: station 1 over 8 s slices, variants", "",
             f"`python3 benchmarks/hive_slice_spread.py`, {time.strftime('%Y-%m-%d')}. Station "
             "1's position from each 8 s slice (from the motion start, 4 s apart) less the "
             "whole-bag solution's, in station 1's frame (x along its line of sight), mm; "
             "sigma = the slices' median reported 1-sigma (position, largest axis).", "",
             "| variant | whole-bag rms µrad | slice differences (x, y, z) mm | rms of the "
             "slice distances mm | slices about their mean mm | slice sigma mm |",
             "|---|---|---|---|---|---|"]
    default = None
    for name, (shift_s, options) in VARIANTS.items():
        data = shifted(angles, 1, shift_s) if shift_s else angles
        whole = solve_graph(board, data, models, options)
        default = default or whole
        L_whole = whole.stations.pose(1)
        diffs, sigmas = [], []
        for k in range(3):
            part = data.select((data.time >= t0 + 4 * k) & (data.time < t0 + 4 * k + 8))
            r = solve_graph(board, part, models, options)
            diffs.append((np.linalg.inv(L_whole) @ r.stations.pose(1))[:3, 3] * 1e3)
            sigmas.append(np.sqrt(np.max(np.diag(r.stations.stations[1].covariance)[3:])) * 1e3)
        d = np.array(diffs)
        lines.append(f"| {name} | {whole.residuals.rms_urad():.1f} | "
                     + "; ".join(f"({x:+.1f}, {y:+.1f}, {z:+.1f})" for x, y, z in d)
                     + f" | {np.sqrt(np.mean(np.sum(d**2, axis=1))):.2f} | "
                     f"{np.sqrt(np.mean(np.sum((d - d.mean(axis=0))**2, axis=1))):.2f} | "
                     f"{np.median(sigmas):.2f} |")
        print(lines[-1], flush=True)
    lines += ["", "What repeats at a diode: the default whole-bag solve's inlier residuals (robust "
              "weight > 0.5) per station, axis and diode (diodes with at least 50): the rms "
              "over the diodes of their mean residual, against the median of their spread "
              "about it.", "", "| station | axis | diodes | rms of the diode means µrad | "
              "median spread µrad |", "|---|---|---|---|---|"]
    for station, axis, n, means, spread in diode_means(default.residuals):
        lines.append(f"| {station} | {axis} | {n} | {means:.1f} | {spread:.1f} |")
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
