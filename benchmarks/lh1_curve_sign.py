"""The LH1 factory terms' signs on the Bitcraze logs: the deck firmware's against the
broadcast values in the convention that fits libsurvive's and hive's recordings.

    python -m benchmarks lh1_curve_sign [--output FILE] [--force]

The deck firmware corrects LH1 angles with the curve term's sign opposite to the one our
model takes for broadcast OOTX values (docs/model.md: the sign that fits libsurvive's and
hive's recordings best), and with the gib term's sign the same as ours after its phase
shift. Each shared LH1 log is imported (``lhgraph import crazyflie``) and solved (the
default graph, the Python API) under four factory models built from the same file:

- ``firmware``: curve and gib as the firmware applies them (its ``correctedAngle``);
- ``broadcast curve`` (the default since 2026-12-08): the firmware's gib, the curve as
  broadcast;
- ``broadcast curve and gib``: both terms in the libsurvive / hive convention on the
  broadcast values (the gib's sign flipped from the firmware's);
- ``broadcast gib``: the firmware's curve, the gib flipped.

Each solve is then judged against the log's Qualisys recording
(``benchmarks/anchored_stations.py``'s resection under the same model): the anchored fit's
median residual per station and axis (a model nearer the truth leaves less), station 1's
distance from station 0 (anchored and ours), ours - anchored (position, along the
baseline, rotation); the solve's own light-only cost and median residual; and the two logs'
station 1 against each other (the pair of unmoved stations). Writes
docs/results/lh1_curve_sign.md. Data: Crazyflie (no licence: read from ../shared only).
~3 min.
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import begin, write_results
from benchmarks.anchored_stations import anchored, cells, geometry, station_1
from benchmarks.compare_pairs import imported_logs
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.model.bitcraze import firmware_equivalent
from lhgraph.model.calibration import StationCalibration, load_calibration, save_calibration
from lhgraph.model.station import FactoryCalibration
from lhgraph.workflow.solve import run_config
from lhgraph.workflow.solve_config import SolveConfig

LOGS = ("lh1_crossingBeam_move/log02", "lh1_crossingBeam_flight/log00")


def gib_flipped(c: FactoryCalibration) -> FactoryCalibration:
    """``c`` with its gib term's sign flipped and the phase shift taken off again: the
    broadcast gibphase in our convention."""
    return replace(c, gibphase=np.angle(np.exp(1j * (c.gibphase - np.pi - c.phase))))


VARIANTS = {
    "firmware": firmware_equivalent,
    "broadcast curve (default)": lambda c: c,
    "broadcast curve and gib": gib_flipped,
    "broadcast gib": lambda c: gib_flipped(firmware_equivalent(c)),
}
"""Per variant, our factory model from the imported (default) one."""


def variant_calibration(work: Path, name: str) -> Path:
    """The imported log ``work``'s ``ootx.toml`` under variant ``name``, written beside it."""
    cal: dict[int, StationCalibration] = load_calibration(work / "ootx.toml")
    out = work / f"ootx-variant-{list(VARIANTS).index(name)}.toml"
    return save_calibration({k: replace(c, calibration=VARIANTS[name](c.calibration))
                             for k, c in cal.items()}, out, overwrite=True)


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "LH1 factory-term signs on the Bitcraze logs")
    lines += [f"{date.today()}; each LH1 log solved (default graph) under four factory "
              "models from its `system-config.yaml` (benchmarks/lh1_curve_sign.py) and "
              "judged against its Qualisys path (the anchored resection, same model). "
              "Residuals in µrad; station 1 in station 0's frame; differences: position "
              "(mm), along the baseline (mm, negative: too short), rotation (deg).", "",
              "| log | model | anchored fit: median residual | station 0 axis 0 / 1, "
              "station 1 axis 0 / 1 | anchored distance (m) | ours (m) | ours - anchored "
              "| | | our solve's cost | its median residual |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    ours: dict[str, dict[str, np.ndarray]] = {name: {} for name in VARIANTS}
    truth: dict[str, dict[str, np.ndarray]] = {name: {} for name in VARIANTS}
    with tempfile.TemporaryDirectory(prefix="lhgraph-curve-") as tmp:
        for log, work in imported_logs(LOGS, Path(tmp)):
            if work is None:
                lines.append(f"| {log} | skipped: data absent |" + " |" * 9)
                continue
            for name in VARIANTS:
                result = run_config(SolveConfig(
                    board=work / "board.toml", angles=work / "angles.csv",
                    calibration=variant_calibration(work, name), graph=GraphOptions()))
                ref = anchored(work, result.stations, result.trajectory)
                ours[name][log] = station_1(geometry(result.stations))
                truth[name][log] = station_1(ref.T_mocap_lh)
                res = result.residuals
                median = float(np.median(np.abs(res.residual_rad))) * 1e6
                axes = " / ".join(f"{v * 1e6:.0f}"
                                  for v in ref.median_residual_by_axis_rad.values())
                lines.append(
                    f"| {log} | {name} | {ref.median_residual_rad * 1e6:.0f} | "
                    f"{axes} | "
                    f"{np.linalg.norm(truth[name][log][:3, 3]):.4f} | "
                    f"{np.linalg.norm(ours[name][log][:3, 3]):.4f} | "
                    f"{cells(ours[name][log], truth[name][log])} | "
                    f"{result.final_error:.0f} | {median:.1f} |")
                print(lines[-1], flush=True)
    lines += ["", "## The pair of unmoved stations", "",
              f"Station 1's difference, {LOGS[0]} - {LOGS[1]}.", "",
              "| model | anchored | | | ours | | |", "|---|---|---|---|---|---|---|"]
    for name in VARIANTS:
        if all(log in ours[name] for log in LOGS):
            a, b = LOGS
            lines.append(f"| {name} | {cells(truth[name][a], truth[name][b])} | "
                         f"{cells(ours[name][a], ours[name][b])} |")
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
