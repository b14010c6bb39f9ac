"""``lhgraph track`` with and without the IMU through each shared recording's own calibration:
the residuals' spread and the verdict (issue #40 item 5: no wrong verdict on the documented
workflow).

    python -m benchmarks track_verdicts [--output FILE] [--force]

Per recording of compare_pairs' pairs: ``lhgraph import``, ``lhgraph solve`` (light only, the
default graph), then ``lhgraph track`` of the same angles through that result, once from the
light alone and once with the recording's ``imu.csv``; each track's robust residual spread
(µrad, and mm at the median range), its ratio to the calibration's own spread, its inliers,
its verdict and exit code. On a few-diode deck the light-only path bends to the light's
noise (a pose per sweep from four diodes), the IMU's cannot: its spread is the light's whole
misfit, which sets :data:`lhgraph.report.assessment.MAX_IMU_TRACK_SPREAD_MM`. Data:
Crazyflie, hive (no licence: read from ../shared only). ~4 min on the 2-core machine.
"""

from __future__ import annotations

import re
import tempfile
from datetime import date
from pathlib import Path

from benchmarks import begin, write_results
from benchmarks.compare_pairs import DATA, lhgraph, recordings, solved
from lhgraph.io.stations import load_stations

SPREAD = re.compile(r"robust spread ([\d.]+) µrad = ([\d.]+) mm .* inlier fraction ([\d.]+)")


def track_row(path: str, folder: Path, stations: Path, imu: bool) -> str:
    """One table row: ``folder``'s angles tracked through ``stations`` (with its IMU)."""
    extra = ["--imu", str(folder / "imu.csv")] if imu else []
    done = lhgraph("track", "--stations", str(stations), "--board", str(folder / "board.toml"),
                   "--angles", str(folder / "angles.csv"), "--calibration",
                   str(folder / "ootx.toml"), "--output", str(folder / "track.csv"), "--force",
                   *extra)
    text = done.stdout + done.stderr
    found = SPREAD.search(text)
    track = "IMU" if imu else "light"
    if found is None:  # the track stopped without a result: its error line
        error = next((ln for ln in text.splitlines() if ln.startswith("lhgraph track: ")),
                     text.strip()[-200:])
        return (f"| {path} | {track} | - | - | - | - | {error.split(';')[0]} | "
                f"{done.returncode} |")
    verdict = next(ln.removeprefix("verdict: ") for ln in text.splitlines()
                   if ln.startswith("verdict: "))
    calibrated = (load_stations(stations).extra.get("verdict") or {}).get(
        "residual_spread_urad")
    spread = float(found[1])
    ratio = f"{spread / calibrated:.1f}" if calibrated else "-"
    return (f"| {path} | {track} | {spread:.0f} | {found[2]} | {ratio} | "
            f"{float(found[3]):.3f} | {verdict.split(':')[0]} | {done.returncode} |")


def main(argv: list[str] | None = None) -> int:
    _, out, started, lines = begin(__file__, __doc__, argv,
                                   "Track verdicts through each recording's own calibration")
    rows = []
    with tempfile.TemporaryDirectory(prefix="lhgraph-tracks-") as tmp:
        for n, (kind, path) in enumerate(recordings()):
            if not (DATA / path).exists():
                rows.append(f"| {path} | skipped: data absent | | | | | | |")
                continue
            work = Path(tmp) / str(n)
            stations = solved(kind, DATA / path, work)
            for imu in (False, True):
                rows.append(track_row(path, work, stations, imu))
                print(rows[-1], flush=True)
    lines += [f"{date.today()}; each recording solved (light only) and tracked through that "
              "result, from the light alone and with its IMU. Spread: the robust spread of "
              "the angle residuals (µrad; mm at the median range); ratio: to the "
              "calibration's own spread (the stations TOML's verdict); limits "
              "(lhgraph.report.assessment): 1 mm and 3x the calibration's without an IMU, "
              "3 mm with one.", "",
              "| recording | track | spread (µrad) | spread (mm) | ratio to the calibration's "
              "| inliers | verdict | exit |", "|---|---|---|---|---|---|---|---|", *rows]
    return write_results(out, lines, started)


if __name__ == "__main__":
    raise SystemExit(main())
