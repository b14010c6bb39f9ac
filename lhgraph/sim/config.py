"""The simulator's configuration: frozen dataclasses read from a simulation TOML.

Schema in docs/simulator.md. Every table is read with :class:`lhgraph.config.Table`, so an
unknown key, a wrong type or a value out of range is one InputError naming the file and
the key. :func:`paper_protocol` expands the paper's protocol file into named configs.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from lhgraph.config import Table
from lhgraph.errors import InputError
from lhgraph.io.files import as_float, as_int, as_matrix, as_vector, get_key, read_toml
from lhgraph.model.boards import board_by_name
from lhgraph.model.station import (
    CALIBRATION_KEYS,
    LH2_CALIBRATION_KEYS,
    FactoryCalibration,
    StationModel,
)
from lhgraph.sim.deck_log import LoggingConfig
from lhgraph.sim.imu import ImuConfig
from lhgraph.sim.layout import ParametricLayout, parametric_scene
from lhgraph.sim.motion import PATTERNS

ROTOR_PERIOD_S = 1.0 / 60.0  # T: one rotor turn, 800000 ticks of 48 MHz
SLOT_S = ROTOR_PERIOD_S / 2  # one sync flash per station per slot
LH2_PERIOD_TICKS = (959000, 957000, 953000, 949000, 947000, 943000, 941000, 939000, 937000,
                    929000, 919000, 911000, 907000, 901000, 893000, 887000)
"""LH2 rotor period per channel 1..16, ticks of the stations' 48 MHz clock (SPEC §8)."""
LH2_MAX_STATIONS = len(LH2_PERIOD_TICKS)


def lh2_rotor_period_s(channel: int) -> float:
    """Rotor period (s, the station's clock) of an LH2 station on ``channel`` (1-16)."""
    return LH2_PERIOD_TICKS[channel - 1] / 48e6
DEFAULT_CONFIG = "default_simulation.toml"


@dataclass(frozen=True)
class MotionConfig:
    """Board motion; ``centre_m`` and ``up`` (site frame) only with explicit station poses."""

    pattern: str = "wave"
    speed_mps: float = 0.5
    amplitude_m: tuple[float, float, float] = (0.4, 0.3, 0.2)
    rotation_amplitude_deg: float = 20.0
    centre_m: tuple[float, float, float] | None = None
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class NoiseConfig:
    """Angle noise (Gaussian, rad), reflections (replaced hits, offset deg), dropouts (per
    hit), LH1 only the stations' slot-timing jitter (``rotor_jitter_us``: white, rms, each
    station's sync flash and the sweep that follows it move together) and, LH2 only,
    dropped whole sweeps (one plane of one revolution, all diodes)."""

    angle_sigma_rad: float = 0.0
    reflection_fraction: float = 0.0
    reflection_offset_deg: tuple[float, float] = (1.0, 20.0)
    dropout_fraction: float = 0.0
    sweep_dropout_fraction: float = 0.0
    rotor_jitter_us: float = 0.0


@dataclass(frozen=True)
class VisibilityConfig:
    """When a diode sees a sweep: incidence, field of view and the sweep window (LH1); LH2:
    incidence and the field of view ``fov_h_deg`` x ``fov_v_deg`` (half-angles, in the
    LH1-equivalent azimuth and elevation)."""

    max_incidence_deg: float = 75.0
    fov_deg: float = 60.0
    window_ms: tuple[float, float] = (1.2, 6.7)
    fov_h_deg: float = 70.0
    fov_v_deg: float = 50.0


@dataclass(frozen=True)
class SimulationConfig:
    """Everything :func:`simulate` needs (schema in docs/simulator.md).

    ``board`` is a built-in board name or a board TOML path (relative to ``base_dir``);
    ``stations`` (site-frame ``T_site_lh`` poses as ``(x, y, z, qw, qx, qy, qz)`` rows)
    replaces ``layout`` when given;
    ``station_models`` maps station index -> factory calibration and rotor offsets;
    ``first_station`` None = drawn at random; ``clock_ppm`` = how much longer the stations'
    rotor period is on the board's clock (ppm), None = drawn at random in +-30 ppm;
    ``logging`` = how the receiver logs its hits (:class:`LoggingConfig`); ``imu`` = the
    receiver's simulated IMU (:class:`ImuConfig`), None = no IMU stream; ``generation`` =
    1 (LH1 slots, :mod:`lhgraph.sim.simulate`) or 2 (LH2 rotors, :mod:`lhgraph.sim.lh2`;
    every station model then has ``generation = 2`` and its ``channel``).
    """

    duration_s: float = 8.0
    sample_rate_hz: float = 2e6
    board: str = "paper32"
    layout: ParametricLayout = field(default_factory=ParametricLayout)
    stations: tuple[tuple[float, ...], ...] | None = None
    motion: MotionConfig = field(default_factory=MotionConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    visibility: VisibilityConfig = field(default_factory=VisibilityConfig)
    station_models: dict[int, StationModel] = field(default_factory=dict)
    first_station: int | None = None
    clock_ppm: float | None = None
    seed: int = 0
    base_dir: str | None = None
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    imu: ImuConfig | None = None
    generation: int = 1

    @property
    def n_stations(self) -> int:
        """Number of stations simulated."""
        return 2 if self.stations is None else len(self.stations)


def _parse_layout(t: Table) -> ParametricLayout:
    d = ParametricLayout()
    yaw = t.get("relative_yaw_deg", None)
    pitch = t.vector("pitch_deg", None, 2)
    layout = ParametricLayout(
        baseline_m=t.number("baseline_m", d.baseline_m, gt=0.0),
        distance_m=t.number("distance_m", d.distance_m, gt=0.0),
        relative_yaw_deg=None if yaw is None else as_float(yaw, t.source,
                                                           t.key("relative_yaw_deg")),
        station_heights_m=t.vector("station_heights_m", d.station_heights_m, 2),
        board_height_m=t.number("board_height_m", d.board_height_m),
        pitch_deg=pitch,
    )
    t.finish()
    try:
        parametric_scene(layout)
    except InputError as exc:
        raise InputError(exc.problem, t.source, exc.where) from None
    return layout


def _parse_stations(value: Any, source: str | Path) -> tuple[tuple[float, ...], ...]:
    if not isinstance(value, list) or not value:
        raise InputError("expected [[stations]] tables", source, "stations")
    poses = []
    for i, item in enumerate(value):
        t = Table(item, source, f"stations[{i}]")
        position = as_vector(t.get("position", None), 3, source, t.key("position"))
        q = as_vector(t.get("quaternion", None), 4, source, t.key("quaternion"))
        if not 0.9 < np.linalg.norm(q) < 1.1:
            raise InputError("quaternion norm is not ~1", source, t.key("quaternion"))
        t.finish()
        poses.append(tuple(float(x) for x in np.r_[position, q / np.linalg.norm(q)]))
    return tuple(poses)


def _parse_factory(value: Any, source: str | Path, n_stations: int,
                   generation: int = 1) -> dict[int, StationModel]:
    models = {}
    channels: dict[int, int] = {}
    for name, item in Table(value, source, "factory").data.items():
        where = f"factory.{name}"
        try:
            index = int(name)
        except ValueError:
            raise InputError("station index must be an integer", source, where) from None
        if not 0 <= index < n_stations:
            raise InputError(f"no station {index} (stations 0..{n_stations - 1})", source, where)
        t = Table(item, source, where)
        values = {k: as_vector(t.get(k, [0.0, 0.0]), 2, source, t.key(k))
                  for k in CALIBRATION_KEYS}
        offsets = as_matrix(t.get("rotor_offsets", [[0.0] * 3] * 2), 2, 3, source,
                            t.key("rotor_offsets"))
        for k in LH2_CALIBRATION_KEYS + ("channel",):
            if k in t and generation != 2:
                raise InputError("an LH2 key: set generation = 2", source, t.key(k))
        if generation == 2:
            values |= {k: as_vector(t.get(k, [0.0, 0.0]), 2, source, t.key(k))
                       for k in LH2_CALIBRATION_KEYS}
            channels[index] = t.integer("channel", index + 1, ge=1, le=LH2_MAX_STATIONS)
        t.finish()
        models[index] = StationModel(FactoryCalibration(**values), offsets)
    if generation == 2:
        models = {i: StationModel(models[i].calibration if i in models else FactoryCalibration(),
                                  models[i].rotor_offsets if i in models else np.zeros((2, 3)),
                                  generation=2, channel=channels.get(i, i + 1))
                  for i in range(n_stations)}
        seen: dict[int, int] = {}
        for i, model in models.items():
            if model.channel in seen:
                j = seen[model.channel]
                raise InputError(f"stations {j} and {i} both on channel {model.channel} (LH2 "
                                 "stations in one space need distinct channels; default: "
                                 "station i on channel i + 1)", source,
                                 f"factory.{i if i in channels else j}.channel")
            seen[model.channel] = i
    return models


def parse_simulation_config(data: dict[str, Any], source: str | Path,
                            base_dir: str | Path | None = None) -> SimulationConfig:
    """Validate a parsed simulation TOML document; errors name ``source`` and the key."""
    top = Table(data, source, "")
    d = SimulationConfig()
    generation = top.integer("generation", 1, ge=1, le=2)
    if generation == 2:  # keys of the LH1 sync/slot schedule and 2 MHz sampler only
        for key in ("sample_rate_hz", "first_station"):
            if key in data:
                raise InputError("an LH1 key (LH2 has no sync flashes and is not sampled by "
                                 "the board)", source, key)
    duration = top.number("duration_s", d.duration_s, ge=0.1)
    fs = top.number("sample_rate_hz", d.sample_rate_hz, ge=1e5)
    board = top.get("board", d.board)
    if not isinstance(board, str):
        raise InputError(f"expected a board name or path, got {board!r}", source, "board")
    board_by_name(board, base_dir, source, "board")
    seed = as_int(top.get("seed", d.seed), source, "seed")
    if seed < 0:
        raise InputError(f"must be >= 0, got {seed}", source, "seed")

    stations = None
    if "stations" in data:
        if "layout" in data:
            raise InputError("give either [layout] or [[stations]], not both", source, "layout")
        stations = _parse_stations(top.get("stations", None), source)
        layout = d.layout
    else:
        layout = _parse_layout(top.table("layout"))
    n_stations = 2 if stations is None else len(stations)
    if generation == 2 and n_stations > LH2_MAX_STATIONS:
        raise InputError(f"{n_stations} stations: LH2 has {LH2_MAX_STATIONS} channels", source,
                         "stations")

    first = top.get("first_station", "random")
    if first == "random":
        first_station = None
    else:
        first_station = as_int(first, source, "first_station")
        if not 0 <= first_station < n_stations:
            raise InputError(f"must be \"random\" or 0..{n_stations - 1}, got {first}", source,
                             "first_station")

    ppm = top.get("clock_ppm", "random")
    clock_ppm = None if ppm == "random" else as_float(ppm, source, "clock_ppm")
    if clock_ppm is not None and abs(clock_ppm) > 1000:
        raise InputError(f"must be \"random\" or within +-1000, got {ppm}", source, "clock_ppm")

    m = top.table("motion")
    pattern = m.get("pattern", "wave")
    if pattern not in PATTERNS:
        raise InputError(f"must be one of {', '.join(PATTERNS)}, got {pattern!r}", source,
                         m.key("pattern"))
    centre = m.vector("centre_m", None, 3)
    if stations is None and centre is not None:
        raise InputError("only with explicit [[stations]] (the [layout] places the board)",
                         source, m.key("centre_m"))
    if stations is not None and centre is None:
        raise InputError("missing key 'centre_m' (required with [[stations]])", source, "motion")
    up = m.vector("up", (0.0, 0.0, 1.0), 3)
    if stations is None and "up" in m.data:
        raise InputError("only with explicit [[stations]]", source, m.key("up"))
    if np.linalg.norm(up) < 1e-9:
        raise InputError("must not be zero", source, m.key("up"))
    amplitude = m.vector("amplitude_m", MotionConfig.amplitude_m, 3)
    if min(amplitude) < 0:
        raise InputError("must be >= 0", source, m.key("amplitude_m"))
    motion = MotionConfig(
        pattern=pattern,
        speed_mps=m.number("speed_mps", MotionConfig.speed_mps, ge=0.0, le=10.0),
        amplitude_m=amplitude,
        rotation_amplitude_deg=m.number("rotation_amplitude_deg",
                                        MotionConfig.rotation_amplitude_deg, ge=0.0, le=60.0),
        centre_m=centre, up=up)
    m.finish()

    n = top.table("noise")
    offset = n.vector("reflection_offset_deg", NoiseConfig.reflection_offset_deg, 2)
    if not 0 < offset[0] <= offset[1] <= 90:
        raise InputError("expected [low, high] with 0 < low <= high <= 90", source,
                         n.key("reflection_offset_deg"))
    noise = NoiseConfig(
        angle_sigma_rad=n.number("angle_sigma_rad", 0.0, ge=0.0, le=0.1),
        reflection_fraction=n.number("reflection_fraction", 0.0, ge=0.0, le=1.0),
        reflection_offset_deg=offset,
        dropout_fraction=n.number("dropout_fraction", 0.0, ge=0.0, le=1.0),
        sweep_dropout_fraction=n.number("sweep_dropout_fraction", 0.0, ge=0.0, le=1.0),
        rotor_jitter_us=n.number("rotor_jitter_us", 0.0, ge=0.0, le=100.0))
    _refuse_other_generation(n, generation, lh1=("rotor_jitter_us",),
                             lh2=("sweep_dropout_fraction",))
    n.finish()

    v = top.table("visibility")
    window = v.vector("window_ms", VisibilityConfig.window_ms, 2)
    if not 0 <= window[0] < window[1] <= SLOT_S * 1e3:
        raise InputError(f"expected [start, end] with 0 <= start < end <= {SLOT_S * 1e3:.3f}",
                         source, v.key("window_ms"))
    visibility = VisibilityConfig(
        max_incidence_deg=v.number("max_incidence_deg", 75.0, ge=0.0, le=90.0),
        fov_deg=v.number("fov_deg", 60.0, ge=0.0, le=89.0), window_ms=window,
        fov_h_deg=v.number("fov_h_deg", VisibilityConfig.fov_h_deg, ge=0.0, le=89.0),
        fov_v_deg=v.number("fov_v_deg", VisibilityConfig.fov_v_deg, ge=0.0, le=89.0))
    _refuse_other_generation(v, generation, lh1=("fov_deg", "window_ms"),
                             lh2=("fov_h_deg", "fov_v_deg"))
    v.finish()

    models = _parse_factory(top.get("factory", {}), source, n_stations, generation)
    logging = top.options("logging", LoggingConfig)
    if generation == 2 and logging.timestamps == "deck":
        raise InputError("\"deck\" logging is LH1's (a deck's LH2 log is not simulated); use "
                         "\"hit\"", source, "logging.timestamps")
    imu = top.options("imu", ImuConfig) if "imu" in data else None
    top.finish()
    return SimulationConfig(duration, fs, board, layout, stations, motion, noise, visibility,
                            models, first_station, clock_ppm, seed,
                            None if base_dir is None else str(base_dir), logging, imu,
                            generation)


def _refuse_other_generation(t: Table, generation: int, lh1: tuple[str, ...],
                             lh2: tuple[str, ...]) -> None:
    """InputError for a key of ``t`` that only the other generation uses."""
    for key in lh1 if generation == 2 else lh2:
        if key in t:
            other = "LH1" if generation == 2 else "LH2"
            hint = "" if generation == 2 else ": set generation = 2"
            raise InputError(f"an {other} key{hint}", t.source, t.key(key))


def load_simulation_config(path: str | Path) -> SimulationConfig:
    """Read and validate a simulation TOML (board paths are relative to the file)."""
    path = Path(path)
    return parse_simulation_config(read_toml(path), path, path.parent)


def default_config_text() -> str:
    """The bundled default simulation config (same as configs/simulation/default.toml)."""
    return resources.files("lhgraph").joinpath("data", DEFAULT_CONFIG).read_text()


def default_simulation_config() -> SimulationConfig:
    """The bundled default :class:`SimulationConfig`."""
    return parse_simulation_config(tomllib.loads(default_config_text()),
                                   f"<bundled {DEFAULT_CONFIG}>")



def paper_protocol(path: str | Path) -> list[tuple[str, SimulationConfig]]:
    """Expand the paper's simulation protocol file into named configs ("setup03/meas2").

    The file has a ``[base]`` simulation config shared by all measurements and
    ``[[setups]]`` (``name`` and ``[layout]`` keys except ``distance_m``) each with
    ``[[setups.measurements]]`` (``distance_m``, ``pattern``, ``speed_mps``, ``seed``).
    """
    path = Path(path)
    data = read_toml(path)
    top = Table(data, path, "")
    base = top.get("base", {})
    Table(base, path, "base")
    setups = top.get("setups", None)
    top.finish()
    if not isinstance(setups, list) or not setups:
        raise InputError("expected [[setups]] tables", path, "setups")
    out = []
    for i, setup in enumerate(setups):
        s = Table(setup, path, f"setups[{i}]")
        name = s.get("name", f"setup{i + 1:02d}")
        measurements = s.get("measurements", None)
        layout = {key: value for key, value in setup.items()
                  if key not in ("name", "measurements")}
        if not isinstance(measurements, list) or not measurements:
            raise InputError("expected [[setups.measurements]] tables", path,
                             s.key("measurements"))
        for j, meas in enumerate(measurements):
            m = Table(meas, path, s.key(f"measurements[{j}]"))
            for key in ("distance_m", "pattern", "speed_mps", "seed"):
                get_key(meas, key, path, m.where)
            doc = {**base, "seed": m.get("seed", 0),
                   "layout": {**base.get("layout", {}), **layout,
                              "distance_m": m.get("distance_m", None)},
                   "motion": {**base.get("motion", {}), "pattern": m.get("pattern", None),
                              "speed_mps": m.get("speed_mps", None)}}
            m.finish()
            out.append((f"{name}/meas{j + 1}",
                        parse_simulation_config(doc, f"{path}:{m.where}", path.parent)))
    return out
