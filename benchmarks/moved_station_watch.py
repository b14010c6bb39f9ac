"""The moved-station watch (`lhgraph track --watch`): a station bumped mid-capture is found,
and unmoved ones are not.

    python -m benchmarks moved_station_watch [--seeds N] [--no-real] [--output FILE] [--force]

1. Simulation (`lhgraph.sim.moved_station`): the 32-diode board and the Crazyflie deck (30 %
   of hits dropped) on the default layout, 20 s, station 1 moved at 10 s by 10 mm along its
   x, y or z axis or turned 0.2 deg about one, and unmoved, N seeds each; tracked with the
   stations before the move (batch), then watched (default options). Per case: how many
   captures flagged, the detection delay after the move (median, max; target <= 5 s), the
   move time's error, and false alarms on the unmoved captures (target 0).
2. Real recordings (SPEC §5; skipped when absent): every shared Crazyflie log and hive bag
   imported (`lhgraph import`, whole processes) and solved, the libsurvive recording
   decoded and solved; each tracked and watched against its own calibration, and the logs
   of unmoved stations against their partner's (compare_pairs' pairs). Target: no alarm.

Writes docs/results/moved_station_watch.md. ~6 min with the real data on the 2-core machine.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import command, prog
from benchmarks.compare_pairs import DATA, PAIRS, imported, solve_imported
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.track import track
from lhgraph.estimation.station_watch import WatchOptions, WatchResult, watch
from lhgraph.geometry.transforms import make_pose, so3_exp
from lhgraph.io.angles import load_angles
from lhgraph.io.files import check_writable
from lhgraph.io.stations import Stations
from lhgraph.model.board import Board, load_board
from lhgraph.model.calibration import load_calibration
from lhgraph.model.station import StationModel
from lhgraph.signal.formats import decode_file
from lhgraph.signal.libsurvive import read_libsurvive_board
from lhgraph.sim.moved_station import moved_station_capture
from lhgraph.sim.simulate import default_simulation_config
from lhgraph.workflow.inputs import models_of

ROOT = Path(__file__).resolve().parent.parent
SHIFT_M, TURN_DEG, T_MOVE_S, DURATION_S = 0.01, 0.2, 10.0, 20.0
LIBSURVIVE = DATA / "libsurvive-lh1" / "lh1_test_cal.rec.gz"


def moves() -> dict[str, np.ndarray]:
    """The simulated moves of station 1, in its own frame."""
    out = {"unmoved": np.eye(4)}
    for i, axis in enumerate("xyz"):
        out[f"10 mm along {axis}"] = make_pose(np.eye(3), SHIFT_M * np.eye(3)[i])
    for i, axis in enumerate("xyz"):
        out[f"0.2 deg about {axis}"] = make_pose(so3_exp(np.radians(TURN_DEG) * np.eye(3)[i]),
                                                 np.zeros(3))
    return out


def watched(board: Board, angles, stations: Stations,
            models: dict[int, StationModel]) -> tuple[WatchResult, float]:
    """Track ``angles`` against ``stations`` (batch), then watch; the result and its time
    (s, track and watch)."""
    tic = time.perf_counter()
    path = track(board, angles, stations, models).path
    result = watch(board, angles, stations, path.trajectory.time,
                   path.trajectory.T_world_board, models)
    return result, time.perf_counter() - tic


def simulated(seeds: int) -> list[str]:
    """Part 1's table rows."""
    rows = []
    base = dataclasses.replace(default_simulation_config(), duration_s=DURATION_S)
    deck = dataclasses.replace(base, board="crazyflie_deck",
                               noise=dataclasses.replace(base.noise, dropout_fraction=0.3))
    for name, config in (("32-diode board", base), ("Crazyflie deck", deck)):
        for case, T_delta in moves().items():
            flagged, delays, t_errors, others, seconds = 0, [], [], 0, []
            for seed in range(1, seeds + 1):
                capture, _ = moved_station_capture(config, 1, T_delta, T_MOVE_S, seed)
                models = {k: s.model for k, s in capture.truth.stations.items()}
                result, s = watched(capture.board, capture.angles, capture.truth, models)
                seconds.append(s)
                mine = [m for m in result.moves if m.station == 1 and not m.reference]
                others += len(result.moves) - len(mine)
                if mine:
                    flagged += 1
                    delays.append(mine[0].detected_s - T_MOVE_S)
                    t_errors.append(abs(mine[0].t_s - T_MOVE_S))
            delay = (f"{np.median(delays):.1f} / {max(delays):.1f}" if delays else "")
            terr = f"{np.median(t_errors):.1f}" if t_errors else ""
            rows.append(f"| {name} | {case} | {flagged} / {seeds} | {delay} | {terr} | "
                        f"{others} | {np.median(seconds):.1f} |")
            print(rows[-1], flush=True)
    return rows


def real_logs(work: Path) -> dict[str, tuple[Board, object, dict[int, StationModel],
                                             Stations]]:
    """Every shared recording present: board, angles, models and its own calibration."""
    out = {}
    for logs in PAIRS.values():
        for kind, path in logs:
            source = DATA / path
            if not source.exists():
                continue
            folder = imported(kind, source, work / path.replace("/", "_"))
            result = solve_imported(folder, GraphOptions())
            models = models_of(load_calibration(folder / "ootx.toml"))
            out[path] = (load_board(folder / "board.toml"), load_angles(folder / "angles.csv"),
                         models, result.stations)
            print(f"solved {path}", flush=True)
    if LIBSURVIVE.exists():
        decoded, _ = decode_file(LIBSURVIVE, "libsurvive", device="HMD")
        board = read_libsurvive_board(LIBSURVIVE, "HMD")
        models = models_of(decoded.calibrations)
        out["libsurvive-lh1"] = (board, decoded.angles, models,
                                 solve_graph(board, decoded.angles, models).stations)
    return out


def real(work: Path) -> list[str]:
    """Part 2's table rows."""
    logs = real_logs(work)
    runs = [(name, name) for name in logs]
    for a, b in PAIRS.values():
        if a[1] in logs and b[1] in logs:
            runs += [(a[1], b[1]), (b[1], a[1])]
    rows = []
    for name, calibration in runs:
        board, angles, models, _ = logs[name]
        result, seconds = watched(board, angles, logs[calibration][3], models)
        peak = max((t.z for t in result.tests), default=float("nan"))
        alarms = "; ".join(m.message() for m in result.moves) or "none"
        whose = "own" if calibration == name else calibration
        rows.append(f"| {name} | {whose} | {len(result.windows)} / "
                    f"{len(result.windows) + len(result.skipped)} | {len(result.tests)} | "
                    f"{peak:.1f} | {alarms} | {seconds:.0f} |")
        print(rows[-1], flush=True)
    return rows



def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--no-real", action="store_true", help="simulation only")
    parser.add_argument("--output", type=Path,
                        default=ROOT / "docs" / "results" / "moved_station_watch.md")
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    o = WatchOptions()
    lines = ["# Moved-station watch", "", f"Command: `{command(__file__, argv)}`  ",
             f"{time.strftime('%Y-%m-%d')}; watch options: windows of {o.window_s:g} s every "
             f"{o.step_s:g} s, history of at least {o.min_history} windows, out over "
             f"{o.k_sigma:g} sigma and {o.floor_mm:g} mm or {o.floor_deg:g} deg, "
             f"{o.sustain} out windows in a row.", "",
             f"## Simulation: station 1 moved at {T_MOVE_S:g} s of {DURATION_S:g}", "",
             "| receiver | move | flagged | delay after the move, median / max (s) "
             "| move time error, median (s) | other alarms | track + watch (s) |",
             "|---|---|---|---|---|---|---|"]
    lines += simulated(args.seeds)
    if not args.no_real:
        lines += ["", "## Real recordings of unmoved stations", "",
                  "Each watched against its own calibration (`own`) and, for the logs of one "
                  "layout, against the other log's.", "",
                  "| recording | calibration | windows solved | station tests "
                  "| largest z (sigma) | alarms | track + watch (s) |",
                  "|---|---|---|---|---|---|---|"]
        with tempfile.TemporaryDirectory(prefix="lhgraph-watch-") as tmp:
            lines += real(Path(tmp))
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
