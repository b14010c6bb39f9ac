"""What the LH1 and LH2 simulators share (:mod:`lhgraph.sim.simulate`, :mod:`lhgraph.sim.lh2`):
the simulated capture and its truth (:class:`SimulatedCapture`), the seeded setting (board,
scene, motion), the time a rotating light plane crosses a moving diode, the timing noise and
reflections, the facing test and the truth files' content.

World frame = station 0's frame. Times in s, angles in rad, lengths in m.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from lhgraph.geometry.transforms import inverse, pose_from_quat, transform_points
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Station, Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.boards import board_by_name
from lhgraph.model.station import StationModel, sweep_angle
from lhgraph.signal.pulses import LightPulses
from lhgraph.sim.config import ROTOR_PERIOD_S, SimulationConfig, VisibilityConfig
from lhgraph.sim.imu import ImuConfig, SimulatedImu, imu_of_motion
from lhgraph.sim.layout import Scene, parametric_scene, scene_from_poses
from lhgraph.sim.motion import Motion, facing_rotation, make_motion

CLOCK_PPM_RANGE = 30.0  # random station-vs-board clock offset: uniform in +-30 ppm
TRAJECTORY_RATE_HZ = 1000.0  # truth trajectory samples
IMU_STREAM = 7
"""The IMU's random stream is seeded by (seed, IMU_STREAM): the light's draws do not change."""


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


def scene_of(config: SimulationConfig) -> Scene:
    """Stations and motion centre of ``config`` in station 0's frame."""
    if config.stations is None:
        return parametric_scene(config.layout)
    rows = np.asarray(config.stations, dtype=float)
    return scene_from_poses(pose_from_quat(rows[:, :3], rows[:, 3:]), config.motion.centre_m,
                            config.motion.up)


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


def timing_noise(config: SimulationConfig, t: NDArray, period_s: float | NDArray,
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


def facing(vis: VisibilityConfig, scene: Scene, board: Board, row: NDArray, station: NDArray,
            T_world_board: NDArray, p_lh: NDArray) -> NDArray[np.bool_]:
    """Candidate hits whose diode faces the station (incidence below ``max_incidence_deg``)
    and that are in front of it (x > 0)."""
    p_world = transform_points(T_world_board, board.positions[row])
    n_world = np.einsum("nij,nj->ni", T_world_board[:, :3, :3], board.normals[row])
    to_station = scene.T_world_lh[station, :3, 3] - p_world
    cos_inc = np.sum(n_world * to_station, axis=1) / np.linalg.norm(to_station, axis=1)
    return (cos_inc > np.cos(np.radians(vis.max_incidence_deg))) & (p_lh[:, 0] > 0)


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


def simulate_imu(capture: SimulatedCapture, config: ImuConfig | None = None, seed: int = 0
                 ) -> SimulatedImu:
    """The IMU stream of ``capture``'s board over its duration, with noise and biases from
    ``config`` (default :class:`ImuConfig`) drawn by ``seed``."""
    return imu_of_motion(capture.motion, capture.truth.extra["simulation"]["up"],
                         capture.config.duration_s, config or ImuConfig(),
                         np.random.default_rng(seed))
