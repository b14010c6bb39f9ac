"""Factory-calibration files (``ootx.toml``): what a station broadcasts over OOTX.

``[lighthouses.K]`` with ``id`` (int), ``phase, tilt, curve, gibphase, gibmag`` as
``[axis0, axis1]`` (rad) and ``accel_dir`` (3 ints: the accelerometer at rest, i.e. up, in
the station's native frame, :mod:`lhgraph.estimation.gravity`); K is the station index used in the
angles CSV. Added for LH2 stations (all optional, docs/formats.md): ``generation`` (1 or 2;
1 when absent), ``ogeephase, ogeemag`` (``[plane0, plane1]``, rad; LH2 only) and
``channel`` (1-16, the station's LH2 channel). Every term is range-checked on load
(:data:`CALIBRATION_RANGES`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.files import as_int, as_vector, read_toml, station_tables, write_toml
from lhgraph.model.station import (
    CALIBRATION_KEYS,
    GENERATIONS,
    LH2_CALIBRATION_KEYS,
    Convention,
    FactoryCalibration,
    StationModel,
)

N_CHANNELS = 16
"""LH2 stations broadcast on channels 1-16 (SPEC §8)."""

CALIBRATION_RANGES: dict[str, float] = {
    "phase": 0.2, "tilt": 0.2, "curve": 1.0, "gibphase": 2 * np.pi, "gibmag": 0.1,
    "ogeephase": 2 * np.pi, "ogeemag": 1.0, "accel_dir": 128.0,
}
"""The largest magnitude a factory-calibration term may have (rad; ``accel_dir``: the int8
reading). Generous: real stations' terms are at most 0.062 (phase), 0.052 (tilt), 0.42
(curve, LH2), 0.021 (gibmag) and 0.46 (ogeemag, LH2); the phases (gibphase, ogeephase) are
angles, within one turn either side of zero. A value outside is not a factory calibration
(e.g. 0.5 rad of phase would move a station's every angle by 29 deg). docs/formats.md."""


def check_ranges(values: dict[str, NDArray[np.float64]], path: str | Path, where: str) -> None:
    """InputError naming the first term of ``values`` (key -> vector) outside
    :data:`CALIBRATION_RANGES`, its value and the allowed range."""
    for key, value in values.items():
        bound = CALIBRATION_RANGES.get(key)
        bad = [] if bound is None else np.flatnonzero(~(np.abs(value) <= bound))
        if len(bad):
            i = int(bad[0])
            raise InputError(f"{value[i]:g} is outside the plausible range [{-bound:g}, "
                             f"{bound:g}]{'' if key == 'accel_dir' else ' rad'}", path,
                             f"{where}.{key}[{i}]")


@dataclass(frozen=True)
class StationCalibration:
    """OOTX content of one station."""

    calibration: FactoryCalibration
    id: int = 0
    accel_dir: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    generation: int = 1
    channel: int | None = None

    def model(self, convention: Convention | None = None) -> StationModel:
        """The station's measurement model (LH1 sign ``convention``: default
        :class:`Convention`)."""
        return StationModel(self.calibration, convention=convention or Convention(),
                            generation=self.generation, channel=self.channel)


def generation_terms(table: dict, path: str | Path, where: str, values: dict[str, np.ndarray]
                     ) -> tuple[int, int | None]:
    """A station table's ``generation`` (1 when absent) and ``channel`` (None when absent);
    its LH2 calibration terms are added to ``values`` (InputError: an unknown generation, a
    channel outside 1-16, ogee terms on an LH1 station)."""
    generation = as_int(table.get("generation", 1), path, where + ".generation")
    if generation not in GENERATIONS:
        raise InputError(f"generation must be 1 or 2, got {generation}", path,
                         where + ".generation")
    for key in LH2_CALIBRATION_KEYS:
        if key in table:
            if generation != 2:
                raise InputError(f"'{key}' is an LH2 term: set generation = 2", path,
                                 f"{where}.{key}")
            values[key] = as_vector(table[key], 2, path, f"{where}.{key}")
    channel = None
    if "channel" in table:
        channel = as_int(table["channel"], path, where + ".channel")
        if not 1 <= channel <= N_CHANNELS:
            raise InputError(f"channel must be 1-{N_CHANNELS}, got {channel}", path,
                             where + ".channel")
    return generation, channel


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
        generation, channel = generation_terms(table, path, where, values)
        check_ranges(values | {"accel_dir": accel}, path, where)
        out[index] = StationCalibration(FactoryCalibration(**values), station_id, accel,
                                        generation, channel)
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
            **c.calibration.as_dict(c.generation),
            "accel_dir": [float(x) for x in c.accel_dir],
            **generation_keys(c.generation, c.channel),
        }
    return write_toml(path, {"lighthouses": tables}, overwrite)


def generation_keys(generation: int, channel: int | None) -> dict[str, int]:
    """The ``generation`` and ``channel`` keys of a station table (none for an LH1 station
    without a channel: old readers see the files they know)."""
    keys = {"generation": generation} if generation != 1 else {}
    return keys | ({"channel": channel} if channel is not None else {})
