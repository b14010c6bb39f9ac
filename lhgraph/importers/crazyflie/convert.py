"""Conversion of a Crazyflie uSD log into lhgraph contract files: :func:`import_crazyflie`
(the ``lhgraph import crazyflie`` command, docs/crazyflie.md).

Time base of every written file: the deck's pulse clock (s since the Crazyflie started, the
log's stamps scaled by :func:`~lhgraph.importers.crazyflie.clock.deck_clock`; the log's own
clock when the log has no raw pulse frames to measure it by).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from lhgraph.errors import InputError
from lhgraph.importers.crazyflie.clock import DeckClock, deck_clock
from lhgraph.importers.crazyflie.mocap import (
    Mocap,
    align_mocap,
    marker_events_s,
    read_mocap_npy,
)
from lhgraph.importers.crazyflie.sweeps import (
    LH2_MAX_INTERVAL_S,
    SweepSummary,
    lh1_angles,
    lh2_angles,
    sweep_interval_s,
)
from lhgraph.importers.crazyflie.usdlog import UsdLog, read_usd_log
from lhgraph.io.angles import save_angles
from lhgraph.io.cfclient import SYSTEM_TYPES, SystemConfig, read_system_config
from lhgraph.io.files import check_writable, write_csv_columns
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2, ImuStream, save_imu
from lhgraph.io.stations import Station, Stations, save_stations
from lhgraph.model.board import save_board
from lhgraph.model.boards import crazyflie_deck
from lhgraph.model.calibration import save_calibration
from lhgraph.model.station import StationModel

IMU_VARIABLES = ("acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z")
MIN_IMU_SAMPLES = 3
"""Fewer valid IMU samples than this (what an IMU stream needs) and no ``imu.csv`` is written."""
ANGLE_VARIABLES = ("basestation", "sweep", "sensor", "angle", "correctedAngle")


@dataclass(frozen=True)
class CrazyflieImport:
    """What :func:`import_crazyflie` wrote and a summary of the log."""

    paths: dict[str, Path]
    version: int
    notes: tuple[str, ...]
    sweeps: SweepSummary
    duration_s: float
    imu_rate_hz: float
    system_type: int = 1
    mocap: Mocap | None = None
    skipped: tuple[str, ...] = field(default=())
    imu_dropped: int = 0
    clock: DeckClock | None = None

    def summary(self) -> str:
        """Human-readable lines."""
        lines = [f"uSD log version {self.version}; {SYSTEM_TYPES[self.system_type]}; "
                 f"duration {self.duration_s:.1f} s"]
        lines += [f"log: {n}" for n in self.notes]
        lines.append(self.clock.line() if self.clock is not None else
                     "clock: the log's own (no raw pulse frames to check it against)")
        lines += self.sweeps.lines()
        lines.append(f"imu: {self.imu_rate_hz:.1f} Hz; dropped {self.imu_dropped} samples "
                     "(a value not finite, or a stamp not after the one before)")
        if self.mocap is not None:
            lines.append(f"mocap: {len(self.mocap.time)} samples on the written clock (clock rate "
                         f"{self.mocap.rate:.6f}), {self.mocap.n_unseen} unseen left out")
        if "ootx" in self.paths and self.system_type == 1:
            lines.append("calibration: the system configuration's OOTX terms, the curve with "
                         "its broadcast sign (the deck firmware negates it, so our corrected "
                         "angles differ from its correctedAngle by twice the curve term; "
                         "docs/crazyflie.md#the-lh1-curves-sign)")
        lines += [f"not written: {s}" for s in self.skipped]
        lines += [f"wrote {p}" for p in self.paths.values()]
        return "\n".join(lines)


def imu_stream(log: UsdLog, source: str | Path) -> tuple[ImuStream, int]:
    """The log's ``fixedFrequency`` events as an IMU stream in SI units (the log's
    accelerometer is in g, its gyro in deg/s) and how many samples were dropped: a value not
    finite, or a stamp not after the last one kept."""
    if not log.count("fixedFrequency"):
        return ImuStream(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))), 0
    log.require("fixedFrequency", IMU_VARIABLES, source)
    ff, t = log.events["fixedFrequency"], log.time_s("fixedFrequency")
    accel = np.stack([ff[f"acc.{k}"].astype(float) for k in "xyz"], axis=1)
    gyro = np.stack([ff[f"gyro.{k}"].astype(float) for k in "xyz"], axis=1)
    keep = np.isfinite(accel).all(axis=1) & np.isfinite(gyro).all(axis=1) & np.isfinite(t)
    keep &= t > np.r_[-np.inf, np.maximum.accumulate(np.where(keep, t, -np.inf))[:-1]]
    stream = ImuStream(t[keep], accel[keep] * STANDARD_GRAVITY_MPS2, np.radians(gyro[keep]))
    return stream, int(np.sum(~keep))


def default_mocap_path(log_path: str | Path) -> Path | None:
    """The dataset's ``mocapNN.npy`` beside ``logNN`` (None when absent)."""
    log_path = Path(log_path)
    m = re.fullmatch(r"log(\d+)", log_path.name)
    candidate = log_path.with_name(f"mocap{m.group(1)}.npy") if m else None
    return candidate if candidate is not None and candidate.is_file() else None


def system_type(log: UsdLog, source: str | Path) -> int:
    """1 (LH1) or 2 (LH2) from how often a station's sweeps of ``log`` come (LH1: every
    33.3 ms; LH2: every rotor turn, 18.5-20 ms); InputError without angles."""
    if log.count("lhAngle") == 0:
        raise InputError("no lhAngle events in the log", source)
    log.require("lhAngle", ANGLE_VARIABLES, source)
    return 2 if sweep_interval_s(log) < LH2_MAX_INTERVAL_S else 1


def _stations(config: SystemConfig) -> Stations:
    cals = config.calibrations
    return Stations(
        min(config.T_world_lh),
        {k: Station(T, None, cals[k].model() if k in cals
                    else StationModel(generation=config.system_type))
         for k, T in config.T_world_lh.items()},
        {"world": "cfclient"})


def import_crazyflie(log_path: str | Path, out_dir: str | Path,
                     system_config: str | Path | None = None, mocap: str | Path | None = None,
                     overwrite: bool = False) -> CrazyflieImport:
    """Convert a Crazyflie uSD log (LH1 or LH2, told apart by the sweeps' rate) into
    ``angles.csv``, ``board.toml``, ``imu.csv``, with a system configuration ``ootx.toml``
    and ``stations-cfclient.toml``, with a mocap recording (default: ``mocapNN.npy`` beside
    ``logNN``) ``mocap.csv``; refuses to replace files unless ``overwrite`` (InputError when
    the configuration's system type is not the log's)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a directory", out)
    config = None if system_config is None else read_system_config(system_config)
    mocap = default_mocap_path(log_path) if mocap is None else Path(mocap)
    names = ["angles.csv", "board.toml", "imu.csv"]
    names += ["ootx.toml", "stations-cfclient.toml"] if config is not None else []
    names += ["mocap.csv"] if mocap is not None else []
    paths = {name.rsplit(".", 1)[0]: out / name for name in names}
    log = read_usd_log(log_path)
    clock = deck_clock(log)
    if clock is not None and clock.plausible:
        log = replace(log, clock_scale=clock.scale)
    generation = system_type(log, log_path)
    if config is not None and config.system_type != generation:
        raise InputError(f"the system configuration is {SYSTEM_TYPES[config.system_type]} "
                         f"(systemType {config.system_type}) but the log holds "
                         f"{SYSTEM_TYPES[generation]} sweeps", system_config)
    for key, found in (("geos", config and config.T_world_lh),
                       ("calibs", config and config.calibrations)):
        if config is not None and not found:
            raise InputError(f"no '{key}' in the system configuration: the importer writes "
                             "cfclient's geometry and calibration from it", system_config)
    for p in paths.values():
        check_writable(p, overwrite)
    aligned = None
    if mocap is not None:
        aligned = align_mocap(read_mocap_npy(mocap), *marker_events_s(log, log_path))
    angles, sweeps = lh2_angles(log) if generation == 2 else lh1_angles(log)
    if len(angles) == 0:
        raise InputError(f"no valid lhAngle hit in the log ({sweeps.lines()[-1]})", log_path)
    save_angles(angles, paths["angles"], overwrite)
    save_board(crazyflie_deck(), paths["board"], overwrite)
    imu_rate = 0.0
    skipped = []
    stream, imu_dropped = imu_stream(log, log_path)
    if len(stream.time) >= MIN_IMU_SAMPLES:
        save_imu(stream, paths["imu"], overwrite)
        imu_rate = (len(stream.time) - 1) / (stream.time[-1] - stream.time[0])
    else:
        skipped.append(f"imu.csv ({len(stream.time)} valid fixedFrequency samples)")
        del paths["imu"]
    if config is not None:
        save_calibration(config.calibrations, paths["ootx"], overwrite)
        save_stations(_stations(config), paths["stations-cfclient"], overwrite)
    if aligned is not None:
        write_csv_columns(paths["mocap"], {"time": aligned.time, "x": aligned.position[:, 0],
                                           "y": aligned.position[:, 1],
                                           "z": aligned.position[:, 2]},
                          {"time": "{:.6f}"}, overwrite)
    if config is None:
        skipped.append("ootx.toml, stations-cfclient.toml (no --system-config)")
    if mocap is None:
        skipped.append("mocap.csv (no mocapNN.npy beside the log, no --mocap)")
    return CrazyflieImport(paths, log.version, log.notes, sweeps,
                           float(angles.time[-1] - angles.time[0]) if len(angles) else 0.0,
                           float(imu_rate), generation, aligned, tuple(skipped), imu_dropped,
                           clock)
