"""The documented Crazyflie workflow's cfclient export against cfclient's own geometry and
the mocap-anchored one: the stations' heights, and how much of their difference is the
world's and how much the geometry's.

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
3. the stations anchored to the log's Qualisys path (benchmarks/anchored_stations.py): their
   heights above the receiver's first mocap sample with Qualisys z as up (what the export
   should give if the accelerometer's up and Qualisys z agree), and the same stations through
   the same track and export, so that ours and cfclient's can be compared with a geometry
   that owes nothing to either solve in the same exported world;
4. the tilt of cfclient's world z from that gravity-levelled z (deg).

Writes docs/results/export_heights.md. Data: Crazyflie (no licence: read from ../shared
only). ~3 min.
"""

from __future__ import annotations

import tempfile
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import begin, write_results
from benchmarks.anchored_stations import save_anchored
from benchmarks.compare_pairs import CF, DATA, imported_logs, lhgraph
from lhgraph.io.cfclient import read_system_config
from lhgraph.io.stations import load_stations
from lhgraph.io.trajectory import load_trajectory

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


def differences(A: dict[int, np.ndarray] | str, B: dict[int, np.ndarray] | str,
                tolerance_m: float | None = None) -> str:
    """Heights ``A - B`` (mm) as a table cell, "(over)" beyond ``tolerance_m``; empty when
    either export was refused."""
    if isinstance(A, str) or isinstance(B, str):
        return ""
    d = [A[k][2, 3] - B[k][2, 3] for k in sorted(A)]
    over = tolerance_m is not None and any(abs(x) >= tolerance_m for x in d)
    return " / ".join(f"{x * 1e3:+.0f}" for x in d) + (" (over)" if over else "")


def row(log: str, work: Path) -> str:
    """One log's table row."""
    theirs = read_system_config(DATA / CF / log.split("/")[0] / "system-config.yaml")
    solved = lhgraph("solve", "--board", str(work / "board.toml"), "--angles",
                     str(work / "angles.csv"), "--calibration", str(work / "ootx.toml"),
                     "--output", str(work / "stations.toml"), "--quiet")
    if solved.returncode not in (0, 3):
        raise SystemExit(f"solve {log}: {solved.stderr.strip()}")
    ours = exported(work, work / "stations.toml", "ours")
    ref, anchored_toml = save_anchored(work, load_stations(work / "stations.toml"),
                                       load_trajectory(work / "track-ours.csv"))
    truth = {k: T.copy() for k, T in ref.T_mocap_lh.items()}
    for T in truth.values():
        T[2, 3] -= ref.first_sample_m[2]
    levelled = exported(work, work / "stations-cfclient.toml", "cfclient")
    pinned = exported(work, anchored_toml, "anchored")
    cells = [log, heights(theirs.T_world_lh), heights(truth)]
    for T in (ours, levelled, pinned):
        cells.append(heights(T) if isinstance(T, dict) else f"refused: {T}")
    cells += [differences(ours, theirs.T_world_lh, TOLERANCE_M),
              differences(pinned, theirs.T_world_lh, TOLERANCE_M), differences(ours, truth),
              differences(ours, pinned, TOLERANCE_M), differences(levelled, pinned, TOLERANCE_M)]
    if isinstance(levelled, dict):
        k = min(levelled)
        R_new_cf = levelled[k][:3, :3] @ theirs.T_world_lh[k][:3, :3].T
        cells.append(f"{np.degrees(np.arccos(np.clip(R_new_cf[2, 2], -1, 1))):.2f}")
    else:
        cells.append("")
    line = "| " + " | ".join(cells) + " |"
    print(line, flush=True)
    return line


def main(argv: list[str] | None = None) -> int:
    _, out, start, lines = begin(__file__, __doc__, argv,
                                 "The cfclient export's station heights against cfclient's")
    lines += [f"{date.today()}; the README's workflow per log (import, solve, track, export "
             "cfclient --imu --trajectory); heights in m, station 0 / 1; differences in mm "
             f"(target: within {TOLERANCE_M * 1e3:.0f} mm of cfclient's file).", "",
             "| log | cfclient's file | anchored, Qualisys z | ours exported "
             "| cfclient's stations, same export | anchored stations, same export "
             "| ours - cfclient's file (mm) | anchored, same export - cfclient's file (mm) "
             "| ours - anchored, Qualisys z (mm) "
             "| ours - anchored, same export (mm) | cfclient's - anchored, same export (mm) "
             "| cfclient's z from gravity (deg) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="lhgraph-heights-") as tmp:
        for log, work in imported_logs(LOGS, Path(tmp)):
            lines.append(row(log, work) if work else f"| {log} | skipped: data absent "
                         + "| " * 11 + "|")
    return write_results(out, lines, start)


if __name__ == "__main__":
    raise SystemExit(main())
