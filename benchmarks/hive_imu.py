"""The hive recording with its IMU (issue #16's real-data target): the tracker path against
OptiTrack and station 1 over 8 s slices, light only and with the IMU factors, side by side.

    python -m benchmarks hive_imu [--bag PATH] [--slices 3]
        [--output docs/results/hive_imu.md]

Imports ``data8.11.bag`` (read from ../shared, never copied) into a temporary folder, then
solves with the factory calibration of ``hive_evaluation.py`` (gib -1, curve +1):

- *light only*: the default graph;
- *IMU as read*: ``--imu imu.csv`` (the importer's stream, tracker IMU frame, the bag's
  values: its gyro reads ~0.48x the true rate, docs/hive.md);
- *IMU, scale and offset solved*: the same with ``gyro_scale_sigma = 1`` and
  ``imu_time_offset_sigma_s = 0.02`` (the IMU calibration: per-axis gyro scale error and the
  IMU-to-light time offset);
- *IMU, scale, offset and frame solved*: also ``imu_rotation_sigma_rad = 0.1`` (the IMU
  frame's rotation in the tracker's);
- *IMU, scale, offset, frame and position solved*: also ``imu_position_sigma_m = 0.1`` (the
  IMU's position in the tracker's frame: the accelerometer's lever arm);
- the first and the last again with ``gyro_preintegration = true`` (the preintegrated gyro
  factor, its reading noise learned from its residuals: the column says where it ended), the
  last once more with that noise held at the default 0.02 rad/s (``adapt_gyro_sigma =
  false``), and the solve's warnings.

For each: the whole bag's path against OptiTrack after the world + hand-eye + time alignment
(:func:`lhgraph.importers.hive.align_to_mocap`, RMSE mm and deg), the solved gyro scale and
time offset, the solve's seconds; station 1 from each 8 s slice (from the motion start, 4 s
apart) against the whole bag's of the same variant (rms over the slices, mm and deg).
Prints the table and writes it to ``--output``. Skips (one line, exit 0) without the bag.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import prog
from benchmarks.hive_slice_spread import in_slice
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.metrics import station_errors
from lhgraph.importers.hive import align_to_mocap, import_hive
from lhgraph.io.angles import load_angles
from lhgraph.io.files import check_writable
from lhgraph.io.imu import load_imu
from lhgraph.io.trajectory import load_trajectory
from lhgraph.model.board import load_board
from lhgraph.model.station import Convention
from lhgraph.workflow.inputs import station_models
from lhgraph.workflow.window import motion_start

REPO = Path(__file__).resolve().parents[1]
BAG = REPO.parent / "shared/data/hive-env8/data8.11.bag"
DEFAULT_OUTPUT = REPO / "docs/results/hive_imu.md"
CALIBRATED = GraphOptions.of(gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02)
VARIANTS = {"light only": (False, GraphOptions()),
            "IMU as read": (True, GraphOptions()),
            "IMU, scale and offset solved": (True, CALIBRATED),
            "IMU, scale, offset and frame solved": (True, GraphOptions.of(
                gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                imu_rotation_sigma_rad=0.1)),
            "IMU, scale, offset, frame and position solved": (True, GraphOptions.of(
                gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                imu_rotation_sigma_rad=0.1, imu_position_sigma_m=0.1)),
            "IMU, scale and offset from the light, combined factors": (True, GraphOptions.of(
                gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02, imu_factors="combined")),
            "IMU, scale, offset and frame from the light, combined factors": (True, GraphOptions.of(
                gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                imu_rotation_sigma_rad=0.1, imu_factors="combined")),
            "IMU as read, preintegrated gyro": (True, GraphOptions.of(gyro_preintegration=True)),
            "IMU, scale, offset and frame solved, preintegrated gyro": (True, GraphOptions.of(
                gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                imu_rotation_sigma_rad=0.1, gyro_preintegration=True)),
            "the same, its gyro noise held at 0.02 rad/s": (True, GraphOptions.of(
                gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                imu_rotation_sigma_rad=0.1, gyro_preintegration=True,
                adapt_gyro_sigma=False))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.splitlines()[0])
    ap.add_argument("--bag", type=Path, default=BAG)
    ap.add_argument("--slices", type=int, default=3)
    ap.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    args = ap.parse_args(argv)
    if not args.bag.is_file():
        print(f"skipped: {args.bag} not found")
        return 0
    check_writable(args.output, overwrite=True)
    with tempfile.TemporaryDirectory() as tmp:
        import_hive(args.bag, tmp)
        board = load_board(Path(tmp) / "board.toml")
        angles = load_angles(Path(tmp) / "angles.csv")
        mocap = load_trajectory(Path(tmp) / "mocap.csv")
        imu = load_imu(Path(tmp) / "imu.csv")
        models = station_models(Path(tmp) / "ootx.toml", Convention(-1, 1))
    t0 = motion_start(angles)
    lines = ["# The hive recording with its IMU", "",
             f"Command: `python -m benchmarks hive_imu --slices {args.slices}"
             + ("" if args.output == DEFAULT_OUTPUT
                else f" --output {os.path.relpath(args.output, REPO)}") + "`  ",
             f"Machine: {platform.machine()}, Python {platform.python_version()}; "
             f"{time.strftime('%Y-%m-%d')}. Factory calibration gib -1, curve +1; slices of 8 s "
             "from the motion start, 4 s apart, each against the whole bag of the same "
             "variant.", "",
             "| variant | path RMSE mm | path RMSE deg | gyro scale x, y, z | IMU time offset "
             "ms | IMU frame rotation deg | IMU position mm | preintegrated gyro noise rad/s | "
             "whole-bag solve s | LM iterations | slices: station 1 rms mm | slices: rms deg "
             "| warnings |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, (with_imu, options) in VARIANTS.items():
        stream = imu if with_imu else None
        tic = time.perf_counter()
        whole = solve_graph(board, angles, models, options, imu=stream)
        seconds = time.perf_counter() - tic
        aligned = align_to_mocap(whole.trajectory, mocap)
        d = whole.diagnostics
        scale = (f"{d['gyro_scale_x']:.3f}, {d['gyro_scale_y']:.3f}, {d['gyro_scale_z']:.3f}"
                 if "gyro_scale_x" in d else "-")
        offset = f"{d['imu_time_offset_s'] * 1e3:+.1f}" if "imu_time_offset_s" in d else "-"
        turn = f"{d['imu_rotation_deg']:.2f}" if "imu_rotation_deg" in d else "-"
        position = (", ".join(f"{d[f'imu_position_{a}_m'] * 1e3:+.1f}" for a in "xyz")
                    if options.imu.imu_position_sigma_m > 0 else "-")
        noise = (f"{d['preintegration_sigma_rad_s']:.4f}" if "preintegration_sigma_rad_s" in d
                 else "-")
        diffs = []
        for k in range(args.slices):
            part = solve_graph(board, angles.select(in_slice(angles, t0, k)), models, options,
                               imu=stream)
            e = station_errors(whole.stations, part.stations)[0]
            diffs.append((e.position_norm_m * 1e3, np.degrees(e.rotation_rad)))
        rms = np.sqrt(np.mean(np.square(diffs), axis=0))
        lines.append(f"| {name} | {aligned.rmse_mm():.2f} | {aligned.rmse_deg():.2f} | {scale} "
                     f"| {offset} | {turn} | {position} | {noise} | {seconds:.1f} | "
                     f"{whole.iterations} | "
                     f"{rms[0]:.2f} | {rms[1]:.3f} | {len(whole.warnings)} |")
        print(lines[-1], flush=True)
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
