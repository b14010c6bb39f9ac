"""A libsurvive ``config.json`` into lhgraph contract files: :func:`import_libsurvive` (the
``lhgraph import libsurvive`` command, docs/interop.md).

The stations keep libsurvive's world; their poses are re-expressed in our station frame
(:data:`lhgraph.io.libsurvive_config.R_SURVIVE_LH`), the file's variances become diagonal
covariances, and the factory calibration (where ``OOTXSet``) becomes an ``ootx.toml``. The
stations TOML serves as a start (``lhgraph track --stations``, ``lhgraph compare``) or, with
its covariance, as a prior.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lhgraph.errors import InputError
from lhgraph.io.files import check_writable
from lhgraph.io.libsurvive_config import SurviveConfig, read_survive_config
from lhgraph.io.stations import Station, Stations, save_stations
from lhgraph.model.calibration import save_calibration
from lhgraph.model.station import StationModel


@dataclass(frozen=True)
class SurviveImport:
    """What :func:`import_libsurvive` wrote (``stations`` and, when the file had factory
    calibration, ``ootx``) and the file read."""

    paths: dict[str, Path]
    config: SurviveConfig

    def summary(self) -> str:
        """Lines for the terminal: what was written, and what the file left out."""
        n_cal = sum(lh.calibration is not None for lh in self.config.lighthouses.values())
        n_cov = sum(lh.covariance is not None for lh in self.config.lighthouses.values())
        n_pose = sum(lh.T_world_lh is not None for lh in self.config.lighthouses.values())
        lines = [f"{len(self.config.lighthouses)} station(s), LH{self.config.generation}: "
                 f"{n_pose} with a pose, {n_cal} with factory calibration, {n_cov} with a "
                 "variance",
                 *(f"note: {note}" for note in self.config.notes),
                 "wrote " + ", ".join(str(p) for p in self.paths.values())]
        return "\n".join(lines)


def survive_stations(config: SurviveConfig, source: str | Path | None = None) -> Stations:
    """The stations of a libsurvive config that have a pose (libsurvive's world; the lowest
    index is the reference); InputError naming ``source`` when none has."""
    stations = {}
    for k, lh in config.lighthouses.items():
        if lh.T_world_lh is None:
            continue
        model = lh.calibration.model() if lh.calibration is not None else \
            StationModel(generation=config.generation)
        stations[k] = Station(lh.T_world_lh, lh.covariance, model)
    if not stations:
        raise InputError("no lighthouse has a pose (PositionSet 0 everywhere)", source)
    return Stations(min(stations), stations, {"world": "libsurvive"})


def import_libsurvive(config_path: str | Path, out_dir: str | Path, overwrite: bool = False
                      ) -> SurviveImport:
    """Convert libsurvive's ``config.json`` into ``stations.toml`` and (when any station
    has its calibration) ``ootx.toml`` in ``out_dir``; refuses to replace files unless
    ``overwrite``."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a directory", out)
    config = read_survive_config(config_path)
    stations = survive_stations(config, config_path)
    calibrations = {k: lh.calibration for k, lh in config.lighthouses.items()
                    if lh.calibration is not None}
    paths = {"stations": out / "stations.toml"}
    if calibrations:
        paths["ootx"] = out / "ootx.toml"
    for p in paths.values():
        check_writable(p, overwrite)
    save_stations(stations, paths["stations"], overwrite)
    if calibrations:
        save_calibration(calibrations, paths["ootx"], overwrite)
    return SurviveImport(paths, config)
