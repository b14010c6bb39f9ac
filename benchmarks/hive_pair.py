"""hive's two bags of one layout (data8.11, data8.17): do the two solves agree, and does each
bag's calibration track the other bag's receiver as well as that bag's own?

    python -m benchmarks hive_pair [--output FILE] [--force]

Issue #39's item 4: the importer's sync-bit correction (docs/hive.md) must make the two
recordings of unmoved stations agree, not disagree. For each import, the default (the
sync-bit correction applied) and `--keep-sync-offsets` (the angles as recorded):

1. both bags imported (`lhgraph import hive`, whole processes) and solved (default graph
   method, the bag's factory calibration; Python API as `lhgraph solve`);
2. station 1's difference between the two solves (`lhgraph.estimation.layout_compare`): mm,
   deg and in combined honest sigmas (target <= 2 sigma and <= 2 mm / 0.05 deg);
3. each bag's angles tracked (`lhgraph track`, batch) through its own stations and through
   the other bag's, each path aligned to the bag's OptiTrack
   (:func:`lhgraph.importers.hive.align_to_mocap`: world, hand-eye, time offset): the path
   error through the other bag's stations against through its own.

Writes docs/results/hive_pair.md. Data: hive (no licence: read from ../shared only). ~3 min.
"""

from __future__ import annotations

import benchmarks._single_thread  # noqa: F401  (first: before numpy loads)

# isort: split

import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np

from benchmarks import command, results_parser, write_results
from benchmarks.compare_pairs import DATA, DEG, imported, solve_imported
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.track import track
from lhgraph.estimation.layout_compare import compare_layouts
from lhgraph.importers.hive import align_to_mocap
from lhgraph.io.angles import load_angles
from lhgraph.io.files import check_writable
from lhgraph.io.stations import Stations
from lhgraph.io.trajectory import load_trajectory
from lhgraph.model.board import load_board
from lhgraph.model.calibration import load_calibration
from lhgraph.workflow.inputs import models_of

BAGS = ("data8.11", "data8.17")
IMPORTS = {"sync-bit correction (default)": (), "as recorded (--keep-sync-offsets)":
           ("--keep-sync-offsets",)}
VARIANTS = {"tracker's sensor positions solved (sensor_offset_sigma_m = 1 mm)":
            {"sensor_offset_sigma_m": 1e-3},
            "per-diode biases solved (diode_bias_sigma_rad = 0.2 mrad)":
            {"diode_bias_sigma_rad": 2e-4},
            "rests thinned (rest_keep_every = 10)": {"rest_keep_every": 10}}
"""Other graph options tried on the corrected import (pair rows only)."""


def tracked_error(folder: Path, stations: Stations, calibration: Path | None = None) -> str:
    """The imported bag ``folder``'s angles tracked through ``stations`` (the factory models
    of ``calibration``, default the bag's ``ootx.toml``), aligned to its OptiTrack: the
    position (mm) and rotation (deg) error, rms and median, as a table cell (the median
    because the OptiTrack path of data8.17 jumps by 15-30 deg in 10 ms a few times, which
    dominates its rms)."""
    models = models_of(load_calibration(calibration or folder / "ootx.toml"))
    path = track(load_board(folder / "board.toml"), load_angles(folder / "angles.csv"),
                 stations, models).path.trajectory
    aligned = align_to_mocap(path, load_trajectory(folder / "mocap.csv"))
    return (f"{aligned.rmse_mm():.2f} / {aligned.rmse_deg():.3f} | "
            f"{np.median(aligned.position_error_m) * 1e3:.2f} / "
            f"{np.degrees(np.median(aligned.rotation_error_rad)):.3f}")


def pair_row(name: str, stations: list[Stations]) -> str:
    """Station 1's difference between the two bags' ``stations``, a table row."""
    d = next(d for d in compare_layouts(stations[0], stations[1]).differences
             if d.station == 1)
    row = (f"| {name} | {d.position_m * 1e3:.1f} | {d.rotation_rad * DEG:.3f} | "
           f"{d.sigma_position_m * 1e3:.2f} / {d.sigma_rotation_rad * DEG:.4f} | "
           f"{d.position_sigmas:.1f} | {d.rotation_sigmas:.1f} | "
           + " / ".join(f"{x * 1e3:+.1f}" for x in d.dp_m) + " |")
    print(row, flush=True)
    return row


def rows(work: Path, name: str, options: tuple[str, ...]
         ) -> tuple[list[Path], str, list[str]]:
    """One import's folders, pair row and its two tracking rows."""
    folders = [imported("hive", DATA / "hive-env8" / f"{bag}.bag", work / bag, *options)
               for bag in BAGS]
    stations = [solve_imported(f, GraphOptions()).stations for f in folders]
    pair = pair_row(name, stations)
    tracks = []
    for i, bag in enumerate(BAGS):
        own = tracked_error(folders[i], stations[i])
        other = tracked_error(folders[i], stations[1 - i])
        tracks.append(f"| {name} | {bag} | {own} | {other} |")
        print(tracks[-1], flush=True)
    return folders, pair, tracks


def main(argv: list[str] | None = None) -> int:
    args = results_parser(__file__, __doc__).parse_args(argv)
    out = check_writable(args.output, args.force)
    if not all((DATA / "hive-env8" / f"{bag}.bag").exists() for bag in BAGS):
        raise SystemExit("hive bags absent from ../shared/data/hive-env8")
    start = time.perf_counter()
    pairs, tracks = [], []
    with tempfile.TemporaryDirectory(prefix="lhgraph-hive-pair-") as tmp:
        for i, (name, options) in enumerate(IMPORTS.items()):
            folders, pair, track_rows = rows(Path(tmp) / str(i), name, options)
            pairs.append(pair)
            tracks += track_rows
            if i == 0:
                corrected = folders
        for name, values in VARIANTS.items():
            options = GraphOptions().with_values(**values)
            pairs.append(pair_row(f"correction, {name}",
                                  [solve_imported(f, options).stations for f in corrected]))
    lines = ["# hive data8.11 and data8.17: one layout, two recordings", "",
             f"Command: `{command(__file__, argv)}`  ",
             f"{date.today()}; default graph options; station 1 in station 0's frame.", "",
             "## Station 1, data8.17 less data8.11", "",
             "| import | dp (mm) | dR (deg) | combined honest sigma (mm / deg) | dp / sigma "
             "| dR / sigma | dp x / y / z (mm) |", "|---|---|---|---|---|---|---|", *pairs, "",
             "## Each bag tracked through its own and the other bag's stations", "",
             "error against the bag's OptiTrack after the world, hand-eye and time-offset "
             "alignment (mm / deg), rms and median.", "",
             "| import | bag | own stations, rms | median | other bag's stations, rms "
             "| median |", "|---|---|---|---|---|---|", *tracks]
    return write_results(out, lines, start)


if __name__ == "__main__":
    raise SystemExit(main())
