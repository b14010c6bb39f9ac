"""A simulated IMU on the board of a simulated capture: :func:`simulate_imu`.

Sampled from the capture's exact motion (:class:`lhgraph.sim.motion.Motion`) at the board
origin, in the board frame: the gyro reads the body angular rate, the accelerometer the
specific force ``R^T (a - g)`` (+9.80665 m/s^2 along the scene's up at rest), each plus a
constant bias drawn once per stream and white noise per sample. The default noise is of
the order of a small MEMS part's at 100 Hz, such as the Crazyflie 2.1's BMI088 (gyro
~0.1 deg/s, accelerometer ~0.02 m/s^2 per sample); the biases are drawn with standard
deviations 0.005 rad/s and 0.05 m/s^2. No bias random walk, no scale error, no lever arm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.config import check_fields, option
from lhgraph.estimation.inertial import STANDARD_GRAVITY
from lhgraph.geometry.transforms import so3_log
from lhgraph.io.imu import ImuStream
from lhgraph.sim.simulate import SimulatedCapture

Array = NDArray[np.float64]
DIFF_STEP_S = 1e-4
"""Central-difference step on the analytic motion (its errors are ~1e-8 of the signal)."""


@dataclass(frozen=True)
class ImuSimOptions:
    """Sample rate (Hz), white noise per sample and the standard deviations of the constant
    biases (gyro rad/s, accelerometer m/s^2)."""

    rate_hz: float = option(100.0, gt=0)
    gyro_sigma_rad_s: float = option(2e-3, ge=0)
    accel_sigma_mps2: float = option(0.02, ge=0)
    gyro_bias_sigma_rad_s: float = option(5e-3, ge=0)
    accel_bias_sigma_mps2: float = option(0.05, ge=0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SimulatedImu:
    """A simulated IMU ``stream`` and its truth: the ``bias`` ``[gyro, accelerometer]`` (6,)
    and the ``gravity`` vector (3,) m/s^2 in the capture's world."""

    stream: ImuStream
    bias: Array
    gravity: Array


def simulate_imu(capture: SimulatedCapture, options: ImuSimOptions | None = None,
                 seed: int = 0) -> SimulatedImu:
    """The IMU stream of ``capture``'s board over its duration (times on the capture's
    clock, the hits' clock), with noise and biases from ``options`` drawn by ``seed``."""
    options = options or ImuSimOptions()
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, capture.config.duration_s, 1.0 / options.rate_hz)
    h = DIFF_STEP_S
    before, now, after = (capture.motion.pose(t + d) for d in (-h, 0.0, h))
    R = now[:, :3, :3]
    rate = so3_log(np.einsum("kji,kjl->kil", before[:, :3, :3], after[:, :3, :3])) / (2 * h)
    accel = (after[:, :3, 3] - 2 * now[:, :3, 3] + before[:, :3, 3]) / h**2
    up = np.asarray(capture.truth.extra["simulation"]["up"], dtype=float)
    gravity = -STANDARD_GRAVITY * up / np.linalg.norm(up)
    force = np.einsum("kji,kj->ki", R, accel - gravity)
    bias = np.concatenate([rng.normal(0, options.gyro_bias_sigma_rad_s, 3),
                           rng.normal(0, options.accel_bias_sigma_mps2, 3)])
    gyro = rate + bias[:3] + rng.normal(0, options.gyro_sigma_rad_s, rate.shape)
    accel_read = force + bias[3:] + rng.normal(0, options.accel_sigma_mps2, force.shape)
    return SimulatedImu(ImuStream(t, accel_read, gyro), bias, gravity)
