"""The documented Crazyflie workflow's cfclient export against cfclient's own geometry: the
stations' heights, and how much of their difference is cfclient's world and how much the
geometry.

    python -m benchmarks export_heights [--output FILE] [--force]

Issue #40 asks the README's workflow (`import crazyflie` -> `solve` -> `track` ->
`export cfclient --imu --trajectory`) to give, on every shared log, a z-up export within
50 mm of the heights in cfclient's `system-config.yaml`, or a refusal with the reason.
Per shared Bitcraze log, as whole processes:

1. the workflow as documented: our stations exported (z up from the accelerometer at the
   receiver's first rest, origin and x there: docs/export.md);
2. cfclient's own stations (the log's `system-config.yaml`, as imported) through the same
   track and export: cfclient's geometry in the same gravity-levelled world with the same
   origin, so that a difference left between (1) and (2) is the geometry's, not the world's;
3. the tilt of cfclient's world z from that gravity-levelled z (deg).

Writes docs/results/export_heights.md. Data: Crazyflie (no licence: read from ../shared
only). ~3 min.
"""

from __future__ import annotations

import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import command, results_parser, write_results
from benchmarks.compare_pairs import CF, DATA, imported_logs, lhgraph
from lhgraph.io.cfclient import read_system_config
from lhgraph.io.files import check_writable

LOGS = ("lh1_crossingBeam_move/log02", "lh1_crossingBeam_flight/log00",
        "lh2_crossingBeam_move/log00", "lh2_crossingBeam_move/log01")
TOLERANCE_M = 0.05


def exported(work: Path, stations: Path, name: str) -> dict[int, np.ndarray] | str:
    """``stations`` tracked on the imported log ``work`` and exported for cfclient with the
    log's IMU (the README's commands): the exported ``T_world_lh`` by station, or the
    export's refusal (its message's first clause)."""
    files = ["--board", str(work / "board.toml"), "--angles", str(work / "angles.csv"),
             "--calibration", str(work / "ootx.toml")]
    track = work / f"track-{name}.csv"
    done = lhgraph("track", *files, "--stations", str(stations), "--output", str(track),
                   "--quiet")
    if done.returncode not in (0, 3):
        raise SystemExit(f"track {work}: {done.stderr.strip()}")
    out = work / f"system-config-{name}.yaml"
    done = lhgraph("export", "cfclient", str(stations), "--calibration",
                   str(work / "ootx.toml"), "--imu", str(work / "imu.csv"), "--trajectory",
                   str(track), "--output", str(out))
    if done.returncode:
        return done.stderr.strip().split(": error: ")[-1].split(":")[0].split(" (")[0]
    return read_system_config(out).T_world_lh


def heights(T: dict[int, np.ndarray]) -> str:
    """The stations' heights (m) as a table cell."""
    return " / ".join(f"{T[k][2, 3]:.3f}" for k in sorted(T))


def row(log: str, work: Path) -> str:
    """One log's table row."""
    theirs = read_system_config(DATA / CF / log.split("/")[0] / "system-config.yaml")
    solved = lhgraph("solve", "--board", str(work / "board.toml"), "--angles",
                     str(work / "angles.csv"), "--calibration", str(work / "ootx.toml"),
                     "--output", str(work / "stations.toml"), "--quiet")
    if solved.returncode not in (0, 3):
        raise SystemExit(f"solve {log}: {solved.stderr.strip()}")
    ours = exported(work, work / "stations.toml", "ours")
    levelled = exported(work, work / "stations-cfclient.toml", "cfclient")
    cells = [log, heights(theirs.T_world_lh)]
    for T in (ours, levelled):
        cells.append(heights(T) if isinstance(T, dict) else f"refused: {T}")
    if isinstance(ours, dict):
        d = [ours[k][2, 3] - theirs.T_world_lh[k][2, 3] for k in sorted(ours)]
        within = all(abs(x) < TOLERANCE_M for x in d)
        cells.append(" / ".join(f"{x * 1e3:+.0f}" for x in d) + ("" if within else " (over)"))
    else:
        cells.append("")
    if isinstance(ours, dict) and isinstance(levelled, dict):
        cells.append(" / ".join(f"{(ours[k][2, 3] - levelled[k][2, 3]) * 1e3:+.0f}"
                                for k in sorted(ours)))
        k = min(levelled)
        R_new_cf = levelled[k][:3, :3] @ theirs.T_world_lh[k][:3, :3].T
        cells.append(f"{np.degrees(np.arccos(np.clip(R_new_cf[2, 2], -1, 1))):.2f}")
    else:
        cells += ["", ""]
    line = "| " + " | ".join(cells) + " |"
    print(line, flush=True)
    return line


def main(argv: list[str] | None = None) -> int:
    args = results_parser(__file__, __doc__).parse_args(argv)
    out = check_writable(args.output, args.force)
    start = time.perf_counter()
    lines = ["# The cfclient export's station heights against cfclient's", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"{date.today()}; the README's workflow per log (import, solve, track, export "
             "cfclient --imu --trajectory); heights in m, station 0 / 1; differences in mm "
             f"(target: within {TOLERANCE_M * 1e3:.0f} mm of cfclient's file).", "",
             "| log | cfclient's file | ours exported | cfclient's stations, same export "
             "| ours - cfclient's file (mm) | ours - cfclient's, same export (mm) "
             "| cfclient's z from gravity (deg) |", "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="lhgraph-heights-") as tmp:
        for log, work in imported_logs(LOGS, Path(tmp)):
            lines.append(row(log, work) if work else f"| {log} | skipped: data absent "
                         "| | | | | |")
    return write_results(out, lines, start)


if __name__ == "__main__":
    raise SystemExit(main())
