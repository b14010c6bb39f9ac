"""``lhgraph export cfclient`` / ``lhgraph export libsurvive``: a stations TOML as
cfclient's ``system-config.yaml`` or libsurvive's ``config.json``.

:func:`prepare_export` reads the stations (and optionally their factory calibration, the
receiver's IMU stream and trajectory) and re-expresses the stations in the world a user of
the other tool expects (:mod:`lhgraph.estimation.world_alignment`: z up from gravity,
origin and x by name). :func:`export_cfclient` then maps our calibration terms to
Bitcraze's (:mod:`lhgraph.model.bitcraze`, through
:data:`lhgraph.io.cfclient.CALIBRATION_MAPPINGS`) and writes the file
(:mod:`lhgraph.io.cfclient`); :func:`export_libsurvive` writes libsurvive's
(:mod:`lhgraph.io.libsurvive_config`). The file's system is the stations' generation (LH1
or LH2, :func:`system_type`). Every input is checked before anything is written.
docs/export.md and docs/interop.md describe the options.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.world_alignment import (
    UpEstimate,
    WorldAlignment,
    WorldOptions,
    align_world,
    still_mask,
    transform_stations,
    up_from_imu,
    up_from_ootx,
)
from lhgraph.io.cfclient import SYSTEM_TYPES, SystemConfig, write_system_config
from lhgraph.io.files import check_writable, read_toml, station_tables
from lhgraph.io.imu import ImuStream, load_imu
from lhgraph.io.libsurvive_config import SurviveConfig, SurviveLighthouse, write_survive_config
from lhgraph.io.stations import Stations, load_stations
from lhgraph.io.trajectory import Trajectory, load_trajectory
from lhgraph.model.calibration import StationCalibration, load_calibration

MAX_REST_TILT_DEG = 5.0
"""The receiver at rest at the receiver-start: its accelerometer through the trajectory's
pose within this of the new world's up (deg)."""


@dataclass(frozen=True)
class PreparedExport:
    """The stations to export, in the new world (:func:`prepare_export`), with their
    factory calibrations, generation, how the world was chosen and the warnings so far."""

    stations: Stations
    calibrations: dict[int, StationCalibration]
    generation: int
    alignment: WorldAlignment
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote: the file, its content (our types), the stations in the new
    world and how that world was chosen."""

    path: Path
    config: SystemConfig | SurviveConfig
    stations: Stations
    alignment: WorldAlignment
    warnings: tuple[str, ...] = ()

    def summary(self) -> str:
        """Two lines for the terminal (the warnings are separate)."""
        if isinstance(self.config, SystemConfig):
            n, system = len(self.config.T_world_lh), self.config.system_type
            n_cal, label = len(self.config.calibrations), f"systemType {system}"
        else:
            n, system = len(self.config.lighthouses), self.config.generation
            n_cal = sum(lh.calibration is not None for lh in self.config.lighthouses.values())
            label = f"lighthouse-gen {system}"
        return (f"wrote {self.path}: {n} station(s), {n_cal} with factory calibration, "
                f"{label} ({SYSTEM_TYPES[system]})\n{self.alignment.summary()}")


def _calibrations_of(stations: Stations, calibrations: dict[int, StationCalibration]
                     ) -> tuple[dict[int, StationCalibration], list[str]]:
    """The calibrations of the exported stations, and a warning per station without one."""
    missing = [k for k in stations.indices() if k not in calibrations]
    warnings = [f"station {k} has no factory calibration in the calibration file: the "
                "Crazyflie will use what it receives from the station" for k in missing]
    return {k: calibrations[k] for k in stations.indices() if k in calibrations}, warnings


def _generation_of(generations: dict[int, int], path: str | Path, what: str) -> int:
    """The one generation of ``generations`` (station index -> 1 or 2); InputError naming
    the stations of each when they are mixed (one cfclient system is LH1 or LH2)."""
    kinds = sorted(set(generations.values()))
    if len(kinds) > 1:
        parts = "; ".join(
            f"{SYSTEM_TYPES[g]}: station(s) "
            + ", ".join(str(k) for k in sorted(generations) if generations[k] == g)
            for g in kinds)
        raise InputError(f"mixed generations in the {what} ({parts}): a cfclient system is "
                         "either LH1 or LH2, export each generation from its own file", path)
    return kinds[0]


def system_type(stations: Stations, stations_path: str | Path,
                calibrations: dict[int, StationCalibration] | None = None,
                calibration_path: str | Path | None = None) -> int:
    """The exported ``systemType`` (1 = LH1, 2 = LH2): the stations' generation.

    From the calibration file's ``generation`` when one is given (every station of it), else
    from the stations file's models (``generation``, LH1 when absent). InputError (one line)
    when either file mixes generations, when the stations file states a generation
    (``generation`` keys) that the calibration contradicts, or when the stations file's old
    top-level ``system_type`` key is not 1 or 2 or contradicts the generation. A stations
    file without ``generation`` keys and without a calibration keeps declaring its system with
    ``system_type`` (``system_type = 2``: LH2).
    """
    in_file = _generation_of({k: stations.stations[k].model.generation
                              for k in stations.indices()}, stations_path, "stations file")
    stated = any("generation" in table for _, table, _ in
                 station_tables(read_toml(stations_path), stations_path))
    generation, source = in_file, f"the stations' generation in {stations_path}"
    if calibrations:
        generation = _generation_of({k: c.generation for k, c in calibrations.items()},
                                    calibration_path, "calibration file")
        source = f"the calibration's generation in {calibration_path}"
        if stated and in_file != generation:
            raise InputError(
                f"the stations file says {SYSTEM_TYPES[in_file]} (generation = {in_file}) but "
                f"the calibration {calibration_path} says {SYSTEM_TYPES[generation]} "
                f"(generation = {generation})", stations_path)
    declared = stations.extra.get("system_type")
    if declared is None:
        return generation
    if isinstance(declared, bool) or not isinstance(declared, int) or (
            declared not in SYSTEM_TYPES):
        raise InputError(f"system_type must be 1 (LH1) or 2 (LH2), got {declared!r}",
                         stations_path, "system_type")
    if declared != generation:
        if not stated and not calibrations:
            return int(declared)  # the file's only statement of its system
        raise InputError(
            f"system_type = {declared} ({SYSTEM_TYPES[declared]}) contradicts {source} "
            f"({SYSTEM_TYPES[generation]}): remove system_type or correct the generation",
            stations_path, "system_type")
    return generation


def verdict_warnings(stations: Stations, stations_path: str | Path, unverified: bool
                     ) -> list[str]:
    """What the stations file's ``verdict`` table (a ``lhgraph solve`` result's) says about
    exporting it: SolverError (exit 3) for a failed result unless ``unverified``; a warning
    for a failed one exported anyway and for one to be checked; nothing for a file without a
    verdict (a truth file, cfclient's geometry) or an OK one."""
    table = stations.extra.get("verdict")
    if not isinstance(table, dict) or table.get("status") in (None, "ok"):
        return []
    text = str(table.get("text") or table.get("status"))
    if table.get("status") == "failed" and not unverified:
        raise SolverError(f"{stations_path}: the result's verdict is {text}; solve again, or "
                          "export it anyway with --force-unverified")
    return [f"exporting a result whose verdict is {text}"]


def check_resting_start(imu: ImuStream, trajectory: Trajectory, alignment: WorldAlignment,
                        options: WorldOptions) -> None:
    """cfclient's convention (``receiver-start``): the receiver rests on the floor at the
    origin at ``alignment.at_s``. InputError when the IMU shows it moving there (the origin
    would be wherever it was carried, e.g. 1.1 m above the floor on the shared hand-held
    LH1 log) or when its accelerometer at rest, through the trajectory's pose, is more than
    :data:`MAX_REST_TILT_DEG` from the new world's up (the tracked pose is flipped)."""
    at = float(alignment.at_s)  # type: ignore[arg-type]
    near = np.abs(imu.time - at) <= 0.5 * options.still_window_s
    still = still_mask(imu.time, imu.accel_mps2, imu.gyro_rad_s, options)
    if not np.any(near) or not np.all(still[near]):
        raise InputError(
            f"the receiver is moving at t = {at:.3f} s (its IMU shows no rest there): "
            "receiver-start puts cfclient's origin where the receiver is, which cfclient "
            "takes to be resting on the floor; give --at S of a moment it rests on the floor "
            "at the origin, or --origin/--x reference-station or world")
    R = trajectory.at(imu.time[near])[:, :3, :3]
    f = np.einsum("nij,nj->ni", R, imu.accel_mps2[near]).mean(axis=0)
    up_w = alignment.T_new_w[2, :3]
    tilt = float(np.degrees(np.arccos(np.clip(f @ up_w / np.linalg.norm(f), -1.0, 1.0))))
    if tilt > MAX_REST_TILT_DEG:
        raise InputError(
            f"at rest (t = {at:.3f} s) the trajectory's pose puts the accelerometer's gravity "
            f"{tilt:.1f} deg from up (more than {MAX_REST_TILT_DEG:g}): the tracked pose there "
            "is wrong (a mirror pose of a few-diode receiver's light-only track?): track it "
            "with --imu")


def _up(options: WorldOptions, stations: Stations,
        calibrations: dict[int, StationCalibration] | None, imu: ImuStream | None,
        trajectory: Trajectory | None) -> UpEstimate:
    source = options.up
    if source == "auto":
        has_ootx = calibrations is not None and any(np.any(c.accel_dir)
                                                    for c in calibrations.values())
        source = "imu" if imu is not None else "ootx" if has_ootx else "none"
    if source == "imu":
        if imu is None or trajectory is None:
            raise InputError("--up imu needs the receiver's IMU stream (--imu) and its "
                             "trajectory (--trajectory)")
        return up_from_imu(imu.time, imu.accel_mps2, imu.gyro_rad_s, trajectory, options)
    if source == "ootx":
        if calibrations is None:
            raise InputError("--up ootx needs the stations' factory calibration "
                             "(--calibration ootx.toml)")
        return up_from_ootx(stations, calibrations)
    return UpEstimate(np.array([0.0, 0.0, 1.0]), "none")


def prepare_export(stations_path: str | Path, *, calibration: str | Path | None = None,
                   imu: str | Path | None = None, trajectory: str | Path | None = None,
                   options: WorldOptions | None = None, unverified: bool = False
                   ) -> PreparedExport:
    """Read and check what an export needs and move the stations into the new world.

    ``calibration``: an ``ootx.toml`` (its terms go into the file; its accelerometer
    vectors can give up); ``imu`` (``imu.csv``, board frame) and ``trajectory``
    (``T_world_board`` in the stations' world, e.g. from ``lhgraph solve --trajectory`` or
    ``lhgraph track``): the receiver's data for ``up = imu`` and the receiver-start choices
    (:func:`check_resting_start`). A result whose ``verdict`` failed (e.g. a solve stopped
    at its iteration limit) is refused unless ``unverified`` (:func:`verdict_warnings`).
    """
    options = options or WorldOptions()
    if imu is not None and trajectory is None:
        raise InputError("--imu needs --trajectory: the receiver's poses carry its "
                         "accelerometer into the stations' world")
    stations = load_stations(stations_path)
    verdict_notes = verdict_warnings(stations, stations_path, unverified)
    calibrations = None if calibration is None else load_calibration(calibration)
    generation = system_type(stations, stations_path, calibrations, calibration)
    stream = None if imu is None else load_imu(imu)
    path_poses = None if trajectory is None else load_trajectory(trajectory)
    up = _up(options, stations, calibrations, stream, path_poses)
    alignment = align_world(stations, up, path_poses, options)
    if stream is not None and path_poses is not None and alignment.at_s is not None:
        check_resting_start(stream, path_poses, alignment, options)
    moved = transform_stations(stations, alignment.T_new_w)
    calibs, warnings = ({}, []) if calibrations is None else _calibrations_of(
        stations, calibrations)
    return PreparedExport(moved, calibs, generation, alignment,
                          tuple(verdict_notes + warnings))


def export_cfclient(stations_path: str | Path, output: str | Path, *,
                    calibration: str | Path | None = None, imu: str | Path | None = None,
                    trajectory: str | Path | None = None,
                    options: WorldOptions | None = None,
                    overwrite: bool = False, unverified: bool = False) -> ExportResult:
    """Write ``stations_path`` (a stations TOML, LH1 or LH2: :func:`system_type`) as
    cfclient's ``system-config.yaml`` (the other arguments: :func:`prepare_export`). The
    calibration's terms are written through the mapping of the system type
    (:data:`lhgraph.io.cfclient.CALIBRATION_MAPPINGS`; LH2: Bitcraze's terms are ours).
    """
    output = check_writable(output, overwrite, create_parents=False)
    ready = prepare_export(stations_path, calibration=calibration, imu=imu,
                           trajectory=trajectory, options=options, unverified=unverified)
    moved = ready.stations
    config = SystemConfig(ready.generation, {k: moved.pose(k) for k in moved.indices()},
                          ready.calibrations)
    path = write_system_config(config, output, overwrite)
    moved = dataclasses.replace(moved, extra={**moved.extra, "world": "cfclient"})
    return ExportResult(path, config, moved, ready.alignment, ready.warnings)


def export_libsurvive(stations_path: str | Path, output: str | Path, *,
                      calibration: str | Path | None = None, imu: str | Path | None = None,
                      trajectory: str | Path | None = None,
                      options: WorldOptions | None = None,
                      overwrite: bool = False, unverified: bool = False) -> ExportResult:
    """Write ``stations_path`` (a stations TOML, LH1 or LH2) as libsurvive's
    ``config.json`` (:mod:`lhgraph.io.libsurvive_config`; the other arguments:
    :func:`prepare_export`): each station's pose in libsurvive's lighthouse frame, its
    covariance as libsurvive's world-axis variances, its factory calibration (OOTX values,
    ``OOTXSet`` 1) and ``mode`` (LH2: channel - 1; LH1: the station index)."""
    output = check_writable(output, overwrite, create_parents=False)
    ready = prepare_export(stations_path, calibration=calibration, imu=imu,
                           trajectory=trajectory, options=options, unverified=unverified)
    lighthouses = {}
    for k in ready.stations.indices():
        station = ready.stations.stations[k]
        cal = ready.calibrations.get(k)
        channel = cal.channel if cal is not None else station.model.channel
        mode = channel - 1 if ready.generation == 2 and channel is not None else k
        lighthouses[k] = SurviveLighthouse(station.T_world_lh, station.covariance, cal, mode)
    config = SurviveConfig(ready.generation, lighthouses)
    path = write_survive_config(config, output, overwrite)
    moved = dataclasses.replace(ready.stations,
                                extra={**ready.stations.extra, "world": "libsurvive"})
    return ExportResult(path, config, moved, ready.alignment, ready.warnings)
