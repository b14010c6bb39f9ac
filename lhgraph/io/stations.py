"""Station poses and their files (truth and results share one format, SPEC §4).

``[lighthouses.<index>]`` tables hold ``position`` and ``quaternion = [w, x, y, z]`` of
``T_world_lh``; results add ``covariance`` (6x6, tangent order ``[rx, ry, rz, tx, ty, tz]``; the
graph's is the honest one, docs/uncertainty.md), may add ``covariance_white`` (the same for
independent residuals only) and may add the factory-calibration keys and
``rotor_offsets``; an LH2 station has ``generation = 2`` (LH1 when absent), its ogee terms
and maybe its ``channel`` (docs/formats.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import matrix_to_quat, pose_from_quat
from lhgraph.io.files import (
    as_int,
    as_matrix,
    as_vector,
    get_key,
    read_toml,
    station_tables,
    write_toml,
)
from lhgraph.model.calibration import check_ranges, generation_keys, generation_terms
from lhgraph.model.station import CALIBRATION_KEYS, FactoryCalibration, StationModel


@dataclass
class Station:
    """One station: ``T_world_lh`` (4x4), optional covariance (6x6), model and optional
    white-noise covariance (6x6; ``covariance`` is then the honest one)."""

    T_world_lh: NDArray[np.float64]
    covariance: NDArray[np.float64] | None = None
    model: StationModel = field(default_factory=StationModel)
    covariance_white: NDArray[np.float64] | None = None

    def moved(self, T_new_world: NDArray[np.float64]) -> Station:
        """The same station in a new world, ``T_new_world @ T_world_lh`` (its covariances
        are in its own tangent space and do not change)."""
        return replace(self, T_world_lh=T_new_world @ self.T_world_lh)


@dataclass
class Stations:
    """All stations of a setup, keyed by station index; ``reference`` defines the world."""

    reference: int
    stations: dict[int, Station]
    extra: dict[str, Any] = field(default_factory=dict)

    def pose(self, index: int) -> NDArray[np.float64]:
        """``T_world_lh`` of station ``index``."""
        return self.stations[index].T_world_lh

    def indices(self) -> list[int]:
        """Sorted station indices."""
        return sorted(self.stations)

    def relative_to_reference(self) -> Stations:
        """The same setup re-expressed with the reference station's frame as world."""
        T_ref_world = np.linalg.inv(self.pose(self.reference))
        return Stations(
            self.reference,
            {k: s.moved(T_ref_world) for k, s in self.stations.items()},
            dict(self.extra),
        )


def _parse_model(table: dict[str, Any], path: str | Path, where: str) -> StationModel:
    values = {}
    for key in CALIBRATION_KEYS:
        if key in table:
            values[key] = as_vector(table[key], 2, path, f"{where}.{key}")
    generation, channel = generation_terms(table, path, where, values)
    check_ranges(values, path, where)
    offsets = np.zeros((2, 3))
    if "rotor_offsets" in table:
        offsets = as_matrix(table["rotor_offsets"], 2, 3, path, f"{where}.rotor_offsets")
    return StationModel(FactoryCalibration(**values), offsets, generation=generation,
                        channel=channel)


def load_stations(path: str | Path) -> Stations:
    """Read a stations TOML (truth or result)."""
    data = read_toml(path)
    reference = as_int(get_key(data, "reference", path, "top level"), path, "reference")
    stations: dict[int, Station] = {}
    for index, table, where in station_tables(data, path):
        position = as_vector(get_key(table, "position", path, where), 3, path, where + ".position")
        q = as_vector(get_key(table, "quaternion", path, where), 4, path, where + ".quaternion")
        norm = np.linalg.norm(q)
        if not 0.9 < norm < 1.1:
            raise InputError(f"quaternion norm {norm:.3g} is not ~1", path, where + ".quaternion")
        cov, white = (as_matrix(table[key], 6, 6, path, f"{where}.{key}") if key in table
                      else None for key in ("covariance", "covariance_white"))
        stations[index] = Station(pose_from_quat(position, q / norm), cov,
                                  _parse_model(table, path, where), white)
    if reference not in stations:
        raise InputError(f"reference station {reference} has no [lighthouses.{reference}] table",
                         path, "reference")
    extra = {k: v for k, v in data.items() if k not in ("reference", "lighthouses")}
    return Stations(reference, stations, extra)


def stations_to_toml(stations: Stations, with_model: bool = True) -> dict[str, Any]:
    """The TOML document of ``stations`` (contract keys first)."""
    tables: dict[str, Any] = {}
    for index in stations.indices():
        s = stations.stations[index]
        table: dict[str, Any] = {
            "position": [float(x) for x in s.T_world_lh[:3, 3]],
            "quaternion": [float(x) for x in matrix_to_quat(s.T_world_lh[:3, :3])],
        }
        for key, cov in (("covariance", s.covariance), ("covariance_white", s.covariance_white)):
            if cov is not None:
                table[key] = [[float(x) for x in row] for row in cov]
        if with_model and not s.model.calibration.is_zero():
            table.update(s.model.calibration.as_dict(s.model.generation))
        if with_model and np.any(s.model.rotor_offsets):
            table["rotor_offsets"] = [[float(x) for x in row] for row in s.model.rotor_offsets]
        table.update(generation_keys(s.model.generation, s.model.channel))
        tables[str(index)] = table
    return {**stations.extra, "reference": int(stations.reference), "lighthouses": tables}


def save_stations(stations: Stations, path: str | Path, overwrite: bool = False) -> Path:
    """Write a stations TOML."""
    return write_toml(path, stations_to_toml(stations), overwrite)
