"""The LH1 factory terms' signs judged by a mocap: on the Bitcraze logs the deck firmware's
against the broadcast values in our convention, and on hive's bags.

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
station 1 against each other (the pair of unmoved stations).

Then the same question on hive's two bags of one layout (its OptiTrack as the judge): each
bag solved with its broadcast OOTX values in our convention, with the curve negated (the
firmware's sign) and with the gib flipped; the two solves' station 1 against each other and
each bag tracked through its own stations against its OptiTrack
(``benchmarks/hive_pair.py``'s measure). Writes docs/results/lh1_curve_sign.md. Data:
Crazyflie and hive (no licence: read from ../shared only). ~4 min.
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import begin, write_results
from benchmarks.anchored_stations import anchored, cells, geometry, station_1
from benchmarks.compare_pairs import DATA, imported, imported_logs, solve_imported
from benchmarks.hive_pair import BAGS, pair_row, tracked_error
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.model.bitcraze import firmware_equivalent
from lhgraph.model.calibration import StationCalibration, load_calibration, save_calibration
from lhgraph.model.station import FactoryCalibration

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


HIVE_VARIANTS = {
    "broadcast, our convention (default)": lambda c: c,
    "curve negated (the firmware's sign)": firmware_equivalent,
    "gib flipped": lambda c: replace(c, gibphase=np.asarray(c.gibphase) + np.pi),
}
"""Per variant, hive's factory model from the imported one."""


def variant_calibration(work: Path, name: str, variants: dict = VARIANTS) -> Path:
    """The imported log ``work``'s ``ootx.toml`` under variant ``name`` of ``variants``,
    written beside it."""
    cal: dict[int, StationCalibration] = load_calibration(work / "ootx.toml")
    out = work / f"ootx-variant-{list(variants).index(name)}.toml"
    return save_calibration({k: replace(c, calibration=variants[name](c.calibration))
                             for k, c in cal.items()}, out, overwrite=True)


def hive_rows(work: Path) -> list[str]:
    """hive's bags under each of :data:`HIVE_VARIANTS`: the pair row, then per bag the track
    error through its own stations (table rows)."""
    folders = [imported("hive", DATA / "hive-env8" / f"{bag}.bag", work / bag)
               for bag in BAGS]
    pairs, tracks = [], []
    for name in HIVE_VARIANTS:
        calibrations = [variant_calibration(f, name, HIVE_VARIANTS) for f in folders]
        results = [solve_imported(f, GraphOptions(), c)
                   for f, c in zip(folders, calibrations, strict=True)]
        pairs.append(pair_row(name, [r.stations for r in results]))
        for f, c, r in zip(folders, calibrations, results, strict=True):
            tracks.append(f"| {name} | {f.name} | {r.final_error:.0f} | "
                          f"{tracked_error(f, r.stations, c)} |")
            print(tracks[-1], flush=True)
    return ["", "## hive: the same signs against its OptiTrack", "",
            "Station 1, data8.17 less data8.11 (as `hive_pair`).", "",
            "| model | dp (mm) | dR (deg) | combined honest sigma (mm / deg) | dp / sigma "
            "| dR / sigma | dp x / y / z (mm) |", "|---|---|---|---|---|---|---|", *pairs, "",
            "Each bag tracked through its own stations, error against its OptiTrack after "
            "the world, hand-eye and time-offset alignment (mm / deg), rms and median; the "
            "solve's cost.", "",
            "| model | bag | solve's cost | rms | median |", "|---|---|---|---|---|", *tracks]


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "LH1 factory-term signs judged by a mocap")
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
                result = solve_imported(work, GraphOptions(),
                                        variant_calibration(work, name))
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
    if all((DATA / "hive-env8" / f"{bag}.bag").exists() for bag in BAGS):
        with tempfile.TemporaryDirectory(prefix="lhgraph-curve-hive-") as tmp:
            lines += hive_rows(Path(tmp))
    else:
        lines += ["", "hive: skipped, its bags are absent."]
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
