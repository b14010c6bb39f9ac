"""The receiver's IMU stream: ``imu.csv`` (docs/formats.md, "IMU"), its units checked on
load (an accelerometer in g, a gyro in deg/s are refused naming the fix)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import so3_exp
from lhgraph.io.files import read_csv_columns, write_csv_columns

STANDARD_GRAVITY_MPS2 = 9.80665
"""Standard gravity (m/s^2): an accelerometer at rest reads this along up; g units of a
device's log convert to ``imu.csv``'s m/s^2 with it."""
IMU_COLUMNS = tuple((name, float) for name in ("time", "ax", "ay", "az"))
GYRO_COLUMNS = ("gx", "gy", "gz")
G_UNITS_NORM = (0.5, 2.0)
"""A median accelerometer norm in this range (the unit: m/s^2) is an accelerometer in g: a
hand-held or flying receiver's specific force averages to gravity, 9.81 m/s^2."""
COHERENCE_SEGMENT_S = 2.0
"""Length of the stretches over which the gyro de-rotates the accelerometer (its bias,
~0.01 rad/s, turns gravity by ~1 deg in one)."""
COHERENCE_SEGMENTS = 40
"""At most this many stretches, spread over the stream (the check stays ~0.1 s)."""
DEG_S_MARGIN = 0.15
"""A gyro is in deg/s when de-rotating with it read as deg/s keeps gravity this much more
coherent than read as rad/s (measured on the six shared real streams, Crazyflie and hive:
0.38-0.78 once converted to deg/s, at most 0.07 in their own rad/s)."""


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
    stream = ImuStream(c["time"], accel, gyro)
    check_units(stream, path)
    return stream


def gravity_coherence(stream: ImuStream, scale: float) -> float:
    """How well the gyro, read as ``scale`` x its values in rad/s, de-rotates the
    accelerometer: in stretches of :data:`COHERENCE_SEGMENT_S`, each sample's specific force
    turned into the stretch's first board frame by the integrated gyro, the norm of their
    mean over their mean norm, the median over stretches (1: a constant gravity, the right
    unit; lower: gravity smeared by a wrong rotation). NaN without a gyro or a stretch."""
    if stream.gyro_rad_s is None:
        return float("nan")
    t = stream.time
    dt = np.diff(t, append=t[-1])
    starts = np.arange(t[0], t[-1] - COHERENCE_SEGMENT_S, COHERENCE_SEGMENT_S)
    starts = starts[np.unique(np.linspace(0, len(starts) - 1, COHERENCE_SEGMENTS).astype(int))
                    ] if len(starts) else starts
    out = []
    for t0 in starts:
        idx = np.flatnonzero((t >= t0) & (t < t0 + COHERENCE_SEGMENT_S))
        if len(idx) < 10:
            continue
        steps = so3_exp(scale * stream.gyro_rad_s[idx] * dt[idx, None])
        R_first_now = np.eye(3)
        f_first = np.empty((len(idx), 3))
        for i, j in enumerate(idx):
            f_first[i] = R_first_now @ stream.accel_mps2[j]
            R_first_now = R_first_now @ steps[i]
        norm = np.linalg.norm(f_first, axis=1).mean()
        if norm > 0:
            out.append(np.linalg.norm(f_first.mean(axis=0)) / norm)
    return float(np.median(out)) if out else float("nan")


def check_units(stream: ImuStream, path: str | Path) -> None:
    """Refuse (:class:`InputError`, naming ``path``, the unit and the fix) an accelerometer
    in g (median norm in :data:`G_UNITS_NORM`) or a gyro in deg/s (it de-rotates gravity
    better read as deg/s than as rad/s, :func:`gravity_coherence`; a receiver that hardly
    turns cannot tell, and is let through)."""
    median = float(np.median(np.linalg.norm(stream.accel_mps2, axis=1)))
    if G_UNITS_NORM[0] <= median <= G_UNITS_NORM[1]:
        raise InputError(f"the accelerometer reads in g (median norm {median:.2f}): imu.csv "
                         f"is in m/s^2, multiply ax,ay,az by {STANDARD_GRAVITY_MPS2}", path)
    as_rad = gravity_coherence(stream, 1.0)
    as_deg = gravity_coherence(stream, np.pi / 180)
    if as_deg - as_rad > DEG_S_MARGIN:
        raise InputError(f"the gyro reads in deg/s (read as deg/s it keeps gravity "
                         f"{as_deg:.2f} coherent, as rad/s {as_rad:.2f}): imu.csv is in rad/s, "
                         f"multiply gx,gy,gz by pi/180", path)


def save_imu(stream: ImuStream, path: str | Path, overwrite: bool = False,
             time_format: str = "{:.6f}") -> Path:
    """Write ``stream`` as an ``imu.csv`` (the gyro columns only when it has a gyro; times
    written with ``time_format``)."""
    columns = {"time": stream.time}
    columns |= {f"a{k}": stream.accel_mps2[:, i] for i, k in enumerate("xyz")}
    if stream.gyro_rad_s is not None:
        columns |= {f"g{k}": stream.gyro_rad_s[:, i] for i, k in enumerate("xyz")}
    return write_csv_columns(path, columns, {"time": time_format}, overwrite)
