"""Capture simulator: Lighthouse v1 sweeps seen by a waved photodiode board (docs/simulator.md);
LH2 (``generation = 2``) is simulated by :mod:`lhgraph.sim.lh2`, which :func:`simulate` calls.

Models the LH1 slot schedule (one axis of one station swept per T/2 slot, every station
flashing a sync in every slot, 20000 ticks of 48 MHz apart), solves each hit time on the
moving board with the full station model, applies visibility, pulse width and 2 MHz
quantisation, and derives the angles exactly as a decoder would from the quantised samples.
World frame = station 0's frame. Times in s, angles in rad, lengths in m.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import inverse, pose_from_quat, transform_points
from lhgraph.io.angles import Angles, save_angles
from lhgraph.io.files import check_writable
from lhgraph.io.imu import save_imu
from lhgraph.io.stations import Station, Stations, save_stations
from lhgraph.io.trajectory import Trajectory, save_trajectory
from lhgraph.model.board import Board, save_board
from lhgraph.model.boards import board_by_name
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.model.station import StationModel, ideal_angles, sweep_angle
from lhgraph.signal.pulses import LightPulses
from lhgraph.sim.config import (
    ROTOR_PERIOD_S,
    SLOT_S,
    SimulationConfig,
    VisibilityConfig,
    default_simulation_config,
    load_simulation_config,
    paper_protocol,
    parse_simulation_config,
)
from lhgraph.sim.deck_log import log_like_deck
from lhgraph.sim.imu import SimulatedImu, imu_of_motion
from lhgraph.sim.layout import Scene, parametric_scene, scene_from_poses
from lhgraph.sim.motion import Motion, facing_rotation, make_motion

# the configuration API (lhgraph.sim.config) is part of the simulator's entry point
__all__ = ["SimulatedCapture", "SimulationConfig", "SweepSlots", "default_simulation_config",
           "load_simulation_config", "paper_protocol", "parse_simulation_config",
           "pulse_width_s", "scene_of", "schedule", "simulate", "solve_crossing_times",
           "solve_hit_times", "write_simulation"]

STATION_CLOCK_HZ = 48e6
SYNC_SPACING_S = 20000 / STATION_CLOCK_HZ  # between consecutive stations' sync flashes
CLOCK_PPM_RANGE = 30.0  # random station-vs-board clock offset: uniform in +-30 ppm
BEAM_WIDTH_M = 6e-3  # laser line width at the rotor...
BEAM_DIVERGENCE_RAD = 1.8e-3  # ...growing with distance: ~10 us pulses at 3 m
TRAJECTORY_RATE_HZ = 1000.0  # truth trajectory samples
IMU_STREAM = 7
"""The IMU's random stream is seeded by (seed, IMU_STREAM): the light's draws do not change."""


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
    ``n_samples`` is the capture length in samples. ``pulses`` and ``slots`` (the raw
    signal) are None for an LH2 capture (no sync slots, not sampled by the board).
    """

    angles: Angles
    board: Board
    truth: Stations
    trajectory: Trajectory
    pulses: LightPulses | None
    slots: SweepSlots | None
    config: SimulationConfig
    reflected: NDArray[np.bool_]
    motion: Motion
    n_samples: int
    imu: SimulatedImu | None = None

    def summary(self) -> str:
        """One line: hits per station and duration."""
        counts = ", ".join(f"station {k}: {int(np.sum(self.angles.lighthouse == k))}"
                           for k in self.truth.indices())
        if self.slots is not None:
            sweeps = f"{len(self.slots)} sweeps"
        else:  # LH2: the (station, sweep) pairs that hit a diode
            seen = np.unique(np.c_[self.angles.lighthouse, self.angles.extra["sweep"]], axis=0)
            sweeps = f"LH2, {len(seen)} sweeps seen"
        return f"{len(self.angles)} hits ({counts}) in {self.config.duration_s:g} s, {sweeps}"


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
             jitter_s: NDArray[np.float64] | None = None,
             ) -> tuple[SweepSlots, NDArray[np.float64]]:
    """The slot schedule of a capture and the true sync start times (K, n) (s).

    ``period_s`` is the rotor period T on the board's clock. Slot k starts at
    ``t0_s + k T/2``; station ``first_station`` flashes first and the others follow
    ``SYNC_SPACING_S`` (scaled like T) apart in index order (cyclically). Slot k is swept by
    station ``((k + phase) // 2) % n`` on axis ``(k + phase) % 2``, so every station/axis is
    swept once every ``n`` rotor periods (30 Hz with two stations). ``jitter_s`` (K, n), if
    given, is added to every station's sync start of every slot: the station's timing
    jitter, which the sweep of that slot shares (its hits are timed from this sync start).
    """
    scale = period_s / ROTOR_PERIOD_S
    K = int(np.ceil((duration_s - t0_s) / (SLOT_S * scale)))
    k = np.arange(K)
    order = (np.arange(n_stations) - first_station) % n_stations
    sync_s = t0_s + (k[:, None] * SLOT_S + order[None, :] * SYNC_SPACING_S) * scale
    if jitter_s is not None:
        sync_s = sync_s + jitter_s[:K]
    slots = SweepSlots(np.ceil(sync_s * fs).astype(np.int64), ((k + phase) // 2) % n_stations,
                       (k + phase) % 2, period_s * fs)
    return slots, sync_s


def setting(config: SimulationConfig, seed: int | None
            ) -> tuple[SimulationConfig, np.random.Generator, Board, Scene, Motion]:
    """What both generations' simulations start from: ``config`` with ``seed`` (overriding
    ``config.seed``), the random generator, the board, the scene and the board's motion
    (the motion's draws come first from the generator)."""
    rng = np.random.default_rng(config.seed if seed is None else seed)
    config = config if seed is None else replace(config, seed=seed)
    board = board_by_name(config.board, config.base_dir)
    scene = scene_of(config)
    mc = config.motion
    R_mean = facing_rotation(scene.centre, scene.T_world_lh[:, :3, 3], scene.up)
    motion = make_motion(mc.pattern, mc.speed_mps, scene.centre, R_mean, mc.amplitude_m,
                         np.radians(mc.rotation_amplitude_deg), config.duration_s, rng)
    return config, rng, board, scene, motion


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
    """Times at which each sweeping LH1 plane passes a moving diode.

    For candidate hits (sensor ``s_board`` (N, 3) board frame, sweeping ``station`` and
    ``axis``, sync start ``t_sync`` (s)) solve ``t = t_sync + T/4 + angle(p_lh(t)) T / 2pi``
    (:func:`solve_crossing_times` with the plane at angle 0 a quarter turn after the sync).
    """
    return solve_crossing_times(motion, T_world_lh, models, s_board, t_sync + period_s / 4,
                                station, axis, period_s, tol_s)


def solve_crossing_times(motion: Motion, T_world_lh: NDArray, models: list[StationModel],
                         s_board: NDArray, t_zero: NDArray, station: NDArray, axis: NDArray,
                         period_s: float | NDArray = ROTOR_PERIOD_S, tol_s: float = 1e-12,
                         ) -> tuple[NDArray, NDArray, NDArray]:
    """Times at which rotating light planes pass moving diodes (fixed-point iteration).

    For candidate hits (sensor ``s_board`` (N, 3) board frame, ``station`` and ``axis``,
    ``t_zero`` (s) the time the plane is at measured angle 0, ``period_s`` the rotor period,
    scalar or (N,)) solve ``t = t_zero + angle(p_lh(t)) T / 2pi`` on the exact motion, with
    ``angle`` the station's model (:func:`lhgraph.model.station.sweep_angle`). Returns ``t``
    (N,), ``T_world_board`` (N, 4, 4) at ``t`` and the station-frame positions (N, 3).
    Contraction factor ~ (speed / distance) T / 2pi << 1.
    """
    T_lh_world = inverse(T_world_lh)[station]
    t = t_zero
    for _ in range(20):
        T_world_board = motion.pose(t)
        p_lh = transform_points(T_lh_world, transform_points(T_world_board, s_board))
        angle = _station_angles(p_lh, station, axis, models)
        t_new = t_zero + angle * period_s / (2 * np.pi)
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
    """Simulate a capture of ``config`` (``seed`` overrides ``config.seed``): LH1 slots here,
    LH2 rotors (``config.generation == 2``) by :func:`lhgraph.sim.lh2.simulate_lh2`."""
    if config.generation == 2:
        from lhgraph.sim.lh2 import simulate_lh2

        return simulate_lh2(config, seed)
    config, rng, board, scene, motion = setting(config, seed)
    fs = config.sample_rate_hz
    n = len(scene.T_world_lh)
    models = [config.station_models.get(i, StationModel()) for i in range(n)]

    first = int(rng.integers(n)) if config.first_station is None else config.first_station
    phase = int(rng.integers(2 * n))
    ppm = config.clock_ppm
    ppm = float(rng.uniform(-CLOCK_PPM_RANGE, CLOCK_PPM_RANGE)) if ppm is None else ppm
    period_s = ROTOR_PERIOD_S * (1 + ppm * 1e-6)
    t0_s = float(rng.uniform(0.0, SLOT_S))
    jitter = config.noise.rotor_jitter_us * 1e-6
    slots, sync_s = schedule(n, config.duration_s, fs, first, phase, t0_s, period_s,
                             _rotor_jitter(jitter, config.duration_s, n, period_s, rng))

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

    window = np.asarray(config.visibility.window_ms) * 1e-3
    t, reflected = _timing_noise(config, t, period_s, rng, t_sync, window)
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
    time = centre / fs
    if config.logging.timestamps == "deck":  # the deck's log: cycles kept, stamped together
        kept, time = log_like_deck(config.logging, k, phase, period_s / 2,
                                   board.positions[row, 0], board.ids[row], axis,
                                   sync_s[k, station] + period_s / 4, rng)
        order = np.flatnonzero(kept)[np.argsort(time, kind="stable")]
        time = np.sort(time, kind="stable")
        k, row, station, axis, start, end, reflected, angle = (
            x[order] for x in (k, row, station, axis, start, end, reflected, angle))
    angles = Angles(time, station.astype(np.int64), axis.astype(np.int64),
                    board.ids[row], angle, {"sweep": k.astype(np.int64)})
    kind = np.where(reflected, LightPulses.REFLECTION, LightPulses.SWEEP).astype(np.int64)
    pulses = LightPulses(board.ids[row], start, end, kind)

    truth, trajectory, imu = truth_and_imu(
        config, scene, models, motion,
        {"seed": int(config.seed), "first_station": first, "clock_ppm": ppm,
         "rotor_period_s": period_s, "up": [float(x) for x in scene.up]})
    return SimulatedCapture(angles, board, truth, trajectory, pulses, slots, config, reflected,
                            motion, n_samples, imu)


def truth_and_imu(config: SimulationConfig, scene: Scene, models: list[StationModel],
                  motion: Motion, simulation: dict
                  ) -> tuple[Stations, Trajectory, SimulatedImu | None]:
    """The truth stations (``[simulation]`` table ``simulation``, plus the IMU's bias and
    gravity), the 1 ms truth trajectory and the simulated IMU (``config.imu``; None without)."""
    t_traj = np.arange(int(config.duration_s * TRAJECTORY_RATE_HZ) + 1) / TRAJECTORY_RATE_HZ
    extra = {"simulation": simulation}
    imu = None
    if config.imu is not None:  # its own random stream: the light is the same with or without
        imu = imu_of_motion(motion, scene.up, config.duration_s, config.imu,
                            np.random.default_rng([int(config.seed), IMU_STREAM]))
        extra["simulation"] |= {"imu_bias": [float(x) for x in imu.bias],
                                "gravity": [float(x) for x in imu.gravity]}
    truth = Stations(0, {i: Station(scene.T_world_lh[i], None, models[i])
                         for i in range(len(models))}, extra)
    return truth, Trajectory(t_traj, motion.pose(t_traj)), imu


def _rotor_jitter(sigma_s: float, duration_s: float, n_stations: int, period_s: float,
                  rng: np.random.Generator) -> NDArray[np.float64] | None:
    """White slot-timing jitter (K, n) of rms ``sigma_s`` for every slot a capture of
    ``duration_s`` can hold (None when ``sigma_s`` is 0: no draw, so captures without jitter
    are the same as before the option existed)."""
    if sigma_s <= 0:
        return None
    slots = int(np.ceil(duration_s / (period_s / 2))) + 1
    return rng.normal(0.0, sigma_s, (slots, n_stations))


def _timing_noise(config: SimulationConfig, t: NDArray, period_s: float | NDArray,
                  rng: np.random.Generator, t_sync: NDArray | None = None,
                  window_s: NDArray | None = None) -> tuple[NDArray, NDArray[np.bool_]]:
    """Hit times with Gaussian angle noise and reflections, and the reflection mask.

    A reflection replaces the direct hit by one offset by ``reflection_offset_deg`` (random
    sign; with the LH1 sweep window ``window_s`` = (start, end) after the sweeping station's
    sync start ``t_sync``, flipped when that keeps it inside). ``period_s`` is scalar or per
    hit.
    """
    noise = config.noise
    rad_to_s = period_s / (2 * np.pi)
    t = t + rng.normal(0.0, noise.angle_sigma_rad, len(t)) * rad_to_s
    reflected = rng.random(len(t)) < noise.reflection_fraction
    lo, hi = np.radians(noise.reflection_offset_deg)
    offset = rng.uniform(lo, hi, len(t)) * rng.choice([-1.0, 1.0], len(t)) * rad_to_s
    if window_s is None or t_sync is None:
        return np.where(reflected, t + offset, t), reflected
    w0, w1 = window_s
    inside = (t + offset - t_sync >= w0) & (t + offset - t_sync <= w1)
    return np.where(reflected, t + np.where(inside, offset, -offset), t), reflected


def _facing(vis: VisibilityConfig, scene: Scene, board: Board, row: NDArray, station: NDArray,
            T_world_board: NDArray, p_lh: NDArray) -> NDArray[np.bool_]:
    """Candidate hits whose diode faces the station (incidence below ``max_incidence_deg``)
    and that are in front of it (x > 0)."""
    p_world = transform_points(T_world_board, board.positions[row])
    n_world = np.einsum("nij,nj->ni", T_world_board[:, :3, :3], board.normals[row])
    to_station = scene.T_world_lh[station, :3, 3] - p_world
    cos_inc = np.sum(n_world * to_station, axis=1) / np.linalg.norm(to_station, axis=1)
    return (cos_inc > np.cos(np.radians(vis.max_incidence_deg))) & (p_lh[:, 0] > 0)


def _visible(vis: VisibilityConfig, scene: Scene, board: Board, row: NDArray, station: NDArray,
             dt_s: NDArray, T_world_board: NDArray, p_lh: NDArray) -> NDArray[np.bool_]:
    """Candidate LH1 hits a diode really sees: facing, in the field of view, in the window."""
    ideal = ideal_angles(p_lh)
    w0, w1 = np.asarray(vis.window_ms) * 1e-3
    return (_facing(vis, scene, board, row, station, T_world_board, p_lh)
            & np.all(np.abs(ideal) <= np.radians(vis.fov_deg), axis=1)
            & (dt_s >= w0) & (dt_s <= w1))


# --- files --------------------------------------------------------------------------------

OUTPUT_FILES = {"angles": "angles.csv", "board": "board.toml", "truth": "truth.toml",
                "trajectory": "trajectory.csv"}


def write_simulation(capture: SimulatedCapture, out_dir: str | Path,
                     overwrite: bool = False, raw_capture: bool = False) -> dict[str, Path]:
    """Write ``angles.csv``, ``board.toml``, ``truth.toml``, ``trajectory.csv`` to ``out_dir``
    (with ``raw_capture`` also the raw signal a board would record, ``capture.lhcap``; with
    a simulated IMU its ``imu.csv``; for LH2 stations ``ootx.toml``, what an LH2 receiver
    decodes from them: generation, channel and factory calibration, which the solver needs
    to read the angles as light planes).

    Checks every target first, so either all files are written or none (InputError when one
    exists and ``overwrite`` is false).
    """
    from lhgraph.sim.capture_sim import CAPTURE_FILE, write_simulated_capture

    if raw_capture and capture.config.generation == 2:
        raise InputError("no raw capture of LH2: the board's 2 MHz sampler cannot decode LH2 "
                         "(SPEC §8; ~6 Mbit/s bitstream)", where="--capture")
    out_dir = Path(out_dir)
    paths = {key: out_dir / name for key, name in OUTPUT_FILES.items()}
    if capture.imu is not None:
        paths["imu"] = out_dir / "imu.csv"
    if capture.config.generation == 2:
        paths["ootx"] = out_dir / "ootx.toml"
    for path in [*paths.values(), *([out_dir / CAPTURE_FILE] if raw_capture else [])]:
        check_writable(path, overwrite)
    save_angles(capture.angles, paths["angles"], overwrite)
    save_board(capture.board, paths["board"], overwrite)
    save_stations(capture.truth, paths["truth"], overwrite)
    save_trajectory(capture.trajectory, paths["trajectory"], overwrite)
    if capture.imu is not None:
        save_imu(capture.imu.stream, paths["imu"], overwrite)
    if "ootx" in paths:
        save_calibration({k: StationCalibration(s.model.calibration, 0x2000 + k,
                                                generation=2, channel=s.model.channel)
                          for k, s in capture.truth.stations.items()}, paths["ootx"], overwrite)
    if raw_capture:
        paths["capture"] = write_simulated_capture(capture, out_dir, overwrite)
    return paths
