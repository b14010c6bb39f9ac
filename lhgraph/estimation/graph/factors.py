"""The graph's factors, built in one place for the batch solve and the streaming smoother.

1. **Bearing factor**, one per sweep k, keys :func:`bearing_keys` (board pose, twist and sweep
   offset of state k, and the station's pose unless it is held fixed: the reference, or
   every station when tracking): one row per diode
   hit in that sweep, residual = predicted angle of the full station model + sweep offset -
   measured, isotropic diode noise wrapped in the per-diode robust loss
   (:mod:`lhgraph.estimation.graph.loss`);
2. **sweep-offset prior** on every offset (GTSAM's ``PriorFactorVector``, zero mean), and
   with ``diode_bias_sigma_rad`` a zero-mean prior on every station's diode-bias vector (then
   a key of each of its bearing factors);
3. **motion prior** (white noise on acceleration) between consecutive states, keys
   :func:`motion_keys`;
4. with an IMU stream and ``imu_factors`` resolving to ``"combined"``: GTSAM's
   preintegrated **combined IMU factor** over every step the stream covers, in C++
   (:mod:`lhgraph.estimation.imu.combined`); with ``"twist"``
   (:mod:`lhgraph.estimation.imu.inertial`): a **gyro factor** on every
   state's twist and the IMU bias (linear: GTSAM's ``LinearContainerFactor``, no Python
   callback; with the IMU calibration, ``gyro_scale_sigma`` / ``imu_time_offset_sigma_s``,
   a callback on the twist, the bias and the calibration), an **accelerometer factor** over
   every step, keys :func:`accel_keys`, with ``gyro_preintegration`` (off by default) a
   **preintegrated gyro factor** over every step on both poses and the IMU bias
   (:mod:`lhgraph.estimation.imu.twist_terms`), one factor on the gravity's magnitude and,
   with the calibration, its zero-mean prior.

The residuals come from :mod:`lhgraph.estimation.residuals`; who evaluates them is the
caller's choice (the batch graph's vectorised :class:`FactorEvaluator`, the streaming
smoother's per-sweep callbacks), passed in as the factor's callback.
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.evaluator import SCALE_SIGMA_M2, FactorError, FactorEvaluator
from lhgraph.estimation.graph.loss import RobustLoss
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    BOARD_TWIST,
    GRAVITY,
    IMU_BIAS,
    IMU_CALIBRATION,
    STATION_POSE,
    SWEEP_OFFSET,
    VariableLayout,
    diode_bias_family,
    sensor_offset_family,
)
from lhgraph.estimation.imu.combined import CombinedImu, gravity_magnitude_factor
from lhgraph.estimation.imu.inertial import InertialData
from lhgraph.estimation.problem import GraphProblem

Array = NDArray[np.float64]


def bearing_keys(k: int, station_var: int | None, bias_key: int | None = None,
                 offset_key: int | None = None) -> list[int]:
    """Keys of sweep k's bearing factor; ``station_var``: the slot of the sweeping station
    when its pose is a variable, None when it is held fixed (the reference); ``bias_key``:
    the sweeping station's diode-bias vector, when the graph has them."""
    keys = [BOARD_POSE.key(k), BOARD_TWIST.key(k), SWEEP_OFFSET.key(k)]
    if station_var is not None:
        keys.append(STATION_POSE.key(station_var))
    if bias_key is not None:
        keys.append(bias_key)
    return keys if offset_key is None else keys + [offset_key]


def motion_keys(k: int) -> list[int]:
    """Keys of the motion prior between states k and k + 1."""
    return [BOARD_POSE.key(k), BOARD_TWIST.key(k), BOARD_POSE.key(k + 1), BOARD_TWIST.key(k + 1)]


def accel_keys(k: int, calibration: bool = False) -> list[int]:
    """Keys of the accelerometer factor over the step from state k to k + 1 (and the IMU
    calibration, whose time offset moves the reading, when the graph has it)."""
    keys = motion_keys(k) + [IMU_BIAS.key(0), GRAVITY.key(0)]
    return keys + [IMU_CALIBRATION.key(0)] if calibration else keys


def gyro_factor(k: int, rate: Array, sigma_rad_s: float) -> gtsam.LinearContainerFactor:
    """State k's gyro factor: ``omega_k + gyro bias = rate`` (3,) rad/s, linear, as a
    nonlinear factor linearised at zero (exact: both variables are vectors)."""
    A_twist = np.hstack([np.eye(3), np.zeros((3, 3))])
    keys = (BOARD_TWIST.key(k), IMU_BIAS.key(0))
    linear = gtsam.JacobianFactor(keys[0], A_twist, keys[1], A_twist, rate,
                                  gtsam.noiseModel.Isotropic.Sigma(3, sigma_rad_s))
    zero = gtsam.Values()
    zero.insert(keys[0], np.zeros(6))
    zero.insert(keys[1], np.zeros(6))
    return gtsam.LinearContainerFactor(linear, zero)


class FactorBuilder:
    """Makes the graph's factors with one robust loss and sweep-offset noise."""

    def __init__(self, loss: RobustLoss, sweep_offset_sigma_rad: float):
        self._estimator = loss.estimator()
        self._offset_noise = gtsam.noiseModel.Isotropic.Sigma(1, sweep_offset_sigma_rad)

    def bearing(self, k: int, station_var: int | None, n_hits: int, angle_sigma_rad: float,
                error: FactorError, bias_key: int | None = None,
                offset_key: int | None = None) -> gtsam.CustomFactor:
        """Sweep k's bearing factor: ``n_hits`` diodes of noise ``angle_sigma_rad``, robust;
        ``station_var`` and ``bias_key`` as in :func:`bearing_keys`."""
        noise = gtsam.noiseModel.Robust.Create(
            self._estimator, gtsam.noiseModel.Isotropic.Sigma(n_hits, angle_sigma_rad))
        return gtsam.CustomFactor(noise, bearing_keys(k, station_var, bias_key, offset_key),
                                  error)

    def offset_prior(self, k: int) -> gtsam.PriorFactorVector:
        """The zero-mean prior on sweep k's offset."""
        return gtsam.PriorFactorVector(SWEEP_OFFSET.key(k), np.zeros(1), self._offset_noise)

    def motion(self, k: int, covariance: Array, error: FactorError) -> gtsam.CustomFactor:
        """The motion prior between states k and k + 1 of ``covariance`` (12, 12)."""
        return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(covariance),
                                  motion_keys(k), error)


def build_graph(problem: GraphProblem, options: GraphOptions, T_world_lh: Array | None = None,
                inertial: InertialData | None = None
                ) -> tuple[gtsam.NonlinearFactorGraph, FactorEvaluator]:
    """The nonlinear factor graph of ``problem`` (one bearing factor per sweep, the offset
    priors, the motion priors, and with ``inertial`` the IMU factors) and the evaluator its
    callbacks slice. ``T_world_lh`` ``(S, 4, 4)`` by station slot holds every station fixed
    at that pose (tracking); without it the stations but the reference are variables."""
    loss = RobustLoss(options.loss, options.huber_k)
    bias = (diode_bias_family(problem.n_sensors) if options.diode_bias_sigma_rad > 0
            else None)
    offset = (sensor_offset_family(problem.n_sensors) if options.sensor_offset_sigma_m > 0
              else None)
    calibrated = options.imu_calibrated
    combined = inertial is not None and options.imu_factor_kind == "combined"
    layout = VariableLayout.of_problem(problem.n_states, len(problem.station_ids),
                                       fixed_stations=T_world_lh is not None,
                                       inertial=inertial is not None, diode_bias=bias,
                                       sensor_offset=offset, imu_calibration=calibrated,
                                       combined_imu=combined)
    ev = FactorEvaluator(problem, layout, loss, options, T_world_lh,
                         None if combined else inertial)
    build = FactorBuilder(loss, options.sweep_offset_sigma_rad)
    graph = gtsam.NonlinearFactorGraph()
    for k in range(problem.n_states):
        n = int(problem.bounds[k + 1] - problem.bounds[k])
        slot = int(problem.state_station[k])
        var = slot if layout.holds(STATION_POSE, slot) else None
        graph.add(build.bearing(k, var, n, options.angle_sigma_rad, ev.bearing_error(k, slot),
                                None if bias is None else bias.key(slot),
                                None if offset is None else offset.key(0)))
    for k in range(problem.n_states):
        graph.add(build.offset_prior(k))
    if bias is not None:
        bias_noise = gtsam.noiseModel.Isotropic.Sigma(bias.dim, options.diode_bias_sigma_rad)
        for slot in layout.indices(bias):
            graph.add(gtsam.PriorFactorVector(bias.key(slot), np.zeros(bias.dim), bias_noise))
    if offset is not None:
        graph.add(gtsam.PriorFactorVector(offset.key(0), np.zeros(offset.dim),
                                          gtsam.noiseModel.Isotropic.Sigma(
                                              offset.dim, options.sensor_offset_sigma_m)))
        graph.add(gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(1, SCALE_SIGMA_M2),
                                     [offset.key(0)], ev.scale_error()))
    first = graph.size()
    for k in range(problem.n_states - 1):
        graph.add(build.motion(k, ev.motion_covariances[k], ev.motion_error(k)))
    ev.motion_factors = range(first, graph.size())
    if combined:
        ev.combined = CombinedImu(inertial.stream, problem.state_time, layout, options)
        graph.push_back(ev.combined.graph)
    elif inertial is not None:
        gyro_noise = gtsam.noiseModel.Isotropic.Sigma(3, options.gyro_sigma_rad_s)
        for k in np.flatnonzero(inertial.rate_ok).tolist():
            graph.add(gtsam.CustomFactor(
                gyro_noise, [BOARD_TWIST.key(k), IMU_BIAS.key(0), IMU_CALIBRATION.key(0)],
                ev.gyro_error(k)) if calibrated
                else gyro_factor(k, inertial.rate[k], options.gyro_sigma_rad_s))
        first = graph.size()
        for k in np.flatnonzero(inertial.force_ok).tolist():
            accel_noise = gtsam.noiseModel.Isotropic.Sigma(3, ev.imu.accel_sigmas[k])
            graph.add(gtsam.CustomFactor(accel_noise, accel_keys(k, calibrated),
                                         ev.accel_error(k)))
        ev.accel_factors = range(first, graph.size())
        for i, (k, sigma) in enumerate(zip(ev.imu.preintegrated.tolist(),
                                           ev.imu.preintegration_sigmas.tolist(),
                                           strict=True)):
            graph.add(gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(3, sigma),
                                         [BOARD_POSE.key(k), BOARD_POSE.key(k + 1),
                                          IMU_BIAS.key(0)], ev.preintegration_error(i)))
        if calibrated:
            graph.add(gtsam.PriorFactorVector(
                IMU_CALIBRATION.key(0), np.zeros(IMU_CALIBRATION.dim),
                gtsam.noiseModel.Diagonal.Sigmas(ev.imu.calibration_sigmas)))
        graph.add(gravity_magnitude_factor())
    return graph, ev
