"""A simulated IMU on the simulated board: :func:`imu_of_motion` (a capture's own stream:
:func:`lhgraph.sim.common.simulate_imu`).

Sampled from the capture's exact motion (:class:`lhgraph.sim.motion.Motion`) at the board
origin, in the board frame, on the capture's clock: the gyro reads the body angular rate,
the accelerometer the specific force ``R^T (a - g)`` (+9.80665 m/s^2 along the scene's up
at rest), each plus a bias drawn once per stream that then wanders, and white noise per
sample. The default noise is of the order of a small MEMS part's at 100 Hz, such as the
Crazyflie 2.1's BMI088 (gyro ~0.1 deg/s, accelerometer ~0.02 m/s^2 per sample, i.e.
2e-4 rad/s and 2e-3 m/s^2 per root hertz); the biases are drawn with standard deviations
0.005 rad/s and 0.05 m/s^2 and wander as random walks of 1e-4 rad/s and 1e-3 m/s^2 per
root second (order-of-magnitude values for such a part; the truth's ``bias`` is the
stream's mean). The IMU's position in the board frame (``position_*_m``, the lever arm:
its accelerometer then reads the specific force of that point), a gyro
scale per axis (``gyro_scale_x``/``_y``/``_z``: the gyro reads that times the rate; the hive
tracker's reads ~0.48), a stamp delay (``time_offset_s``: a reading of the motion at T
is stamped T + offset) and a rotation of the IMU's frame (``rotation_x_rad``/``_y``/``_z``)
when asked. A simulation config asks for a stream with an ``[imu]`` table
(:class:`ImuConfig`, docs/simulator.md); ``lhgraph simulate`` then writes ``imu.csv``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.config import check_fields, option
from lhgraph.geometry.transforms import so3_exp, so3_log
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2, ImuStream
from lhgraph.sim.motion import Motion

Array = NDArray[np.float64]
DIFF_STEP_S = 1e-4
"""Central-difference step on the analytic motion (its errors are ~1e-8 of the signal)."""


@dataclass(frozen=True)
class ImuConfig:
    """Sample rate (Hz), white noise per sample, the standard deviations of the constant
    biases (gyro rad/s, accelerometer m/s^2), the gyro's scale per axis, the stamps'
    delay (s: a reading of the motion at T is stamped T + ``time_offset_s``) and the rotation
    vector ``rotation_*_rad`` of the IMU's frame in the board's (the IMU reads ``R^T`` of the
    board-frame rate and force), its position ``position_*_m`` in the board frame (m); the
    biases wander from their drawn start as random walks
    of ``*_bias_walk_*`` per square-root second."""

    rate_hz: float = option(100.0, gt=0, le=10000)
    gyro_sigma_rad_s: float = option(2e-3, ge=0)
    accel_sigma_mps2: float = option(0.02, ge=0)
    gyro_bias_sigma_rad_s: float = option(5e-3, ge=0)
    accel_bias_sigma_mps2: float = option(0.05, ge=0)
    gyro_scale_x: float = option(1.0, gt=0, le=10)
    gyro_scale_y: float = option(1.0, gt=0, le=10)
    gyro_scale_z: float = option(1.0, gt=0, le=10)
    time_offset_s: float = option(0.0, ge=-1, le=1)
    rotation_x_rad: float = option(0.0, ge=-0.5, le=0.5)
    rotation_y_rad: float = option(0.0, ge=-0.5, le=0.5)
    rotation_z_rad: float = option(0.0, ge=-0.5, le=0.5)
    position_x_m: float = option(0.0, ge=-0.5, le=0.5)
    position_y_m: float = option(0.0, ge=-0.5, le=0.5)
    position_z_m: float = option(0.0, ge=-0.5, le=0.5)
    gyro_bias_walk_rad_s_per_sqrt_s: float = option(1e-4, ge=0)
    accel_bias_walk_mps2_per_sqrt_s: float = option(1e-3, ge=0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SimulatedImu:
    """A simulated IMU ``stream`` and its truth: the ``bias`` ``[gyro, accelerometer]`` (6,)
    and the ``gravity`` vector (3,) m/s^2 in the capture's world."""

    stream: ImuStream
    bias: Array
    gravity: Array


def imu_of_motion(motion: Motion, up: ArrayLike, duration_s: float, config: ImuConfig,
                  rng: np.random.Generator) -> SimulatedImu:
    """The IMU stream of a board moving by ``motion`` for ``duration_s`` in a world whose up
    is ``up``, noise and biases from ``config`` drawn by ``rng``."""
    stamp = np.arange(0.0, duration_s, 1.0 / config.rate_hz)
    t = stamp - config.time_offset_s  # the motion's time of each reading
    h = DIFF_STEP_S
    before, now, after = (motion.pose(t + d) for d in (-h, 0.0, h))
    R = now[:, :3, :3]
    rate = so3_log(np.einsum("kji,kjl->kil", before[:, :3, :3], after[:, :3, :3])) / (2 * h)
    p_board = np.array([config.position_x_m, config.position_y_m, config.position_z_m])
    at = [T[:, :3, :3] @ p_board + T[:, :3, 3] for T in (before, now, after)]  # the IMU point
    accel = (at[2] - 2 * at[1] + at[0]) / h**2
    up = np.asarray(up, dtype=float)
    gravity = -STANDARD_GRAVITY_MPS2 * up / np.linalg.norm(up)
    force = np.einsum("kji,kj->ki", R, accel - gravity)
    bias = np.concatenate([rng.normal(0, config.gyro_bias_sigma_rad_s, 3),
                           rng.normal(0, config.accel_bias_sigma_mps2, 3)])
    scale = np.array([config.gyro_scale_x, config.gyro_scale_y, config.gyro_scale_z])
    R = so3_exp([config.rotation_x_rad, config.rotation_y_rad, config.rotation_z_rad])
    walk = np.cumsum(rng.normal(0.0, np.sqrt(1.0 / config.rate_hz), (len(stamp), 6)), axis=0)
    walk *= np.r_[[config.gyro_bias_walk_rad_s_per_sqrt_s] * 3,
                  [config.accel_bias_walk_mps2_per_sqrt_s] * 3]
    gyro = scale * (rate @ R) + bias[:3] + walk[:, :3] \
        + rng.normal(0, config.gyro_sigma_rad_s, rate.shape)
    accel_read = force @ R + bias[3:] + walk[:, 3:] \
        + rng.normal(0, config.accel_sigma_mps2, force.shape)
    return SimulatedImu(ImuStream(stamp, accel_read, gyro), bias + walk.mean(axis=0), gravity)

