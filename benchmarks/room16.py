"""Many stations (issue #41 item 3): a simulated room of 16 LH2 stations calibrated from
captures that each see 2-4 of them, solved jointly as a lab would, with the report's
co-visibility graph.

    python -m benchmarks room16 [--seeds 2] [--segment 5] [--output FILE] [--force]

Per seed: one walk round the room of configs/simulation/lh2_room16.toml (16 stations on
channels 1-16, 50 s) cut into captures of ``--segment`` seconds that each keep at most 4
stations (:func:`lhgraph.sim.room_captures.room_captures`: each shares a station with the one
before, every station in one at least), written as files and solved by one whole
``lhgraph solve RUN.toml -o DIR`` process (``angles = [...]``, the factory calibration, the
truth; timed): every station's error against the truth in the reference station's frame,
the NEES of its honest 6x6 covariance (6 dof: mean 6 expected), its links from the
reference in the co-visibility graph, and the run directory's report, whose co-visibility
figure of the first seed is copied to docs/results/room16_visibility.png.
Targets (as for the 8-station room): every station within 2 mm / 0.05 deg, NEES in range.
~4 min per seed on the 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import command, prog
from benchmarks.joint_captures import nees
from lhgraph.estimation.metrics import station_errors
from lhgraph.estimation.visibility import co_visibility
from lhgraph.io.angles import load_angles, save_angles
from lhgraph.io.captures import join_captures
from lhgraph.io.files import check_writable
from lhgraph.io.stations import load_stations, save_stations
from lhgraph.model.board import save_board
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.report.figures import png_bytes
from lhgraph.report.visibility import visibility_figure
from lhgraph.sim.room_captures import room_captures
from lhgraph.sim.simulate import load_simulation_config, simulate

ROOT = Path(__file__).resolve().parent.parent
ROOM16 = ROOT / "configs" / "simulation" / "lh2_room16.toml"
RESULTS = ROOT / "docs" / "results"


def write_room(seed: int, segment_s: float, folder: Path) -> tuple[Path, list[Path]]:
    """The seed's captures, board, truth, calibration and run config in ``folder``; the
    config and the captures' angles files."""
    sim = simulate(load_simulation_config(ROOM16), seed)
    captures = room_captures(sim.angles, segment_s)
    names = []
    for c, part in enumerate(captures):
        names.append(f"capture{c:02d}.csv")
        save_angles(part, folder / names[-1])
    save_board(sim.board, folder / "board.toml")
    save_stations(sim.truth, folder / "truth.toml")
    save_calibration({k: StationCalibration(s.model.calibration, 0x2000 + k, generation=2,
                                            channel=s.model.channel)
                      for k, s in sim.truth.stations.items()}, folder / "ootx.toml")
    config = folder / "run.toml"
    config.write_text('board = "board.toml"\ntruth = "truth.toml"\n'
                      'calibration = "ootx.toml"\nmethod = "graph"\n'
                      f"angles = {json.dumps(names)}\n")
    return config, [folder / n for n in names]


def one_seed(seed: int, segment_s: float, work: Path, figure: Path | None) -> list[str]:
    """The table rows of one seed (and the visibility figure, when ``figure``)."""
    folder = work / f"seed{seed}"
    folder.mkdir()
    config, files = write_room(seed, segment_s, folder)
    captures = [load_angles(f) for f in files]
    kept = [c.stations() for c in captures]
    tic = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "lhgraph", "solve", str(config), "--output",
                           str(folder / "run"), "--quiet"], cwd=ROOT, capture_output=True,
                          text=True)
    seconds = time.perf_counter() - tic
    if done.returncode not in (0, 3):
        raise SystemExit(f"solve seed {seed}: {done.stderr.strip()}")
    result = load_stations(folder / "run" / "stations.toml")
    truth = load_stations(folder / "truth.toml")
    angles, _, _ = join_captures(captures, [f.name for f in files])
    vis = co_visibility(angles)
    hops = vis.hops(result.reference)
    if figure is not None:
        positions = {k: result.pose(k)[:3, 3] for k in result.indices()}
        figure.write_bytes(png_bytes(visibility_figure(vis, positions, result.reference), 110))
    report = (folder / "run" / "report.html").read_text()
    rows = []
    errors = {e.station: e for e in station_errors(truth, result)}
    for k, e in sorted(errors.items()):  # every station but the reference
        seen_in = [str(c) for c, s in enumerate(kept) if k in s]
        rows.append(f"| {seed} | {k} | {', '.join(seen_in)} | {hops.get(k, '-')} | "
                    f"{e.position_norm_m * 1e3:.3f} | {np.degrees(e.rotation_rad):.4f} | "
                    f"{nees(truth, result, k):.1f} |")
    worst = max(e.position_norm_m for e in errors.values()) * 1e3
    worst_deg = max(np.degrees(e.rotation_rad) for e in errors.values())
    summary = (f"| {seed} | {len(kept)} | {' / '.join(','.join(map(str, s)) for s in kept)} | "
               f"{max(hops.values())} | {worst:.3f} | {worst_deg:.4f} | {seconds:.0f} | "
               f"{'yes' if 'Co-visibility' in report else 'NO'} | {done.returncode} |")
    print(summary, flush=True)
    return [summary] + rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--segment", type=float, default=5.0, help="capture length (s)")
    parser.add_argument("--output", type=Path, default=RESULTS / "room16.md")
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    out = check_writable(args.output, args.force)
    figure = args.output.with_name("room16_visibility.png")
    summaries, stations = [], []
    with tempfile.TemporaryDirectory(prefix="lhgraph-room16-") as tmp:
        for seed in range(1, args.seeds + 1):
            rows = one_seed(seed, args.segment, Path(tmp), figure if seed == 1 else None)
            summaries.append(rows[0])
            stations += rows[1:]
        shutil.rmtree(tmp, ignore_errors=True)
    lines = ["# A room of 16 LH2 stations in captures of 2-4", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"{time.strftime('%Y-%m-%d')}; configs/simulation/lh2_room16.toml, captures of "
             f"{args.segment:g} s of one 50 s walk, each keeping at most 4 stations; one whole "
             "`lhgraph solve RUN.toml -o DIR` process per seed (default graph options).", "",
             "| seed | captures | stations per capture | most links from the reference "
             "| worst station mm | worst deg | solve process s | report has the "
             "co-visibility graph | exit |", "|---|---|---|---|---|---|---|---|---|",
             *summaries, "", "Per station (reference: station 0; NEES of the honest "
             "covariance, 6 dof):", "",
             "| seed | station | captures | links from the reference | error mm | error deg "
             "| NEES |", "|---|---|---|---|---|---|---|", *stations, "",
             "The first seed's co-visibility graph, as the report draws it: "
             "![co-visibility](room16_visibility.png)"]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
