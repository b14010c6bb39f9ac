"""Conversion of a hive bag into lhgraph contract files: :func:`import_hive` (the
``lhgraph import hive`` command).

Time base of every written file: seconds since the bag's ``t0``
(:mod:`lhgraph.importers.hive.bag`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.importers.hive.bag import MAX_ABS_ANGLE_RAD, read_hive_bag
from lhgraph.importers.hive.conventions import hive_angles, station_calibrations
from lhgraph.importers.hive.sync_offsets import SyncBitCorrection, correct_sync_bits
from lhgraph.io.angles import save_angles
from lhgraph.io.files import check_writable, write_csv_columns
from lhgraph.io.imu import ImuStream, save_imu
from lhgraph.model.board import save_board
from lhgraph.model.calibration import save_calibration

Array = NDArray[np.float64]

OUTPUT_FILES = ("angles.csv", "board.toml", "ootx.toml", "imu.csv", "mocap.csv")


@dataclass(frozen=True)
class HiveImport:
    """What :func:`import_hive` wrote and a summary of the recording."""

    paths: dict[str, Path]
    serials: list[str]
    n_hits: int
    n_dropped: int
    n_sensors: int
    duration_s: float
    sweep_rate_hz: dict[tuple[int, int], float] = field(default_factory=dict)
    imu_rate_hz: float = 0.0
    mocap_rate_hz: float = 0.0
    off_grid_sweeps: dict[int, int] = field(default_factory=dict)
    n_off_grid_hits: int = 0
    sync_bits: SyncBitCorrection | None = None
    notes: tuple[str, ...] = ()
    """What a damaged bag lost (:attr:`lhgraph.importers.hive.bag.HiveBag.notes`)."""

    def summary(self) -> str:
        """Human-readable lines."""
        lines = [f"bag: {n}" for n in self.notes] + [
            f"stations: {len(self.serials)} ("
            + ", ".join(f"{i}={s}" for i, s in enumerate(self.serials)) + ")",
            f"sensors: {self.n_sensors}; hits kept {self.n_hits}, dropped {self.n_dropped} "
            f"(angle beyond {np.degrees(MAX_ABS_ANGLE_RAD):.0f} deg)",
            f"dropped {sum(self.off_grid_sweeps.values())} sweeps ({self.n_off_grid_hits} hits) "
            "off their station's timing grid: " + ", ".join(
                f"station {k}: {n}" for k, n in sorted(self.off_grid_sweeps.items())),
            f"duration: {self.duration_s:.2f} s",
            "sweep rate (Hz): " + ", ".join(
                f"lh{lh}/ax{ax} {r:.1f}" for (lh, ax), r in sorted(self.sweep_rate_hz.items())),
            f"imu: {self.imu_rate_hz:.1f} Hz; mocap: {self.mocap_rate_hz:.1f} Hz",
        ]
        lines += ([self.sync_bits.summary()] if self.sync_bits is not None
                  else ["sync-bit offsets: not looked for (the angles as recorded)"])
        lines += [f"wrote {p}" for p in self.paths.values()]
        return "\n".join(lines)


def _rate_hz(t: Array) -> float:
    t = np.unique(t)
    return float((len(t) - 1) / (t[-1] - t[0])) if len(t) > 1 else 0.0


def import_hive(bag_path: str | Path, out_dir: str | Path, overwrite: bool = False,
                sync_bits: bool = True) -> HiveImport:
    """Convert a hive bag into ``angles.csv``, ``board.toml``, ``ootx.toml``, ``imu.csv`` and
    ``mocap.csv`` in ``out_dir`` (refuses to replace existing files unless ``overwrite``);
    ``sync_bits``: find and raise the sweeps that read one sync-bit length low
    (:mod:`lhgraph.importers.hive.sync_offsets`)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a directory", out)
    paths = {name.split(".")[0]: out / name for name in OUTPUT_FILES}
    bag = read_hive_bag(bag_path)
    for p in paths.values():
        check_writable(p, overwrite)
    angles = hive_angles(bag)
    correction = None
    if sync_bits:
        angles, correction = correct_sync_bits(angles)
    save_angles(angles, paths["angles"], overwrite)
    save_board(bag.board, paths["board"], overwrite)
    save_calibration(station_calibrations(bag), paths["ootx"], overwrite)
    save_imu(ImuStream(bag.imu_time, bag.imu_accel, bag.imu_gyro), paths["imu"], overwrite,
             time_format="{:.9f}")
    q = bag.mocap_quat_wxyz
    write_csv_columns(
        paths["mocap"],
        {"time": bag.mocap_time, "x": bag.mocap_position[:, 0], "y": bag.mocap_position[:, 1],
         "z": bag.mocap_position[:, 2], "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2],
         "qz": q[:, 3]},
        {"time": "{:.9f}"}, overwrite)
    rates = {}
    for lh in range(len(bag.serials)):
        for ax in (0, 1):
            sel = (angles.lighthouse == lh) & (angles.axis == ax)
            rates[(lh, ax)] = _rate_hz(angles.time[sel])
    t_all = np.concatenate([angles.time, bag.imu_time, bag.mocap_time])
    return HiveImport(
        paths=paths, serials=bag.serials, n_hits=len(angles), n_dropped=bag.n_dropped,
        n_sensors=len(bag.board.ids), off_grid_sweeps=bag.off_grid_sweeps,
        n_off_grid_hits=bag.n_off_grid_hits, duration_s=float(t_all.max() - t_all.min()),
        sweep_rate_hz=rates, imu_rate_hz=_rate_hz(bag.imu_time),
        mocap_rate_hz=_rate_hz(bag.mocap_time), sync_bits=correction, notes=bag.notes,
    )
