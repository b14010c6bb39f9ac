"""Capture simulator: Lighthouse v1 sweeps seen by a waved photodiode board (docs/simulator.md).

Models the LH1 slot schedule (one axis of one station swept per T/2 slot, every station
flashing a sync in every slot, 20000 ticks of 48 MHz apart), solves each hit time on the
moving board with the full station model, applies visibility, pulse width and 2 MHz
quantisation, and derives the angles exactly as a decoder would from the quantised samples.
World frame = station 0's frame. Times in s, angles in rad, lengths in m.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import inverse, pose_from_quat, transform_points
from lhgraph.io.angles import Angles, save_angles
from lhgraph.io.files import (
    as_float,
    as_int,
    as_matrix,
    as_vector,
    check_writable,
    get_key,
    read_toml,
)
from lhgraph.io.stations import Station, Stations, save_stations
from lhgraph.io.trajectory import Trajectory, save_trajectory
from lhgraph.model.board import Board, save_board
from lhgraph.model.boards import board_by_name
from lhgraph.model.lh1 import (
    CALIBRATION_KEYS,
    FactoryCalibration,
    StationModel,
    ideal_angles,
    sweep_angle,
)
from lhgraph.signal.pulses import LightPulses
from lhgraph.sim.layout import ParametricLayout, Scene, parametric_scene, scene_from_poses
from lhgraph.sim.motion import PATTERNS, Motion, facing_rotation, make_motion

ROTOR_PERIOD_S = 1.0 / 60.0  # T: one rotor turn, 800000 ticks of 48 MHz
SLOT_S = ROTOR_PERIOD_S / 2  # one sync flash per station per slot
STATION_CLOCK_HZ = 48e6
SYNC_SPACING_S = 20000 / STATION_CLOCK_HZ  # between consecutive stations' sync flashes
CLOCK_PPM_RANGE = 30.0  # random station-vs-board clock offset: uniform in +-30 ppm
BEAM_WIDTH_M = 6e-3  # laser line width at the rotor...
BEAM_DIVERGENCE_RAD = 1.8e-3  # ...growing with distance: ~10 us pulses at 3 m
TRAJECTORY_RATE_HZ = 1000.0  # truth trajectory samples
DEFAULT_CONFIG = "default_simulation.toml"


# --- configuration -------------------------------------------------------------------------


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
    """Angle noise (Gaussian, rad), reflections (replaced hits, offset deg) and dropouts."""

    angle_sigma_rad: float = 0.0
    reflection_fraction: float = 0.0
    reflection_offset_deg: tuple[float, float] = (1.0, 20.0)
    dropout_fraction: float = 0.0


@dataclass(frozen=True)
class VisibilityConfig:
    """When a diode sees a sweep: incidence, field of view and the sweep window."""

    max_incidence_deg: float = 75.0
    fov_deg: float = 60.0
    window_ms: tuple[float, float] = (1.2, 6.7)


@dataclass(frozen=True)
class SimulationConfig:
    """Everything :func:`simulate` needs (schema in docs/simulator.md).

    ``board`` is a built-in board name or a board TOML path (relative to ``base_dir``);
    ``stations`` (site-frame ``T_site_lh`` poses as ``(x, y, z, qw, qx, qy, qz)`` rows)
    replaces ``layout`` when given;
    ``station_models`` maps station index -> factory calibration and rotor offsets;
    ``first_station`` None = drawn at random; ``clock_ppm`` = how much longer the stations'
    rotor period is on the board's clock (ppm), None = drawn at random in +-30 ppm.
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

    @property
    def n_stations(self) -> int:
        """Number of stations simulated."""
        return 2 if self.stations is None else len(self.stations)


class _Table:
    """A config table whose keys are checked: unknown keys and bad values raise InputError."""

    def __init__(self, data: Any, source: str | Path, where: str):
        if not isinstance(data, dict):
            raise InputError("expected a table", source, where or None)
        self.data, self.source, self.where = data, source, where
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.where}.{name}" if self.where else name

    def get(self, name: str, default: Any) -> Any:
        self.used.add(name)
        return self.data.get(name, default)

    def number(self, name: str, default: float, low: float | None = None,
               high: float | None = None, strict_low: bool = False) -> float:
        value = self.get(name, default)
        value = as_float(value, self.source, self.key(name))
        if low is not None and (value < low or (strict_low and value == low)):
            raise InputError(f"must be {'>' if strict_low else '>='} {low:g}, got {value:g}",
                             self.source, self.key(name))
        if high is not None and value > high:
            raise InputError(f"must be <= {high:g}, got {value:g}", self.source, self.key(name))
        return value

    def vector(self, name: str, default: Any, n: int) -> tuple[float, ...] | None:
        value = self.get(name, default)
        if value is None or isinstance(value, tuple):
            return value
        return tuple(float(x) for x in as_vector(value, n, self.source, self.key(name)))

    def table(self, name: str) -> _Table:
        return _Table(self.get(name, {}), self.source, self.key(name))

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise InputError(f"unknown key '{unknown[0]}'", self.source, self.key(unknown[0]))


def _parse_layout(t: _Table) -> ParametricLayout:
    d = ParametricLayout()
    yaw = t.get("relative_yaw_deg", None)
    pitch = t.vector("pitch_deg", None, 2)
    layout = ParametricLayout(
        baseline_m=t.number("baseline_m", d.baseline_m, 0.0, strict_low=True),
        distance_m=t.number("distance_m", d.distance_m, 0.0, strict_low=True),
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
        t = _Table(item, source, f"stations[{i}]")
        position = as_vector(t.get("position", None), 3, source, t.key("position"))
        q = as_vector(t.get("quaternion", None), 4, source, t.key("quaternion"))
        if not 0.9 < np.linalg.norm(q) < 1.1:
            raise InputError("quaternion norm is not ~1", source, t.key("quaternion"))
        t.finish()
        poses.append(tuple(float(x) for x in np.r_[position, q / np.linalg.norm(q)]))
    return tuple(poses)


def _parse_factory(value: Any, source: str | Path, n_stations: int) -> dict[int, StationModel]:
    models = {}
    for name, item in _Table(value, source, "factory").data.items():
        where = f"factory.{name}"
        try:
            index = int(name)
        except ValueError:
            raise InputError("station index must be an integer", source, where) from None
        if not 0 <= index < n_stations:
            raise InputError(f"no station {index} (stations 0..{n_stations - 1})", source, where)
        t = _Table(item, source, where)
        values = {k: as_vector(t.get(k, [0.0, 0.0]), 2, source, t.key(k))
                  for k in CALIBRATION_KEYS}
        offsets = as_matrix(t.get("rotor_offsets", [[0.0] * 3] * 2), 2, 3, source,
                            t.key("rotor_offsets"))
        t.finish()
        models[index] = StationModel(FactoryCalibration(**values), offsets)
    return models


def parse_simulation_config(data: dict[str, Any], source: str | Path,
                            base_dir: str | Path | None = None) -> SimulationConfig:
    """Validate a parsed simulation TOML document; errors name ``source`` and the key."""
    top = _Table(data, source, "")
    d = SimulationConfig()
    duration = top.number("duration_s", d.duration_s, 0.1)
    fs = top.number("sample_rate_hz", d.sample_rate_hz, 1e5)
    board = top.get("board", d.board)
    if not isinstance(board, str):
        raise InputError(f"expected a board name or path, got {board!r}", source, "board")
    board_by_name(board, base_dir, source, "board")
    seed = as_int(top.get("seed", d.seed), source, "seed")

    stations = None
    if "stations" in data:
        if "layout" in data:
            raise InputError("give either [layout] or [[stations]], not both", source, "layout")
        stations = _parse_stations(top.get("stations", None), source)
        layout = d.layout
    else:
        layout = _parse_layout(top.table("layout"))
    n_stations = 2 if stations is None else len(stations)

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
        speed_mps=m.number("speed_mps", MotionConfig.speed_mps, 0.0, 10.0),
        amplitude_m=amplitude,
        rotation_amplitude_deg=m.number("rotation_amplitude_deg",
                                        MotionConfig.rotation_amplitude_deg, 0.0, 60.0),
        centre_m=centre, up=up)
    m.finish()

    n = top.table("noise")
    offset = n.vector("reflection_offset_deg", NoiseConfig.reflection_offset_deg, 2)
    if not 0 < offset[0] <= offset[1] <= 90:
        raise InputError("expected [low, high] with 0 < low <= high <= 90", source,
                         n.key("reflection_offset_deg"))
    noise = NoiseConfig(
        angle_sigma_rad=n.number("angle_sigma_rad", 0.0, 0.0, 0.1),
        reflection_fraction=n.number("reflection_fraction", 0.0, 0.0, 1.0),
        reflection_offset_deg=offset,
        dropout_fraction=n.number("dropout_fraction", 0.0, 0.0, 1.0))
    n.finish()

    v = top.table("visibility")
    window = v.vector("window_ms", VisibilityConfig.window_ms, 2)
    if not 0 <= window[0] < window[1] <= SLOT_S * 1e3:
        raise InputError(f"expected [start, end] with 0 <= start < end <= {SLOT_S * 1e3:.3f}",
                         source, v.key("window_ms"))
    visibility = VisibilityConfig(
        max_incidence_deg=v.number("max_incidence_deg", 75.0, 0.0, 90.0),
        fov_deg=v.number("fov_deg", 60.0, 0.0, 89.0), window_ms=window)
    v.finish()

    models = _parse_factory(top.get("factory", {}), source, n_stations)
    top.finish()
    return SimulationConfig(duration, fs, board, layout, stations, motion, noise, visibility,
                            models, first_station, clock_ppm, seed,
                            None if base_dir is None else str(base_dir))


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


# --- results ------------------------------------------------------------------------------


@dataclass
class SweepSlots:
    """The sync/sweep schedule, one row per slot k (the global slot counter).

    ``sync_start_sample`` (K, n) = sample at which each station's sync flash starts;
    ``sweeping`` (K,) and ``axis`` (K,) = who sweeps which axis; ``period_samples`` = T in
    samples.
    """

    sync_start_sample: NDArray[np.int64]
    sweeping: NDArray[np.int64]
    axis: NDArray[np.int64]
    period_samples: float

    def __len__(self) -> int:
        return len(self.sweeping)


@dataclass
class SimulatedCapture:
    """A simulated capture and its truth.

    ``angles`` has the contract columns plus ``extra["sweep"]`` (slot k of each hit);
    ``reflected`` (len(angles),) marks rows that come from a reflection (gross outliers);
    ``motion`` is the exact board motion (``trajectory`` samples it every 1 ms);
    ``n_samples`` is the capture length in samples.
    """

    angles: Angles
    board: Board
    truth: Stations
    trajectory: Trajectory
    pulses: LightPulses
    slots: SweepSlots
    config: SimulationConfig
    reflected: NDArray[np.bool_]
    motion: Motion
    n_samples: int

    def summary(self) -> str:
        """One line: hits per station and duration."""
        counts = ", ".join(f"station {k}: {int(np.sum(self.angles.lighthouse == k))}"
                           for k in self.truth.indices())
        return (f"{len(self.angles)} hits ({counts}) in {self.config.duration_s:g} s, "
                f"{len(self.slots)} sweeps")


# --- simulation ---------------------------------------------------------------------------


def scene_of(config: SimulationConfig) -> Scene:
    """Stations and motion centre of ``config`` in station 0's frame."""
    if config.stations is None:
        return parametric_scene(config.layout)
    rows = np.asarray(config.stations, dtype=float)
    return scene_from_poses(pose_from_quat(rows[:, :3], rows[:, 3:]), config.motion.centre_m,
                            config.motion.up)


def schedule(n_stations: int, duration_s: float, fs: float, first_station: int,
             phase: int, t0_s: float, period_s: float = ROTOR_PERIOD_S,
             ) -> tuple[SweepSlots, NDArray[np.float64]]:
    """The slot schedule of a capture and the true sync start times (K, n) (s).

    ``period_s`` is the rotor period T on the board's clock. Slot k starts at
    ``t0_s + k T/2``; station ``first_station`` flashes first and the others follow
    ``SYNC_SPACING_S`` (scaled like T) apart in index order (cyclically). Slot k is swept by
    station ``((k + phase) // 2) % n`` on axis ``(k + phase) % 2``, so every station/axis is
    swept once every ``n`` rotor periods (30 Hz with two stations).
    """
    scale = period_s / ROTOR_PERIOD_S
    K = int(np.ceil((duration_s - t0_s) / (SLOT_S * scale)))
    k = np.arange(K)
    order = (np.arange(n_stations) - first_station) % n_stations
    sync_s = t0_s + (k[:, None] * SLOT_S + order[None, :] * SYNC_SPACING_S) * scale
    slots = SweepSlots(np.ceil(sync_s * fs).astype(np.int64), ((k + phase) // 2) % n_stations,
                       (k + phase) % 2, period_s * fs)
    return slots, sync_s


def _station_angles(p_lh: NDArray, station: NDArray, axis: NDArray,
                    models: list[StationModel]) -> NDArray:
    """Measured sweep angles of station-frame points, each with its own station's model."""
    angle = np.empty(len(p_lh))
    for s, model in enumerate(models):
        sel = station == s
        angle[sel] = sweep_angle(p_lh[sel], axis[sel], model)
    return angle


def solve_hit_times(motion: Motion, T_world_lh: NDArray, models: list[StationModel],
                    s_board: NDArray, t_sync: NDArray, station: NDArray, axis: NDArray,
                    period_s: float = ROTOR_PERIOD_S, tol_s: float = 1e-12,
                    ) -> tuple[NDArray, NDArray, NDArray]:
    """Times at which each sweeping plane passes a moving diode (fixed-point iteration).

    For candidate hits (sensor ``s_board`` (N, 3) board frame, sweeping ``station`` and
    ``axis``, sync start ``t_sync`` (s)) solve ``t = t_sync + T/4 + angle(p_lh(t)) T / 2pi``
    on the exact motion. Returns ``t`` (N,), ``T_world_board`` (N, 4, 4) at ``t`` and the
    station-frame positions (N, 3). Contraction factor ~ (speed / distance) T / 2pi << 1.
    """
    T_lh_world = inverse(T_world_lh)[station]
    t = t_sync + period_s / 4
    for _ in range(20):
        T_world_board = motion.pose(t)
        p_lh = transform_points(T_lh_world, transform_points(T_world_board, s_board))
        angle = _station_angles(p_lh, station, axis, models)
        t_new = t_sync + period_s / 4 + angle * period_s / (2 * np.pi)
        converged = np.max(np.abs(t_new - t), initial=0.0) < tol_s
        t = t_new
        if converged:
            break
    T_world_board = motion.pose(t)
    p_lh = transform_points(T_lh_world, transform_points(T_world_board, s_board))
    return t, T_world_board, p_lh


def pulse_width_s(distance_m: NDArray) -> NDArray:
    """Laser pulse duration (s) at ``distance_m`` from the rotor.

    The beam line has width ``BEAM_WIDTH_M + BEAM_DIVERGENCE_RAD * r`` and sweeps past at
    ``r 2 pi / T``: ~21 us at 1 m, ~10 us at 3 m, ~7 us at 6 m.
    """
    r = np.maximum(distance_m, 0.05)
    return (BEAM_WIDTH_M + BEAM_DIVERGENCE_RAD * r) / (r * 2 * np.pi / ROTOR_PERIOD_S)


def simulate(config: SimulationConfig, seed: int | None = None) -> SimulatedCapture:
    """Simulate a capture of ``config`` (``seed`` overrides ``config.seed``)."""
    rng = np.random.default_rng(config.seed if seed is None else seed)
    config = config if seed is None else replace(config, seed=seed)
    fs = config.sample_rate_hz
    board = board_by_name(config.board, config.base_dir)
    scene = scene_of(config)
    n = len(scene.T_world_lh)
    models = [config.station_models.get(i, StationModel()) for i in range(n)]

    mc = config.motion
    R_mean = facing_rotation(scene.centre, scene.T_world_lh[:, :3, 3], scene.up)
    motion = make_motion(mc.pattern, mc.speed_mps, scene.centre, R_mean, mc.amplitude_m,
                         np.radians(mc.rotation_amplitude_deg), config.duration_s, rng)

    first = int(rng.integers(n)) if config.first_station is None else config.first_station
    phase = int(rng.integers(2 * n))
    ppm = config.clock_ppm
    ppm = float(rng.uniform(-CLOCK_PPM_RANGE, CLOCK_PPM_RANGE)) if ppm is None else ppm
    period_s = ROTOR_PERIOD_S * (1 + ppm * 1e-6)
    slots, sync_s = schedule(n, config.duration_s, fs, first, phase,
                             float(rng.uniform(0.0, SLOT_S)), period_s)

    # every (slot, sensor) pair is a candidate hit; keep those the diode really sees
    S = len(board.ids)
    k = np.repeat(np.arange(len(slots)), S)
    row = np.tile(np.arange(S), len(slots))
    station, axis = slots.sweeping[k], slots.axis[k]
    t_sync = sync_s[k, station]
    t, T_world_board, p_lh = solve_hit_times(motion, scene.T_world_lh, models,
                                             board.positions[row], t_sync, station, axis,
                                             period_s)
    keep = _visible(config.visibility, scene, board, row, station, t - t_sync,
                    T_world_board, p_lh)
    keep &= rng.random(len(keep)) >= config.noise.dropout_fraction
    k, row, station, axis, t, t_sync = (x[keep] for x in (k, row, station, axis, t, t_sync))

    t, reflected = _timing_noise(config, t, t_sync, period_s, rng)
    half = pulse_width_s(np.linalg.norm(p_lh[keep], axis=1)) / 2
    start = np.ceil((t - half) * fs).astype(np.int64)
    end = np.maximum(np.ceil((t + half) * fs).astype(np.int64), start + 1)
    n_samples = int(round(config.duration_s * fs))
    # drop pulses running past the end of the capture; order rows by decoded time
    ok = np.flatnonzero(end <= n_samples)
    ok = ok[np.lexsort((board.ids[row[ok]], start[ok] + end[ok]))]
    k, row, station, axis, start, end, reflected = (
        x[ok] for x in (k, row, station, axis, start, end, reflected))

    # decode exactly as from a capture: pulse centre vs the sweeping station's sync start
    centre = (start + end) / 2
    Ts = slots.period_samples
    angle = (centre - slots.sync_start_sample[k, station] - Ts / 4) * 2 * np.pi / Ts
    angles = Angles(centre / fs, station.astype(np.int64), axis.astype(np.int64),
                    board.ids[row], angle, {"sweep": k.astype(np.int64)})
    kind = np.where(reflected, LightPulses.REFLECTION, LightPulses.SWEEP).astype(np.int64)
    pulses = LightPulses(board.ids[row], start, end, kind)

    t_traj = np.arange(int(config.duration_s * TRAJECTORY_RATE_HZ) + 1) / TRAJECTORY_RATE_HZ
    extra = {"simulation": {"seed": int(config.seed), "first_station": first,
                            "clock_ppm": ppm, "rotor_period_s": period_s,
                            "up": [float(x) for x in scene.up]}}
    truth = Stations(0, {i: Station(scene.T_world_lh[i], None, models[i]) for i in range(n)},
                     extra)
    return SimulatedCapture(angles, board, truth, Trajectory(t_traj, motion.pose(t_traj)),
                            pulses, slots, config, reflected, motion, n_samples)


def _timing_noise(config: SimulationConfig, t: NDArray, t_sync: NDArray, period_s: float,
                  rng: np.random.Generator) -> tuple[NDArray, NDArray[np.bool_]]:
    """Hit times with Gaussian angle noise and reflections, and the reflection mask.

    A reflection replaces the direct hit by one offset by ``reflection_offset_deg`` (random
    sign, flipped when that keeps it inside the sweep window).
    """
    noise = config.noise
    rad_to_s = period_s / (2 * np.pi)
    t = t + rng.normal(0.0, noise.angle_sigma_rad, len(t)) * rad_to_s
    reflected = rng.random(len(t)) < noise.reflection_fraction
    lo, hi = np.radians(noise.reflection_offset_deg)
    offset = rng.uniform(lo, hi, len(t)) * rng.choice([-1.0, 1.0], len(t)) * rad_to_s
    w0, w1 = np.asarray(config.visibility.window_ms) * 1e-3
    inside = (t + offset - t_sync >= w0) & (t + offset - t_sync <= w1)
    return np.where(reflected, t + np.where(inside, offset, -offset), t), reflected


def _visible(vis: VisibilityConfig, scene: Scene, board: Board, row: NDArray, station: NDArray,
             dt_s: NDArray, T_world_board: NDArray, p_lh: NDArray) -> NDArray[np.bool_]:
    """Candidate hits a diode really sees: facing, in the field of view, in the window."""
    p_world = transform_points(T_world_board, board.positions[row])
    n_world = np.einsum("nij,nj->ni", T_world_board[:, :3, :3], board.normals[row])
    to_station = scene.T_world_lh[station, :3, 3] - p_world
    cos_inc = np.sum(n_world * to_station, axis=1) / np.linalg.norm(to_station, axis=1)
    ideal = ideal_angles(p_lh)
    w0, w1 = np.asarray(vis.window_ms) * 1e-3
    return ((cos_inc > np.cos(np.radians(vis.max_incidence_deg)))
            & (p_lh[:, 0] > 0)
            & np.all(np.abs(ideal) <= np.radians(vis.fov_deg), axis=1)
            & (dt_s >= w0) & (dt_s <= w1))


# --- files --------------------------------------------------------------------------------

OUTPUT_FILES = {"angles": "angles.csv", "board": "board.toml", "truth": "truth.toml",
                "trajectory": "trajectory.csv"}


def write_simulation(capture: SimulatedCapture, out_dir: str | Path,
                     overwrite: bool = False) -> dict[str, Path]:
    """Write ``angles.csv``, ``board.toml``, ``truth.toml``, ``trajectory.csv`` to ``out_dir``.

    Checks every target first, so either all files are written or none (InputError when one
    exists and ``overwrite`` is false).
    """
    out_dir = Path(out_dir)
    paths = {key: out_dir / name for key, name in OUTPUT_FILES.items()}
    for path in paths.values():
        check_writable(path, overwrite)
    save_angles(capture.angles, paths["angles"], overwrite)
    save_board(capture.board, paths["board"], overwrite)
    save_stations(capture.truth, paths["truth"], overwrite)
    save_trajectory(capture.trajectory, paths["trajectory"], overwrite)
    return paths


def paper_protocol(path: str | Path) -> list[tuple[str, SimulationConfig]]:
    """Expand the paper's simulation protocol file into named configs ("setup03/meas2").

    The file has a ``[base]`` simulation config shared by all measurements and
    ``[[setups]]`` (``name`` and ``[layout]`` keys except ``distance_m``) each with
    ``[[setups.measurements]]`` (``distance_m``, ``pattern``, ``speed_mps``, ``seed``).
    """
    path = Path(path)
    data = read_toml(path)
    top = _Table(data, path, "")
    base = top.get("base", {})
    _Table(base, path, "base")
    setups = top.get("setups", None)
    top.finish()
    if not isinstance(setups, list) or not setups:
        raise InputError("expected [[setups]] tables", path, "setups")
    out = []
    for i, setup in enumerate(setups):
        s = _Table(setup, path, f"setups[{i}]")
        name = s.get("name", f"setup{i + 1:02d}")
        measurements = s.get("measurements", None)
        layout = {key: value for key, value in setup.items()
                  if key not in ("name", "measurements")}
        if not isinstance(measurements, list) or not measurements:
            raise InputError("expected [[setups.measurements]] tables", path,
                             s.key("measurements"))
        for j, meas in enumerate(measurements):
            m = _Table(meas, path, s.key(f"measurements[{j}]"))
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
