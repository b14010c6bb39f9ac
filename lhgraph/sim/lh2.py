"""Lighthouse v2 (SteamVR 2.0) angle captures with truth (docs/simulator.md, section LH2).

No raw signal: each station's rotor turns with its channel's period (SPEC §8) and a random
phase, and in every revolution each of its two light planes crosses every diode once. The
crossing time is solved on the moving board with the station's model
(:func:`lhgraph.model.station.sweep_angle`, generation 2) like the LH1 hits
(:func:`lhgraph.sim.common.solve_crossing_times`); visibility, Gaussian angle noise,
reflections, per-hit dropouts and dropped whole sweeps follow. The angles are what an LH2
decoder reports: the rotor angle of the plane at the hit, from the bitstream offset on the
station's time base. Times in s (board clock), angles in rad.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.angles import Angles
from lhgraph.model.board import Board
from lhgraph.model.lh2 import ideal_angles, lh1_equivalent
from lhgraph.model.station import StationModel
from lhgraph.sim.common import (
    CLOCK_PPM_RANGE,
    SimulatedCapture,
    facing,
    setting,
    solve_crossing_times,
    timing_noise,
    truth_and_imu,
)
from lhgraph.sim.config import (
    LH2_MAX_STATIONS,
    SimulationConfig,
    VisibilityConfig,
    lh2_rotor_period_s,
)
from lhgraph.sim.layout import Scene

PLANE_OFFSETS_RAD = np.array([-np.pi / 3, np.pi / 3])
"""Where each plane sits on the rotor: plane i crosses measured angle ``alpha`` at the rotor
time ``(alpha + pi + PLANE_OFFSETS_RAD[i]) T / 2pi`` after the revolution starts (Bitcraze's
decoder: ``angle = offset 2pi / T - pi -+ pi/3``), so a diode on the optical axis is hit by
plane 0 a third of a revolution after the start and by plane 1 a third later."""


def lh2_models(config: SimulationConfig, n: int) -> list[StationModel]:
    """The ``n`` station models of an LH2 config: generation 2, channel ``i + 1`` unless set;
    ValueError for more than 16 stations or two on one channel."""
    if n > LH2_MAX_STATIONS:
        raise ValueError(f"{n} stations: LH2 has {LH2_MAX_STATIONS} channels")
    models = []
    for i in range(n):
        model = config.station_models.get(i, StationModel())
        channel = i + 1 if model.channel is None else model.channel
        models.append(replace(model, generation=2, channel=channel))
    channels = [m.channel for m in models]
    if len(set(channels)) != n:
        raise ValueError(f"LH2 stations need distinct channels, got {channels}")
    return models


def simulate_lh2(config: SimulationConfig, seed: int | None = None) -> SimulatedCapture:
    """Simulate an LH2 capture of ``config`` (``seed`` overrides ``config.seed``).

    ``angles.extra["sweep"]`` counts the plane passes of each station: ``2 m + plane`` in
    revolution ``m`` (0 = the revolution in progress at t = 0), so hits with the same
    ``lighthouse`` and ``sweep`` come from one pass of one plane. ``pulses`` and ``slots`` are
    None (no raw signal).
    """
    config, rng, board, scene, motion = setting(config, seed)
    n = len(scene.T_world_lh)
    models = lh2_models(config, n)
    ppm = config.clock_ppm
    ppm = float(rng.uniform(-CLOCK_PPM_RANGE, CLOCK_PPM_RANGE)) if ppm is None else ppm
    periods = np.array([lh2_rotor_period_s(m.channel) for m in models]) * (1 + ppm * 1e-6)
    start = rng.uniform(0.0, 1.0, n) * periods  # a revolution starts at start + m T

    # candidate sweeps: (station, revolution m >= -1, plane); every diode of each
    sweep_station, sweep_m, sweep_plane = _sweeps(periods, start, config.duration_s)
    dropped = rng.random(len(sweep_station)) < config.noise.sweep_dropout_fraction
    S = len(board.ids)
    k = np.repeat(np.flatnonzero(~dropped), S)
    row = np.tile(np.arange(S), int(np.sum(~dropped)))
    station, plane = sweep_station[k], sweep_plane[k]
    period = periods[station]
    t_zero = (start[station] + sweep_m[k] * period
              + (np.pi + PLANE_OFFSETS_RAD[plane]) * period / (2 * np.pi))
    t, T_world_board, p_lh = solve_crossing_times(motion, scene.T_world_lh, models,
                                                  board.positions[row], t_zero, station, plane,
                                                  period)
    keep = _visible_lh2(config.visibility, scene, board, row, station, T_world_board, p_lh)
    keep &= rng.random(len(keep)) >= config.noise.dropout_fraction
    k, row, station, plane, t, t_zero, period = (
        x[keep] for x in (k, row, station, plane, t, t_zero, period))

    t, reflected = timing_noise(config, t, period, rng)
    ok = (t >= 0) & (t <= config.duration_s)
    ok = np.flatnonzero(ok)[np.lexsort((board.ids[row[ok]], t[ok]))]
    k, row, station, plane, t, t_zero, period, reflected = (
        x[ok] for x in (k, row, station, plane, t, t_zero, period, reflected))
    # the decoder's angle: the plane's rotor angle at the hit, wrapped to [-pi, pi)
    angle = np.mod((t - t_zero) * 2 * np.pi / period + np.pi, 2 * np.pi) - np.pi
    sweep = 2 * (sweep_m[k] + 1) + plane
    angles = Angles(t, station.astype(np.int64), plane.astype(np.int64), board.ids[row], angle,
                    {"sweep": sweep.astype(np.int64)})

    truth, trajectory, imu = truth_and_imu(
        config, scene, models, motion,
        {"seed": int(config.seed), "generation": 2, "clock_ppm": ppm,
         "rotor_periods_s": [float(x) for x in periods],
         "rotor_start_s": [float(x) for x in start],
         "plane_offsets_rad": [float(x) for x in PLANE_OFFSETS_RAD],
         "up": [float(x) for x in scene.up]})
    n_samples = int(round(config.duration_s * config.sample_rate_hz))
    return SimulatedCapture(angles, board, truth, trajectory, None, None, config, reflected,
                            motion, n_samples, imu)


def _sweeps(periods: NDArray, start: NDArray, duration_s: float
            ) -> tuple[NDArray, NDArray, NDArray]:
    """Station, revolution ``m`` (from -1: the one in progress before t = 0 may still hit)
    and plane of every sweep that can fall in ``[0, duration_s]``, station by station."""
    station, m, plane = [], [], []
    for s, (T, t0) in enumerate(zip(periods, start, strict=True)):
        revs = np.arange(-1, int(np.ceil((duration_s - t0) / T)) + 1)
        station.append(np.full(2 * len(revs), s))
        m.append(np.repeat(revs, 2))
        plane.append(np.tile([0, 1], len(revs)))
    return np.concatenate(station), np.concatenate(m), np.concatenate(plane)


def _visible_lh2(vis: VisibilityConfig, scene: Scene, board: Board, row: NDArray, station: NDArray,
                 T_world_board: NDArray, p_lh: NDArray) -> NDArray[np.bool_]:
    """Candidate hits a diode sees: facing the station and inside its field of view,
    ``|azimuth| <= fov_h_deg`` and ``|elevation| <= fov_v_deg`` in LH1-equivalent angles."""
    ideal = ideal_angles(p_lh)
    az, el = lh1_equivalent(ideal[:, 0], ideal[:, 1])
    return (facing(vis, scene, board, row, station, T_world_board, p_lh)
            & (np.abs(az) <= np.radians(vis.fov_h_deg))
            & (np.abs(el) <= np.radians(vis.fov_v_deg)))
