"""The IMU factors' residuals and Jacobians at the batch graph's evaluated point, vectorised:
:class:`ImuTerms`, held by :class:`~lhgraph.estimation.graph.evaluator.FactorEvaluator` when
the graph has IMU factors (:mod:`lhgraph.estimation.inertial`).

Variables read: the IMU bias ``I(0)``, the gravity ``N(0)`` and, when the options ask for it,
the IMU calibration ``C(0)`` (per-axis gyro scale error ``s``, time offset ``tau``): the gyro
residual is then ``(1 + s) omega_k + b_gyro - gyro(t_k + tau)`` and the accelerometer is read
at each step's middle ``+ tau``.
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import (
    GRAVITY,
    IMU_BIAS,
    IMU_CALIBRATION,
    VariableLayout,
)
from lhgraph.estimation.inertial import GRAVITY_SIGMA_MPS2, InertialData
from lhgraph.estimation.residuals import accel_residuals, gyro_residuals
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2

Array = NDArray[np.float64]
FIXED_CALIBRATION_SIGMA = 1e-7
"""Prior spread of an IMU calibration component the options do not ask for (a gyro scale of
0.1 ppm, a time offset of 0.1 us): held at zero."""


class ImuTerms:
    """Gyro and accelerometer residuals (``g`` (K, 3) rad/s, ``a`` (K - 1, 3) m/s^2) and their
    Jacobians (``Hg``: twist, IMU bias, calibration; ``Ha``: as
    :func:`~lhgraph.estimation.residuals.accel_residuals`, with the bias Jacobian widened to
    the 6-vector, and the calibration's last) of ``data`` at the point of :meth:`read`."""

    def __init__(self, data: InertialData, layout: VariableLayout, options: GraphOptions):
        self.data = data
        self.gyro_sigma = options.gyro_sigma_rad_s
        self.accel_sigma = options.accel_sigma_mps2
        self.calibration = layout.family(IMU_CALIBRATION.name)
        self.calibration_sigmas = np.array(
            [options.gyro_scale_sigma or FIXED_CALIBRATION_SIGMA] * 3
            + [options.imu_time_offset_sigma_s or FIXED_CALIBRATION_SIGMA])
        """Prior spread of the calibration's components (an unasked one is held at 0)."""
        self.imu = np.zeros(9)  # IMU bias (gyro, accelerometer), gravity
        self.C = np.zeros(4)  # gyro scale error (3), time offset (s)

    def matches(self, values: gtsam.Values) -> bool:
        """Whether ``values`` hold the IMU variables of the last :meth:`read`."""
        return (np.array_equal(values.atVector(IMU_BIAS.key(0)), self.imu[:6])
                and np.array_equal(values.atVector(GRAVITY.key(0)), self.imu[6:])
                and (self.calibration is None or np.array_equal(
                    values.atVector(self.calibration.key(0)), self.C)))

    def read(self, values: gtsam.Values, X: Array, W: Array) -> None:
        """Residuals at ``values`` with board poses ``X`` (K, 4, 4) and twists ``W`` (K, 6)."""
        self.imu = np.concatenate([values.atVector(IMU_BIAS.key(0)),
                                   values.atVector(GRAVITY.key(0))])
        d = self.data
        rate, self._force, self._rate_slope, self._force_slope = d.rate, d.force, None, None
        if self.calibration is not None:
            self.C = values.atVector(self.calibration.key(0))
            rate, self._rate_slope, self._force, self._force_slope = d.read_at(self.C[3])
        self._X, self._W = X, W
        self.g = gyro_residuals(W * np.r_[1.0 + self.C[:3], np.ones(3)], self.imu[:3], rate)
        self.a = self._accel(False)[0]

    def jacobians(self) -> None:
        """``Hg`` and ``Ha`` at the point of the last :meth:`read`."""
        _, Ha = self._accel(True)
        H_bias = np.zeros((len(Ha[4]), 3, 6))
        H_bias[:, :, 3:] = Ha[4]
        self.Ha = (*Ha[:4], H_bias, Ha[5])
        if self.calibration is None:
            return
        K = len(self._W)
        H_twist = np.zeros((K, 3, 6))
        H_twist[:, :, :3] = np.diag(1.0 + self.C[:3])
        H_gyro_bias = np.zeros((K, 3, 6))
        H_gyro_bias[:, :, :3] = np.eye(3)
        H_cal = np.zeros((K, 3, 4))
        H_cal[:, [0, 1, 2], [0, 1, 2]] = self._W[:, :3]
        H_cal[:, :, 3] = -self._rate_slope
        self.Hg = (H_twist, H_gyro_bias, H_cal)
        H_accel_cal = np.zeros((K - 1, 3, 4))
        H_accel_cal[:, :, 3] = -np.einsum("kij,kj->ki", self._X[:-1, :3, :3],
                                          self._force_slope)
        self.Ha = (*self.Ha, H_accel_cal)

    def cost(self) -> float:
        """Half the squared whitened gyro, accelerometer, gravity-magnitude and calibration
        prior residuals (what the IMU factors add to ``graph.error``)."""
        d = self.data
        g = self.g[d.rate_ok] / self.gyro_sigma
        a = self.a[d.force_ok] / self.accel_sigma
        m = (np.linalg.norm(self.imu[6:]) - STANDARD_GRAVITY_MPS2) / GRAVITY_SIGMA_MPS2
        c = self.C / self.calibration_sigmas if self.calibration is not None else np.zeros(0)
        return 0.5 * float(np.sum(g * g) + np.sum(a * a) + m * m + np.sum(c * c))

    def residuals(self) -> tuple[Array, Array]:
        """Gyro (K, 3) and accelerometer (K - 1, 3) residuals, NaN where the IMU has no
        sample."""
        return (np.where(self.data.rate_ok[:, None], self.g, np.nan),
                np.where(self.data.force_ok[:, None], self.a, np.nan))

    def summary(self) -> dict[str, float]:
        """The biases' norms, the gravity's magnitude, the rms residuals and, with the
        calibration, the gyro scales (``1 + s``) and the time offset (s)."""
        gyro, accel = self.residuals()
        calibration = {} if self.calibration is None else {
            "gyro_scale_x": 1.0 + float(self.C[0]), "gyro_scale_y": 1.0 + float(self.C[1]),
            "gyro_scale_z": 1.0 + float(self.C[2]), "imu_time_offset_s": float(self.C[3])}
        return calibration | {"gyro_bias_rad_s": float(np.linalg.norm(self.imu[:3])),
                              "accel_bias_mps2": float(np.linalg.norm(self.imu[3:6])),
                              "gravity_mps2": float(np.linalg.norm(self.imu[6:])),
                              "gyro_rms_rad_s": float(np.sqrt(np.nanmean(gyro**2))),
                              "accel_rms_mps2": float(np.sqrt(np.nanmean(accel**2)))}

    def _accel(self, jacobians: bool) -> tuple[Array, tuple | None]:
        X, W = self._X, self._W
        return accel_residuals(X[:-1], W[:-1], X[1:], W[1:], self.data.dt, self._force,
                               self.imu[3:6], self.imu[6:], jacobians)
