"""Capture simulator: Lighthouse v1 sweeps seen by a waved photodiode board (docs/simulator.md);
LH2 (``generation = 2``) is simulated by :mod:`lhgraph.sim.lh2`, which :func:`simulate` calls.

Models the LH1 slot schedule (one axis of one station swept per T/2 slot, every station
flashing a sync in every slot, 20000 ticks of 48 MHz apart), solves each hit time on the
moving board with the full station model, applies visibility, pulse width and 2 MHz
quantisation, and derives the angles exactly as a decoder would from the quantised samples.
World frame = station 0's frame. Times in s, angles in rad, lengths in m.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.angles import Angles, save_angles
from lhgraph.io.files import check_writable
from lhgraph.io.imu import save_imu
from lhgraph.io.stations import save_stations
from lhgraph.io.trajectory import save_trajectory
from lhgraph.model.board import Board, save_board
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.model.station import StationModel, ideal_angles
from lhgraph.signal.pulses import LightPulses
from lhgraph.sim.capture_sim import CAPTURE_FILE, write_simulated_capture
from lhgraph.sim.common import (
    CLOCK_PPM_RANGE,
    SimulatedCapture,
    SweepSlots,
    facing,
    scene_of,
    setting,
    simulate_imu,
    solve_crossing_times,
    timing_noise,
    truth_and_imu,
)
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
from lhgraph.sim.layout import Scene
from lhgraph.sim.lh2 import simulate_lh2
from lhgraph.sim.motion import Motion

# the simulator's entry point: the configuration API (lhgraph.sim.config) and the capture
# it gives (lhgraph.sim.common) are part of it
__all__ = ["SimulatedCapture", "SimulationConfig", "SweepSlots", "default_simulation_config",
           "load_simulation_config", "paper_protocol", "parse_simulation_config",
           "pulse_width_s", "scene_of", "schedule", "simulate", "simulate_imu",
           "solve_crossing_times", "solve_hit_times", "write_simulation"]

STATION_CLOCK_HZ = 48e6
SYNC_SPACING_S = 20000 / STATION_CLOCK_HZ  # between consecutive stations' sync flashes
BEAM_WIDTH_M = 6e-3  # laser line width at the rotor...
BEAM_DIVERGENCE_RAD = 1.8e-3  # ...growing with distance: ~10 us pulses at 3 m

# --- simulation ---------------------------------------------------------------------------


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
    t, reflected = timing_noise(config, t, period_s, rng, t_sync, window)
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


def _rotor_jitter(sigma_s: float, duration_s: float, n_stations: int, period_s: float,
                  rng: np.random.Generator) -> NDArray[np.float64] | None:
    """White slot-timing jitter (K, n) of rms ``sigma_s`` for every slot a capture of
    ``duration_s`` can hold (None when ``sigma_s`` is 0: no draw, so captures without jitter
    are the same as before the option existed)."""
    if sigma_s <= 0:
        return None
    slots = int(np.ceil(duration_s / (period_s / 2))) + 1
    return rng.normal(0.0, sigma_s, (slots, n_stations))


def _visible(vis: VisibilityConfig, scene: Scene, board: Board, row: NDArray, station: NDArray,
             dt_s: NDArray, T_world_board: NDArray, p_lh: NDArray) -> NDArray[np.bool_]:
    """Candidate LH1 hits a diode really sees: facing, in the field of view, in the window."""
    ideal = ideal_angles(p_lh)
    w0, w1 = np.asarray(vis.window_ms) * 1e-3
    return (facing(vis, scene, board, row, station, T_world_board, p_lh)
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
