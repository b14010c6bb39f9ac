"""GTSAM's preintegrated IMU factors between the batch graph's board states (``imu_factors =
"combined"``): everything evaluated in C++, no Python callback per factor.

Per board state k the graph gains the board origin's velocity in the world ``v(k)`` and the
IMU bias ``b(k)`` (``gtsam.imuBias.ConstantBias``: accelerometer m/s^2, gyro rad/s, board
frame); over every step k -> k + 1 that the stream covers, the readings between the two
state times are preintegrated (:func:`preintegrate`) into one
``gtsam.CombinedImuFactorWithGravityVector`` on ``x(k), v(k), x(k+1), v(k+1), b(k), b(k+1)``
and the gravity vector ``n(0)`` (m/s^2, world; the world is the reference station's frame,
so its up is unknown): position, velocity and rotation change of the step, and the bias's
random walk over it.

The readings' noise: each axis's white noise from the stream itself
(:func:`~lhgraph.estimation.imu.inertial.reading_noise`, the largest axis) times
``imu_noise_factor``, as a density (``sigma sqrt(period)``); the bias walks
``gyro_bias_walk`` / ``accel_bias_walk``. A step the stream does not cover (a gap longer
than ``imu_max_gap_s``, or no time between the states) gets a bias random walk only
(``BetweenFactorConstantBias``) and each state none of whose steps has an IMU factor a loose
velocity prior (:data:`FREE_VELOCITY_SIGMA_MPS`), so that no variable is left undetermined.
A zero-mean prior on the first bias (:data:`BIAS_PRIOR_SIGMAS`, a MEMS part's turn-on bias
and more) and one factor on the gravity's magnitude (the only callback: the norm, near
standard gravity, :data:`~lhgraph.estimation.imu.inertial.GRAVITY_SIGMA_MPS2`) complete it.

The IMU is at the board origin in the board frame (``imu.csv``'s convention); its
calibration (gyro scale, time offset, frame) is not a variable of these factors: the twist
factors (:mod:`lhgraph.estimation.imu.twist_terms`) solve it in the graph, and for these
:func:`~lhgraph.estimation.graph.solver.solve_graph` finds it from the light-only solution
(:mod:`lhgraph.estimation.imu.calibration`) and corrects the stream.

The specific force's half turn: under a held body-frame reading, the nav-frame force over a
piece is ``R(start) Exp(omega (tau - start)) f``, on average the turn to the piece's middle;
GTSAM takes it in the start's frame, so the reading is turned by ``Exp(omega dt / 2)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    GRAVITY,
    IMU_BIAS_STATE,
    IMU_VELOCITY,
    VariableLayout,
)
from lhgraph.estimation.imu.inertial import (
    GRAVITY_SIGMA_MPS2,
    gravity_magnitude_residual,
    gyro_reading_sigma,
    reading_noise,
)
from lhgraph.geometry.transforms import so3_exp
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2, ImuStream

Array = NDArray[np.float64]
FREE_VELOCITY_SIGMA_MPS = 10.0
"""Spread (m/s) of the prior that holds the velocity of a state no IMU factor reaches (the
light and the motion prior say nothing of it): far looser than any hand-held motion."""
BIAS_PRIOR_SIGMAS = np.array([0.5, 0.5, 0.5, 0.05, 0.05, 0.05])
"""Spread of the zero-mean prior on the first state's bias (accelerometer m/s^2, gyro
rad/s): several times a small MEMS part's turn-on bias (0.05 m/s^2, 0.005 rad/s, the
simulator's); it only keeps the bias determined where the motion says little of it."""
RESIDUAL_GROUPS = {"rotation": slice(0, 3), "position": slice(3, 6),
                   "velocity": slice(6, 9), "bias": slice(9, 15)}
"""The components of a combined IMU factor's 15 residuals (GTSAM's order)."""
INTEGRATION_SIGMA = 1e-4
"""Integration noise of the preintegration (m/s per root second: GTSAM's integration
covariance, the position's error beyond the accelerometer's)."""


@dataclass(frozen=True)
class Preintegration:
    """The steps of a problem's board states with IMU factors: ``steps`` (n,) the k of
    each k -> k + 1 the stream covers, ``measurements`` their preintegrated readings in the
    same order; ``gaps`` the other steps."""

    steps: NDArray[np.int64]
    measurements: list[gtsam.PreintegratedCombinedMeasurements]
    gaps: NDArray[np.int64]


def noise_params(stream: ImuStream, options: GraphOptions) -> gtsam.PreintegrationCombinedParams:
    """GTSAM's preintegration parameters for ``stream``: the readings' white-noise densities
    (rad/s and m/s^2 per root hertz) from the stream's own noise times
    ``options.imu.imu_noise_factor``, the bias walks of ``options``; gravity is a variable of
    the factors, not of these parameters."""
    period = float(np.median(np.diff(stream.time)))
    gyro = max(gyro_reading_sigma(stream), options.imu.min_gyro_sigma_rad_s)
    accel = max(float(np.max(reading_noise(stream.accel_mps2))), options.imu.min_accel_sigma_mps2)
    p = gtsam.PreintegrationCombinedParams.MakeSharedU(STANDARD_GRAVITY_MPS2)
    scale2 = options.imu.imu_noise_factor**2 * period
    p.setGyroscopeCovariance(np.eye(3) * gyro**2 * scale2)
    p.setAccelerometerCovariance(np.eye(3) * accel**2 * scale2)
    p.setIntegrationCovariance(np.eye(3) * INTEGRATION_SIGMA**2)
    p.setBiasOmegaCovariance(np.eye(3) * options.imu.gyro_bias_walk**2)
    p.setBiasAccCovariance(np.eye(3) * options.imu.accel_bias_walk**2)
    return p


def preintegrate(stream: ImuStream, state_time: Array, options: GraphOptions) -> Preintegration:
    """The readings of ``stream`` (board frame, the states' clock) between consecutive
    ``state_time`` (K,) preintegrated at zero bias: each sample holds from halfway to the
    sample before to halfway to the one after (its white noise then enters the
    preintegration once, as the noise model has it; interpolated readings would share each
    sample's noise among several pieces); a step is cut where its samples' spans meet, and
    each piece's specific force is turned by half the piece's gyro turn (GTSAM's
    integration takes it in the frame at the piece's start: a hand-held deck turning at
    ~1 rad/s read at 100 Hz otherwise gets a systematic error of ~0.05 m/s^2 that scaled
    the simulated decks' stations by -0.1 %). A step
    is covered when it has positive length, lies within the stream, and no two samples
    around it are more than ``options.imu.imu_max_gap_s`` apart."""
    t = stream.time
    edges = 0.5 * (t[1:] + t[:-1])  # sample i holds from edges[i - 1] to edges[i]
    t0, t1 = state_time[:-1], state_time[1:]
    first = np.searchsorted(t, t0, side="right") - 1  # the last sample at or before t0
    last = np.searchsorted(t, t1, side="left")  # the first sample at or after t1
    inside = (t1 > t0) & (t0 >= t[0]) & (t1 <= t[-1])
    too_long = np.r_[0, np.cumsum(np.diff(t) > options.imu.imu_max_gap_s)]
    covered = inside & (too_long[np.clip(last, 0, len(t) - 1)]
                        == too_long[np.clip(first, 0, len(t) - 1)])
    # every piece between consecutive state times and sample edges, its step and its sample
    cuts = np.union1d(state_time[np.r_[covered, False] | np.r_[False, covered]],
                      edges[(edges > state_time[0]) & (edges < state_time[-1])])
    middle = 0.5 * (cuts[1:] + cuts[:-1])
    step = np.searchsorted(state_time, middle, side="right") - 1
    keep = covered[np.clip(step, 0, len(covered) - 1)] & (step < len(covered))
    dt, step, sample = np.diff(cuts)[keep], step[keep], np.searchsorted(edges, middle[keep])
    gyro = stream.gyro_rad_s[sample]
    # GTSAM turns a piece's specific force into the frame at the piece's start; the
    # reading is the frame's at its middle, half a piece of turn later
    accel = np.einsum("kij,kj->ki", so3_exp(gyro * (dt / 2)[:, None]),
                      stream.accel_mps2[sample])
    params = noise_params(stream, options)
    zero = gtsam.imuBias.ConstantBias()
    bounds = np.searchsorted(step, np.flatnonzero(covered)).tolist()
    measurements = []
    ends = bounds[1:] + [len(step)] if bounds else []
    for start, end in zip(bounds, ends, strict=True):
        pim = gtsam.PreintegratedCombinedMeasurements(params, zero)
        for i in range(start, end):
            pim.integrateMeasurement(accel[i], gyro[i], dt[i])
        measurements.append(pim)
    return Preintegration(np.flatnonzero(covered), measurements, np.flatnonzero(~covered))


def gravity_magnitude_factor() -> gtsam.CustomFactor:
    """The factor holding the gravity vector's norm near standard gravity (noise
    :data:`~lhgraph.estimation.imu.inertial.GRAVITY_SIGMA_MPS2`;
    :func:`~lhgraph.estimation.imu.inertial.gravity_magnitude_residual`), for both kinds of IMU
    factors."""

    def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
        r, J = gravity_magnitude_residual(values.atVector(GRAVITY.key(0)))
        if H is not None:
            H[0] = J
        return r

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(1, GRAVITY_SIGMA_MPS2),
                              [GRAVITY.key(0)], error)


def combined_imu_factors(pre: Preintegration, state_time: Array, options: GraphOptions
                         ) -> gtsam.NonlinearFactorGraph:
    """The IMU part of the batch graph of board states at ``state_time`` (K,): a
    ``CombinedImuFactorWithGravityVector`` per covered step of ``pre``, a bias random walk
    over each other step, the loose zero-mean velocity priors of the states no IMU factor
    reaches, the first bias's prior and the gravity's magnitude."""
    graph = gtsam.NonlinearFactorGraph()
    x, v, b = BOARD_POSE.key, IMU_VELOCITY.key, IMU_BIAS_STATE.key
    for k, pim in zip(pre.steps.tolist(), pre.measurements, strict=True):
        graph.add(gtsam.CombinedImuFactorWithGravityVector(
            x(k), v(k), x(k + 1), v(k + 1), b(k), b(k + 1), GRAVITY.key(0), pim))
    walk = np.r_[[options.imu.accel_bias_walk] * 3, [options.imu.gyro_bias_walk] * 3]
    n_states = len(state_time)
    period = float(np.median(np.diff(state_time))) if n_states > 1 else 1.0
    zero = gtsam.imuBias.ConstantBias()
    for k in pre.gaps.tolist():
        dt = max(float(state_time[k + 1] - state_time[k]), period)
        graph.add(gtsam.BetweenFactorConstantBias(
            b(k), b(k + 1), zero, gtsam.noiseModel.Diagonal.Sigmas(walk * np.sqrt(dt))))
    reached = np.zeros(n_states, dtype=bool)
    reached[pre.steps] = reached[pre.steps + 1] = True
    free = gtsam.noiseModel.Isotropic.Sigma(3, FREE_VELOCITY_SIGMA_MPS)
    for k in np.flatnonzero(~reached).tolist():
        graph.add(gtsam.PriorFactorVector(v(k), np.zeros(3), free))
    graph.add(gtsam.PriorFactorConstantBias(b(0), zero,
                                            gtsam.noiseModel.Diagonal.Sigmas(BIAS_PRIOR_SIGMAS)))
    graph.add(gravity_magnitude_factor())
    return graph


class CombinedImu:
    """The combined IMU factors of one batch graph (:func:`combined_imu_factors` of
    :func:`preintegrate`): their cost, the gravity and a summary at given values, for the
    evaluator that adds them to the graph's."""

    def __init__(self, stream: ImuStream, state_time: Array, layout: VariableLayout,
                 options: GraphOptions):
        self.preintegration = preintegrate(stream, state_time, options)
        if not len(self.preintegration.steps):
            raise InputError(
                f"the IMU stream covers no step between board states (its samples "
                f"{stream.time[0]:.3f}-{stream.time[-1]:.3f} s, longest gap "
                f"{np.max(np.diff(stream.time), initial=0.0) * 1e3:.0f} ms against "
                f"imu_max_gap_s = {options.imu.imu_max_gap_s * 1e3:.0f} ms)", "imu")
        self.graph = combined_imu_factors(self.preintegration, state_time, options)
        self.layout = layout

    def cost(self, values: gtsam.Values) -> float:
        """Half the squared whitened residuals of every factor of :attr:`graph`."""
        return float(self.graph.error(values))

    def mean_bias(self, values: gtsam.Values) -> Array:
        """The states' mean IMU bias at ``values`` as ``[gyro (rad/s), accelerometer
        (m/s^2)]`` (6,), the order of the twist factors' one bias."""
        biases = self.layout.read_vectors(values, IMU_BIAS_STATE).mean(axis=0)
        return np.r_[biases[3:], biases[:3]]

    def summary(self, values: gtsam.Values) -> dict[str, float]:
        """What the factors found at ``values``: the biases' mean (norms of the accelerometer
        and gyro parts), the gravity's magnitude, the number of preintegrated factors and
        their whitened residuals' mean square per component group (rotation, position,
        velocity, bias walk: 1 where the noise is right and the fit does not absorb them)."""
        bias = self.mean_bias(values)
        n = len(self.preintegration.steps)  # the graph's first n factors
        e = np.array([self.graph.at(i).whitenedError(values) for i in range(n)]
                     ).reshape(-1, 15)
        out = {"accel_bias_mps2": float(np.linalg.norm(bias[3:])),
               "gyro_bias_rad_s": float(np.linalg.norm(bias[:3])),
               "gravity_mps2": float(np.linalg.norm(values.atVector(GRAVITY.key(0)))),
               "imu_factors": float(n)}
        for name, cols in RESIDUAL_GROUPS.items():
            out[f"imu_chi2_{name}"] = float(np.mean(e[:, cols] ** 2)) if n else float("nan")
        return out
