"""The receiver's IMU readings at the graph's board states (gyro and accelerometer factors).

A few-diode receiver (the Crazyflie deck) seen by one station at a time has a weakly
determined tilt and range; its IMU, on the same clock, measures what the light does not:

- **gyro**: at every board state k, the state's angular rate plus the gyro bias equals the
  gyro's reading at ``t_k`` (interpolated between samples within ``max_gap_s``);
- **accelerometer**: over every step k -> k + 1, the change of the world-frame velocity
  ``R v`` divided by the step equals the specific force, rotated into the world, plus
  gravity. The specific force over the step is the accelerometer's reading at the step's
  middle, rotated into state k's frame by half a step of the gyro's rate; the factor's
  noise adds how far that reading is from the mean of the readings within the step
  (:meth:`InertialData.accel_sigmas`) to the options' (:func:`accel_factor_sigma` by
  default).

Residuals and Jacobians: :func:`lhgraph.estimation.residuals.gyro_residuals` and
:func:`~lhgraph.estimation.residuals.accel_residuals`. The IMU is taken at the board origin
and in the board frame (the Crazyflie's IMU frame is the ``crazyflie_deck`` board frame); its
lever arm is neglected (the centripetal acceleration of a few cm at 1-2 rad/s is
0.02-0.2 m/s^2, below the accelerometer noise the factors assume). Unknowns added to the
graph: one IMU bias (gyro, accelerometer) and the gravity vector in the world, whose
magnitude a factor holds near the standard gravity (``GRAVITY_SIGMA_MPS2``: otherwise an
accelerometer bias along the mean up and the magnitude trade off over a short capture).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.estimation.spread import robust_sigma
from lhgraph.geometry.transforms import so3_exp
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2, ImuStream

if TYPE_CHECKING:
    from lhgraph.estimation.init.pnp_kabsch import Initialisation

Array = NDArray[np.float64]
GRAVITY_SIGMA_MPS2 = 0.3
"""How far the gravity's magnitude as the accelerometer reads it may be from the standard
one: the local gravity varies by ~0.05 m/s^2 over the Earth, a MEMS accelerometer's scale
by a few % (the Crazyflie log's reads 9.62 m/s^2 over 120 s): the gravity-magnitude
factor's noise."""


ACCEL_FACTOR_NOISE_RATIO = 4.0
"""The accelerometer factor's noise over its readings' (:func:`accel_factor_sigma`). The
readings' noise is a lower bound: the factor compares one reading, at the step's middle, with
the step's mean acceleration, and a real device adds clock and lever-arm misfit. Measured
(docs/track.md): 2.5 fits the simulated decks best (0.39x the light alone) but on the real
Crazyflie log it pulls the gravity's magnitude to 10.9 m/s^2 over a 15 s track and worsens
measure (b) from 10.0 to 10.4 mm; 4 keeps that log where the fixed 0.5 m/s^2 had it (0.46)."""


def gravity_magnitude_residual(g: Array) -> tuple[Array, Array]:
    """The gravity-magnitude factor's residual ``|g| - STANDARD_GRAVITY_MPS2`` (1,) of the
    gravity vector ``g`` (3,; m/s^2, world) and its Jacobian (1, 3): with the magnitude
    known, an accelerometer bias along the mean up separates from it."""
    norm = float(np.linalg.norm(g))
    return np.array([norm - STANDARD_GRAVITY_MPS2]), (g / max(norm, 1e-9))[None]


def reading_noise(x: Array) -> Array:
    """White-noise standard deviation per column of a sampled signal ``x`` (N, d), from its
    second differences (``e_k-1 - 2 e_k + e_k+1`` has variance ``6 sigma^2``; a smooth
    signal's curvature adds little at an IMU's rate), robustly (MAD): the difference-based
    estimator of the noise of a regression."""
    d2 = x[2:] - 2.0 * x[1:-1] + x[:-2]
    return robust_sigma(d2, axis=0) / np.sqrt(6.0)


def accel_factor_sigma(imu: ImuStream) -> float:
    """Noise (m/s^2) of an accelerometer factor for the stream ``imu``:
    :data:`ACCEL_FACTOR_NOISE_RATIO` times its readings' noise (:func:`reading_noise`, the
    largest axis), which carries the device's vibration. Readings' noise measured: 0.020
    m/s^2 on the simulated default part, 0.07-0.12 on the real Crazyflie log, 0.026-0.039 on
    hive's tracker."""
    return ACCEL_FACTOR_NOISE_RATIO * float(np.max(reading_noise(imu.accel_mps2)))


def gyro_reading_sigma(imu: ImuStream) -> float:
    """Noise (rad/s) of one gyro reading of the stream ``imu``: :func:`reading_noise` of its
    gyro, the largest axis (the preintegrated gyro factors integrate it). Measured: 0.0020
    rad/s on the simulated default part at 1 kHz, 0.0013 on hive's tracker (250 Hz), 0.048 on
    the real Crazyflie log, whose 100 Hz samples carry the hand's motion too."""
    return float(np.max(reading_noise(imu.gyro_rad_s)))


@dataclass(frozen=True)
class InertialData:
    """The IMU readings at a problem's K board states: ``rate`` (K, 3) the gyro at each
    state's time (rad/s, board frame), ``rate_ok`` (K,) where it has samples within the gap;
    ``force`` (K - 1, 3) the specific force over each step in its first state's frame
    (m/s^2), ``force_ok`` (K - 1,) likewise; ``dt`` (K - 1,) the steps (s); ``force_spread``
    (K - 1,) how far the one reading the factor uses (at the step's middle) is from the mean
    of the accelerometer's readings within the step (m/s^2, rms over the axes; 0 with fewer
    than two readings): its error as the step's mean force. ``stream``, ``state_time`` and
    ``half_turn`` (K - 1, 3, 3: each step's middle frame seen from its first state's) let
    :meth:`read_at` sample the stream again at a time offset."""

    rate: Array
    rate_ok: NDArray[np.bool_]
    force: Array
    force_ok: NDArray[np.bool_]
    dt: Array
    stream: ImuStream | None = None
    state_time: Array | None = None
    half_turn: Array | None = None
    force_spread: Array | None = None

    def accel_sigmas(self, sigma_mps2: float) -> Array:
        """Each step's accelerometer-factor noise (K - 1,): ``sigma_mps2`` and the step's
        middle-reading error (``force_spread``) added in quadrature, so a long step (a turn
        no station sees) is not held to one reading."""
        spread = np.zeros(len(self.dt)) if self.force_spread is None else self.force_spread
        return np.sqrt(sigma_mps2**2 + spread**2)

    def read_at(self, offset_s: float) -> tuple[Array, Array, Array, Array]:
        """The gyro at every state and the specific force over every step with the IMU read
        ``offset_s`` later on the light's clock (an IMU stamped ``offset_s`` early), and
        their derivatives with respect to the offset: ``(rate, d rate / d offset, force,
        d force / d offset)``, shapes as :attr:`rate` and :attr:`force` (the derivatives are
        the slopes of the linear interpolation)."""
        t, middle = self.state_time + offset_s, self.state_time[:-1] + self.dt / 2 + offset_s
        rate, rate_slope = _sampled(self.stream.time, self.stream.gyro_rad_s, t)
        force, force_slope = _sampled(self.stream.time, self.stream.accel_mps2, middle)
        turn = self.half_turn
        return (rate, rate_slope, np.einsum("kij,kj->ki", turn, force),
                np.einsum("kij,kj->ki", turn, force_slope))


def _interpolated(t: Array, x: Array, query: Array, max_gap_s: float
                  ) -> tuple[Array, NDArray[np.bool_]]:
    """``x`` (N, 3) sampled at ``t`` interpolated at ``query``, and where both neighbours are
    within ``max_gap_s``."""
    i = np.clip(np.searchsorted(t, query), 1, len(t) - 1)
    ok = ((query >= t[0]) & (query <= t[-1]) & (query - t[i - 1] <= max_gap_s)
          & (t[i] - query <= max_gap_s))
    return _sampled(t, x, query)[0], ok


def _sampled(t: Array, x: Array, query: Array) -> tuple[Array, Array]:
    """``x`` (N, 3) sampled at ``t`` (sorted, N >= 2) interpolated linearly at ``query``
    (held at the ends), and the slope of the segment each query falls in."""
    i = np.clip(np.searchsorted(t, query), 1, len(t) - 1)
    span = np.maximum(t[i] - t[i - 1], 1e-12)
    w = np.clip((query - t[i - 1]) / span, 0.0, 1.0)[:, None]
    slope = (x[i] - x[i - 1]) / span[:, None]
    inside = ((query >= t[0]) & (query <= t[-1]))[:, None]
    return (1 - w) * x[i - 1] + w * x[i], np.where(inside, slope, 0.0)


def inertial_data(imu: ImuStream, state_time: Array, max_gap_s: float = 0.05,
                  source: str = "imu") -> InertialData:
    """:class:`InertialData` of ``imu`` at board states at ``state_time`` (s, sorted, the
    IMU's clock). InputError naming ``source`` if the stream has no gyro or no sample near
    any state."""
    if imu.gyro_rad_s is None:
        raise InputError("the IMU stream has no gyro columns (gx, gy, gz): the graph's IMU "
                         "factors need both the accelerometer and the gyro", source)
    t = imu.time
    state_time = np.asarray(state_time, dtype=float)
    rate, rate_ok = _interpolated(t, imu.gyro_rad_s, state_time, max_gap_s)
    dt = np.diff(state_time)
    middle = state_time[:-1] + dt / 2
    force_mid, force_ok = _interpolated(t, imu.accel_mps2, middle, max_gap_s)
    rate_mid, _ = _interpolated(t, imu.gyro_rad_s, middle, max_gap_s)
    # the frame at the middle seen from state k's: R_k^T R_mid = Exp(omega dt / 2)
    half_turn = so3_exp(rate_mid * (dt / 2)[:, None])
    force = np.einsum("kij,kj->ki", half_turn, force_mid)
    if not rate_ok.any():
        raise InputError(f"no IMU sample within {max_gap_s * 1e3:.0f} ms of any board state "
                         f"(IMU {t[0]:.3f}-{t[-1]:.3f} s, light {state_time[0]:.3f}-"
                         f"{state_time[-1]:.3f} s): not on the light's clock?", source)
    return InertialData(rate, rate_ok, force, force_ok & (dt > 0), dt, imu, state_time,
                        half_turn, _mid_reading_error(t, imu.accel_mps2, state_time, force_mid))


def _mid_reading_error(t: Array, x: Array, edges: Array, mid: Array) -> Array:
    """Per interval ``[edges[k], edges[k+1])``: how far ``mid[k]`` (the samples ``x`` at times
    ``t`` interpolated at the interval's middle) is from the mean of the samples in it, rms
    over the columns (0 with fewer than two samples)."""
    bounds = np.searchsorted(t, edges)
    n = np.diff(bounds)
    csum = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    mean = (csum[bounds[1:]] - csum[bounds[:-1]]) / np.maximum(n, 1)[:, None]
    return np.where(n >= 2, np.sqrt(np.mean((mid - mean) ** 2, axis=1)), 0.0)


def initial_gravity(data: InertialData, T_world_board: Array) -> Array:
    """Gravity vector (m/s^2, world frame) from the specific force carried into the world by
    the initial poses ``T_world_board`` (K, 4, 4): over a capture whose receiver ends about
    where it started moving, the mean acceleration is small, so gravity is minus the mean
    world-frame specific force, scaled to standard gravity."""
    R = T_world_board[:-1, :3, :3][data.force_ok]
    mean = np.einsum("kij,kj->i", R, data.force[data.force_ok]) / max(len(R), 1)
    norm = float(np.linalg.norm(mean))
    if norm < 1e-6:
        return np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2])
    return -mean / norm * STANDARD_GRAVITY_MPS2


def start_with_imu(init: Initialisation, data: InertialData) -> tuple[Initialisation, Array]:
    """The initialisation with the gyro's angular rates as the states' (where it has them),
    and the initial gravity (:func:`initial_gravity`)."""
    V = init.V.copy()
    V[data.rate_ok, :3] = data.rate[data.rate_ok]
    return replace(init, V=V), initial_gravity(data, init.X)
