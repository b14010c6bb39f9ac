"""The IMU's two factor families of the batch graph
(:mod:`lhgraph.estimation.graph.families.base`): :class:`TwistImu` and :class:`CombinedImuFamily`.

- :class:`TwistImu` (``imu_factors = "twist"``): a **gyro factor** on every state's twist and
  the IMU bias (linear: GTSAM's ``LinearContainerFactor``, no Python callback; with the IMU
  calibration a callback on the twist, the bias and the calibration), an **accelerometer
  factor** over every step (keys :func:`accel_keys`), with ``gyro_preintegration`` a
  **preintegrated gyro factor** over every step on both poses and the IMU bias, with the
  calibration its zero-mean prior, and the factor on the gravity's magnitude; residuals and
  Jacobians from :class:`~lhgraph.estimation.imu.twist_terms.ImuTerms`.
- :class:`CombinedImuFamily` (``"combined"``): GTSAM's preintegrated combined IMU factors,
  evaluated in C++ (:mod:`lhgraph.estimation.imu.combined`).

Both give the IMU bias, the gravity and a summary at the evaluated point.
"""

from __future__ import annotations

import gtsam
import numpy as np

from lhgraph.estimation.graph.families.base import (
    Array,
    BoardPoint,
    Ensure,
    FactorFamily,
    indexed_callback,
)
from lhgraph.estimation.graph.families.motion import motion_keys
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    BOARD_TWIST,
    GRAVITY,
    IMU_BIAS,
    IMU_BIAS_STATE,
    IMU_CALIBRATION,
    IMU_VELOCITY,
    VariableFamily,
    VariableLayout,
)
from lhgraph.estimation.imu.combined import CombinedImu, gravity_magnitude_factor
from lhgraph.estimation.imu.inertial import InertialData
from lhgraph.estimation.imu.twist_terms import ImuTerms
from lhgraph.io.imu import ImuStream


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


class TwistImu(FactorFamily):
    """The twist IMU factors of one graph; :attr:`terms` their residuals, :attr:`accel`
    where the accelerometer factors sit in the graph (for the noise hook's redundancy)."""

    name = "IMU (twist factors)"

    def __init__(self, inertial: InertialData, layout: VariableLayout, options: GraphOptions):
        self.terms = ImuTerms(inertial, layout, options)
        self.data = inertial
        self.calibrated = options.imu.calibrated
        self._gyro_sigma = options.imu.gyro_sigma_rad_s
        self.accel = range(0)
        self._ready = False

    @property
    def variables(self) -> tuple[VariableFamily, ...]:
        return ((BOARD_POSE, BOARD_TWIST, IMU_BIAS, GRAVITY)
                + ((IMU_CALIBRATION,) if self.calibrated else ()))

    def keys(self, i: int) -> list[int]:
        """Keys of factor ``i``: the gyro factors (one per state with a rate), the
        accelerometer factors, the preintegrated gyro factors, the calibration's prior (with
        the calibration) and the gravity's magnitude."""
        gyro = np.flatnonzero(self.data.rate_ok).tolist()
        accel = np.flatnonzero(self.data.force_ok).tolist()
        pre = self.terms.preintegrated.tolist()
        calibration = [IMU_CALIBRATION.key(0)] if self.calibrated else []
        rows = ([[BOARD_TWIST.key(k), IMU_BIAS.key(0)] + calibration for k in gyro]
                + [accel_keys(k, self.calibrated) for k in accel]
                + [[BOARD_POSE.key(k), BOARD_POSE.key(k + 1), IMU_BIAS.key(0)] for k in pre]
                + ([calibration] if self.calibrated else []) + [[GRAVITY.key(0)]])
        return rows[i]

    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        t, first = self.terms, graph.size()
        gyro_noise = gtsam.noiseModel.Isotropic.Sigma(3, self._gyro_sigma)
        for k in np.flatnonzero(self.data.rate_ok).tolist():
            graph.add(gtsam.CustomFactor(
                gyro_noise, [BOARD_TWIST.key(k), IMU_BIAS.key(0), IMU_CALIBRATION.key(0)],
                indexed_callback(ensure, (k,), k, self, lambda: t.g, lambda: t.Hg))
                if self.calibrated else gyro_factor(k, self.data.rate[k], self._gyro_sigma))
        start = graph.size()
        for k in np.flatnonzero(self.data.force_ok).tolist():
            graph.add(gtsam.CustomFactor(
                gtsam.noiseModel.Isotropic.Sigma(3, t.accel_sigmas[k]),
                accel_keys(k, self.calibrated),
                indexed_callback(ensure, (k, k + 1), k, self, lambda: t.a_scaled,
                                 lambda: t.Ha_scaled)))
        self.accel = range(start, graph.size())
        for i, (k, sigma) in enumerate(zip(t.preintegrated.tolist(),
                                           t.preintegration_sigmas.tolist(), strict=True)):
            graph.add(gtsam.CustomFactor(
                gtsam.noiseModel.Isotropic.Sigma(3, sigma),
                [BOARD_POSE.key(k), BOARD_POSE.key(k + 1), IMU_BIAS.key(0)],
                indexed_callback(ensure, (k, k + 1), i, self, lambda: t.p_scaled,
                                 lambda: t.Hp)))
        if self.calibrated:
            graph.add(gtsam.PriorFactorVector(
                IMU_CALIBRATION.key(0), np.zeros(IMU_CALIBRATION.dim),
                gtsam.noiseModel.Diagonal.Sigmas(t.calibration_sigmas)))
        graph.add(gravity_magnitude_factor())
        self.indices = range(first, graph.size())

    def read(self, values: gtsam.Values, point: BoardPoint) -> None:
        self.terms.read(values, point.X, point.W)
        self._ready = False

    def matches(self, values: gtsam.Values, k: int) -> bool:
        return self.terms.matches(values)

    def jacobians(self) -> None:
        if not self._ready:
            self.terms.jacobians()
            self._ready = True

    def cost(self, values: gtsam.Values) -> float:
        return self.terms.cost()

    def summary(self, values: gtsam.Values) -> dict[str, float]:
        return self.terms.summary()

    def preintegrated(self) -> ImuTerms | None:
        """The terms when the graph has preintegrated gyro factors (else None)."""
        return self.terms if len(self.terms.preintegrated) else None

    def scale_preintegration_noise(self, factor: float) -> None:
        """Multiply the preintegrated gyro factors' variance by ``factor`` (at an evaluated
        point; no-op without them)."""
        if self.preintegrated() is not None:
            self.terms.scale_preintegration_noise(factor)
            self._ready = False

    def scale_accel_noise(self, factor: float) -> None:
        """Multiply the accelerometer factors' variance by ``factor`` (at an evaluated
        point)."""
        self.terms.scale_accel_noise(factor)
        self._ready = False

    def bias(self, values: gtsam.Values) -> Array:
        """The IMU bias ``[gyro (rad/s), accelerometer (m/s^2)]`` (6,) at the point read."""
        return self.terms.imu[:6].copy()

    def gravity(self, values: gtsam.Values) -> Array:
        """The gravity vector (m/s^2, world) at the point read."""
        return self.terms.imu[6:].copy()


class CombinedImuFamily(FactorFamily):
    """GTSAM's combined IMU factors of one graph (:class:`CombinedImu`), whose error GTSAM
    evaluates in C++ at the values given."""

    name = "IMU (combined factors)"
    variables: tuple[VariableFamily, ...] = (BOARD_POSE, IMU_VELOCITY, IMU_BIAS_STATE, GRAVITY)

    def __init__(self, stream: ImuStream, state_time: Array, layout: VariableLayout,
                 options: GraphOptions):
        self.combined = CombinedImu(stream, state_time, layout, options)

    def keys(self, i: int) -> list[int]:
        return list(self.combined.graph.at(i).keys())

    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        first = graph.size()
        graph.push_back(self.combined.graph)
        self.indices = range(first, graph.size())

    def cost(self, values: gtsam.Values) -> float:
        return self.combined.cost(values)

    def summary(self, values: gtsam.Values) -> dict[str, float]:
        return self.combined.summary(values)

    def bias(self, values: gtsam.Values) -> Array:
        """The states' mean IMU bias ``[gyro (rad/s), accelerometer (m/s^2)]`` (6,)."""
        return self.combined.mean_bias(values)

    def gravity(self, values: gtsam.Values) -> Array:
        """The gravity vector (m/s^2, world) at ``values``."""
        return values.atVector(GRAVITY.key(0))
