"""The receiver's IMU stream: ``imu.csv`` (docs/formats.md, "IMU")."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lhgraph.errors import InputError
from lhgraph.io.files import read_csv_columns, write_csv_columns

STANDARD_GRAVITY_MPS2 = 9.80665
"""Standard gravity (m/s^2): an accelerometer at rest reads this along up; g units of a
device's log convert to ``imu.csv``'s m/s^2 with it."""
IMU_COLUMNS = tuple((name, float) for name in ("time", "ax", "ay", "az"))
GYRO_COLUMNS = ("gx", "gy", "gz")


@dataclass(frozen=True)
class ImuStream:
    """An IMU stream in the board frame: ``time`` (N,) s, ``accel_mps2`` (N, 3) specific
    force and ``gyro_rad_s`` (N, 3) angular rate, or None when the file has no gyro."""

    time: np.ndarray
    accel_mps2: np.ndarray
    gyro_rad_s: np.ndarray | None = None


def load_imu(path: str | Path) -> ImuStream:
    """Read an ``imu.csv`` (``time,ax,ay,az[,gx,gy,gz]``, s, m/s^2, rad/s; docs/formats.md)."""
    c = read_csv_columns(path, IMU_COLUMNS, optional=GYRO_COLUMNS)
    if len(c["time"]) < 3:
        raise InputError(f"{len(c['time'])} rows: an IMU stream needs at least 3", path)
    if np.any(back := np.diff(c["time"]) <= 0):
        raise InputError("time must increase", path, str(int(np.flatnonzero(back)[0]) + 3))
    accel = np.stack([c["ax"], c["ay"], c["az"]], axis=1)
    gyro = (np.stack([c[k] for k in GYRO_COLUMNS], axis=1)
            if all(k in c for k in GYRO_COLUMNS) else None)
    return ImuStream(c["time"], accel, gyro)


def save_imu(stream: ImuStream, path: str | Path, overwrite: bool = False,
             time_format: str = "{:.6f}") -> Path:
    """Write ``stream`` as an ``imu.csv`` (the gyro columns only when it has a gyro; times
    written with ``time_format``)."""
    columns = {"time": stream.time}
    columns |= {f"a{k}": stream.accel_mps2[:, i] for i, k in enumerate("xyz")}
    if stream.gyro_rad_s is not None:
        columns |= {f"g{k}": stream.gyro_rad_s[:, i] for i, k in enumerate("xyz")}
    return write_csv_columns(path, columns, {"time": time_format}, overwrite)
