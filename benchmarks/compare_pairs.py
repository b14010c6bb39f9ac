"""`lhgraph compare` on the shared recordings of unmoved stations: each pair solved, compared.

Each pair records the same stations, unmoved (SPEC §5): Bitcraze's LH2 hand-held log00 and
log01, its LH1 hand-held log02 and flight log00, hive's data8.11 and data8.17. Every log is
imported (`lhgraph import`) and solved with the default graph method and its factory
calibration (`lhgraph solve`) as whole processes in a temporary folder, then the two results
are compared (`lhgraph compare`, default options). Writes docs/results/compare_pairs.md: per
pair and station the difference (mm, deg), the combined honest and white sigmas the results
report and the difference in each, and the verdict. Pairs whose data is absent are skipped. Data:
Crazyflie, hive (no licence: read from ../shared only). ~2 min.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from datetime import date
from pathlib import Path

from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.resolve import STEP_TOLERANCE_SIGMA
from lhgraph.estimation.result import SolveResult
from lhgraph.estimation.station_watch import CalibrationStart
from lhgraph.io.angles import Angles, load_angles
from lhgraph.model.board import Board, load_board
from lhgraph.model.calibration import load_calibration
from lhgraph.model.station import StationModel
from lhgraph.workflow.inputs import models_of
from lhgraph.workflow.solve import run_config
from lhgraph.workflow.solve_config import SolveConfig

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data"
DEG = 57.29577951308232
CF = "bitcraze-positioning"
PAIRS = {
    "LH2 hand-held log00 / log01": (
        ("crazyflie", f"{CF}/lh2_crossingBeam_move/log00"),
        ("crazyflie", f"{CF}/lh2_crossingBeam_move/log01")),
    "LH1 hand-held log02 / flight log00": (
        ("crazyflie", f"{CF}/lh1_crossingBeam_move/log02"),
        ("crazyflie", f"{CF}/lh1_crossingBeam_flight/log00")),
    "hive data8.11 / data8.17": (
        ("hive", "hive-env8/data8.11.bag"), ("hive", "hive-env8/data8.17.bag")),
}


def recordings() -> list[tuple[str, str]]:
    """Every recording of :data:`PAIRS`, pair by pair: ``(kind, path under DATA)``."""
    return [recording for logs in PAIRS.values() for recording in logs]


def lhgraph(*args: str) -> subprocess.CompletedProcess:
    """``python -m lhgraph ARGS`` with this checkout's package."""
    return subprocess.run([sys.executable, "-m", "lhgraph", *args], cwd=ROOT,
                          capture_output=True, text=True)


def imported(kind: str, source: Path, work: Path, *options: str) -> Path:
    """Import ``source`` (``kind`` crazyflie or hive; further import ``options``) into the
    folder ``work``; ``work``."""
    extra = ["--system-config", str(source.parent / "system-config.yaml")] \
        if kind == "crazyflie" else []
    done = lhgraph("import", kind, str(source), *extra, *options, "--output", str(work),
                   "--quiet")
    if done.returncode:
        raise SystemExit(f"import {source}: {done.stderr.strip()}")
    return work


def imported_logs(logs: tuple[str, ...], work: Path) -> Iterator[tuple[str, Path | None]]:
    """Each Bitcraze log of ``logs`` (paths under the dataset) imported into a folder of
    ``work`` as it is reached: ``(log, folder)``, the folder None when the log is absent."""
    for i, log in enumerate(logs):
        source = DATA / CF / log
        yield log, imported("crazyflie", source, work / f"log{i}") if source.exists() else None


def solved_logs(logs: tuple[str, ...], work: Path
                ) -> Iterator[tuple[str, Path | None, SolveResult | None]]:
    """:func:`imported_logs` each solved by the default graph (:func:`solve_imported`):
    ``(log, folder, result)``, both None when the log is absent."""
    for log, folder in imported_logs(logs, work):
        yield log, folder, None if folder is None else solve_imported(folder, GraphOptions())


def solve_imported(work: Path, options: GraphOptions, calibration: Path | None = None
                   ) -> SolveResult:
    """Solve an imported log folder ``work`` with its factory calibration (or the
    ``ootx.toml`` ``calibration``) through the Python API (the default graph method under
    ``options``)."""
    return run_config(SolveConfig(board=work / "board.toml", angles=work / "angles.csv",
                                  calibration=calibration or work / "ootx.toml",
                                  graph=options))


TIGHT = GraphOptions.of(covariance="white", step_tolerance_sigma=STEP_TOLERANCE_SIGMA / 100,
                        relative_tolerance=1e-9)
"""The default graph with the stopping rule tightened a hundredfold (station step tolerance
and relative error decrease) and the white covariance: for differences of solves that the
default stop's tolerance would otherwise show in."""


def imported_inputs(work: Path) -> tuple[Board, Angles, dict[int, StationModel]]:
    """An imported log folder's board, angles and station models (its ``ootx.toml``)."""
    return (load_board(work / "board.toml"), load_angles(work / "angles.csv"),
            models_of(load_calibration(work / "ootx.toml")))


def start_at(result: SolveResult) -> CalibrationStart:
    """A solve's start at ``result``'s stations and receiver path."""
    return CalibrationStart(result.stations, result.stations.reference,
                            result.trajectory.time, result.trajectory.T_world_board)


def solved(kind: str, source: Path, work: Path, *options: str) -> Path:
    """Import ``source`` into ``work`` (import ``options``) and solve it; the stations
    TOML."""
    imported(kind, source, work, *options)
    out = work / "stations.toml"
    done = lhgraph("solve", "--board", str(work / "board.toml"), "--angles",
                   str(work / "angles.csv"), "--calibration", str(work / "ootx.toml"),
                   "--output", str(out), "--quiet")
    if done.returncode not in (0, 3):
        raise SystemExit(f"solve {source}: {done.stderr.strip()}")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks compare_pairs",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path,
                        default=ROOT / "docs" / "results" / "compare_pairs.md")
    args = parser.parse_args(argv)
    lines = ["# `lhgraph compare` on recordings of unmoved stations", "",
             "Command: `python -m benchmarks compare_pairs`  ",
             f"Each log imported and solved by the default graph method; {date.today()}", "",
             "The results' `covariance` is the honest (time-block) one, `covariance_white` the "
             "white-noise one (docs/uncertainty.md); the issue's target: each difference within "
             "2 combined honest sigmas.", "",
             "| pair | station | dp (mm) | dR (deg) | honest sigma (mm / deg) "
             "| dp / sigma | dR / sigma | white sigma (mm / deg) | dp / white | dR / white "
             "| verdict (exit) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="lhgraph-pairs-") as tmp:
        for name, logs in PAIRS.items():
            if not all((DATA / path).exists() for _, path in logs):
                lines.append(f"| {name} | skipped: data absent | | | | | | |")
                continue
            results = [solved(kind, DATA / path, Path(tmp) / f"{name[:3]}{i}")
                       for i, (kind, path) in enumerate(logs)]
            report = Path(tmp) / "cmp.json"
            done = lhgraph("compare", *map(str, results), "--json", str(report), "--force",
                           "--quiet")
            if done.returncode not in (0, 3):
                raise SystemExit(f"compare: {done.stderr.strip()}")
            c = json.loads(report.read_text())
            for k, d in c["stations"].items():
                cells = [f"{d['position_m'] * 1e3:.1f}", f"{d['rotation_rad'] * DEG:.3f}"]
                for kind in ("sigma", "sigma_white"):
                    p, r = d[f"{kind}_position_m"], d[f"{kind}_rotation_rad"]
                    cells += ([f"{p * 1e3:.2f} / {r * DEG:.4f}", f"{d['position_m'] / p:.1f}",
                               f"{d['rotation_rad'] / r:.1f}"] if p and r else ["none", "", ""])
                lines.append(f"| {name} | {k} | " + " | ".join(cells)
                             + f" | {c['verdict']} ({done.returncode}) |")
            print(name, c["verdict"], flush=True)
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
