"""Factory-calibration files (``ootx.toml``): what a station broadcasts over OOTX.

``[lighthouses.K]`` with ``id`` (int), ``phase, tilt, curve, gibphase, gibmag`` as
``[axis0, axis1]`` (rad) and ``accel_dir`` (3 ints: the accelerometer at rest, i.e. up, in
the station's native frame, :mod:`lhgraph.estimation.gravity`); K is the station index used in the
angles CSV.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.files import as_int, as_vector, read_toml, station_tables, write_toml
from lhgraph.model.lh1 import CALIBRATION_KEYS, FactoryCalibration


@dataclass(frozen=True)
class StationCalibration:
    """OOTX content of one station."""

    calibration: FactoryCalibration
    id: int = 0
    accel_dir: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))


def load_calibration(path: str | Path) -> dict[int, StationCalibration]:
    """Read an ``ootx.toml`` -> {station index: StationCalibration}."""
    data = read_toml(path)
    out: dict[int, StationCalibration] = {}
    for index, table, where in station_tables(data, path):
        values = {}
        for key in CALIBRATION_KEYS:
            if key not in table:
                raise InputError(f"missing key '{key}'", path, where)
            values[key] = as_vector(table[key], 2, path, f"{where}.{key}")
        station_id = as_int(table.get("id", 0), path, where + ".id")
        accel = np.zeros(3)
        if "accel_dir" in table:
            accel = as_vector(table["accel_dir"], 3, path, where + ".accel_dir")
        out[index] = StationCalibration(FactoryCalibration(**values), station_id, accel)
    return out


def save_calibration(
    calibrations: dict[int, StationCalibration], path: str | Path, overwrite: bool = False
) -> Path:
    """Write an ``ootx.toml``."""
    tables = {}
    for index in sorted(calibrations):
        c = calibrations[index]
        tables[str(index)] = {
            "id": int(c.id),
            **c.calibration.as_dict(),
            "accel_dir": [float(x) for x in c.accel_dir],
        }
    return write_toml(path, {"lighthouses": tables}, overwrite)
