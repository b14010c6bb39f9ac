"""The IMU factors' residuals and Jacobians at the batch graph's evaluated point, vectorised:
:class:`ImuTerms`, held by the twist factor family
(:class:`~lhgraph.estimation.imu.families.TwistImu`) when the graph has them
(:mod:`lhgraph.estimation.imu.inertial`).

Variables read: the IMU bias ``I(0)``, the gravity ``N(0)`` and, when the options ask for it,
the IMU calibration ``C(0)`` (per-axis gyro scale error ``s``, time offset ``tau``, rotation
vector ``theta`` of the IMU's frame in the board's, ``R = Exp(theta)``: IMU to board, and the
IMU's position ``p`` in the board frame): the gyro residual is then
``(1 + s) (R^T omega_k) + b_gyro - gyro(t_k + tau)`` and the accelerometer, read at each
step's middle ``+ tau``, is ``R`` times its reading in the board frame less the lever arm's
``alpha x p + omega x (omega x p)`` (the step's mean angular rate ``omega`` and its angular
acceleration ``alpha`` from the two states' twists): the specific force at the board origin.

**Preintegrated gyro** (``gyro_preintegration``, off by default): over every step
k -> k + 1 the gyro's readings between the two states, bias-corrected (and scaled, offset),
integrated into the rotation ``dR_k`` (at the IMU's own rate, in sub-steps of at most one
sample period); the
residual is ``Log(dR_k^T R_k^T R_k+1)`` (3, rad), its noise ``gyro_sigma_rad_s`` per reading
integrated over the step, ``sigma sqrt(dt / rate)``; the noise hook may rescale it
(:meth:`ImuTerms.scale_preintegration_noise`, ``adapt_gyro_sigma``) down to the stream's own
reading noise (:attr:`ImuTerms.reading_sigma`). It uses every reading, where the gyro
factor reads one per state: across a turn that no station sees (no states for a third of a
second) it ties the rotation on both sides. Jacobians: the two poses' rotations and the gyro
bias (first order, ``d dR / d b`` accumulated with the product); the calibration is held at
its current value in them.
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
from lhgraph.estimation.imu.inertial import GRAVITY_SIGMA_MPS2, InertialData, gyro_reading_sigma
from lhgraph.estimation.residuals import accel_residuals, gyro_residuals
from lhgraph.geometry.transforms import skew, so3_exp, so3_log, so3_right_jacobian
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2

Array = NDArray[np.float64]
MAX_SUBSTEPS = 2000
"""Sub-steps of one preintegrated step at most (a step longer than this many IMU periods is
integrated in longer sub-steps)."""
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
        self.gyro_sigma = options.imu.gyro_sigma_rad_s
        self.accel_sigmas = data.accel_sigmas(options.imu.accel_start_sigma(data.stream))
        """Each step's accelerometer-factor noise (m/s^2, :meth:`InertialData.accel_sigmas`) in
        the graph's noise models; the factors see it times :meth:`accel_sigma_factor`."""
        self.accel_bounds = (options.imu.min_accel_sigma_mps2, options.imu.accel_sigma_mps2)
        """The range (m/s^2) a rescaling may move the factors' median noise within."""
        self._accel_scale = 1.0  # 1/sqrt(f): the accelerometer factors' variance is f times
        self.calibration = layout.family(IMU_CALIBRATION.name)
        self.calibration_sigmas = np.array(
            [options.imu.gyro_scale_sigma or FIXED_CALIBRATION_SIGMA] * 3
            + [options.imu.imu_time_offset_sigma_s or FIXED_CALIBRATION_SIGMA]
            + [options.imu.imu_rotation_sigma_rad or FIXED_CALIBRATION_SIGMA] * 3
            + [options.imu.imu_position_sigma_m or FIXED_CALIBRATION_SIGMA] * 3)
        """Prior spread of the calibration's components (an unasked one is held at 0)."""
        self.imu = np.zeros(9)  # IMU bias (gyro, accelerometer), gravity
        self.C = np.zeros(IMU_CALIBRATION.dim)
        """Gyro scale error (3), time offset (s), IMU rotation (3, rad), IMU position (3, m)."""
        self._R = np.eye(3)  # IMU frame to board frame, Exp(C[4:7])
        self.preintegrated = (np.zeros(0, dtype=np.int64) if not options.imu.gyro_preintegration
                              else np.flatnonzero(data.rate_ok[:-1] & data.rate_ok[1:]
                                                  & (data.dt > 0)))
        """Steps k (k -> k + 1) with a preintegrated gyro factor."""
        self.preintegration_sigmas = np.zeros(0)
        """Noise (rad) of each preintegrated gyro factor (its noise model's: at
        ``gyro_sigma_rad_s``)."""
        self._pre_scale = 1.0  # 1/sqrt(f): the preintegrated factors' variance is f times theirs
        self.reading_sigma = options.imu.gyro_sigma_rad_s
        """The lowest reading noise the preintegrated factors may be rescaled to (rad/s): the
        stream's own within [``min_gyro_sigma_rad_s``, ``gyro_sigma_rad_s``]."""
        if len(self.preintegrated):
            self._substeps(options.imu.gyro_sigma_rad_s)
            self.reading_sigma = float(np.clip(gyro_reading_sigma(data.stream),
                                               options.imu.min_gyro_sigma_rad_s,
                                               options.imu.gyro_sigma_rad_s))

    def scale_preintegration_noise(self, factor: float) -> None:
        """Multiply the preintegrated gyro factors' variance by ``factor`` (their residuals
        and Jacobians are scaled instead of their noise models)."""
        self._pre_scale /= np.sqrt(factor)
        self.p_scaled = self.p * self._pre_scale

    def scale_accel_noise(self, factor: float) -> None:
        """Multiply the accelerometer factors' variance by ``factor`` (their residuals and
        Jacobians are scaled instead of their noise models)."""
        self._accel_scale /= np.sqrt(factor)
        self.a_scaled = self.a * self._accel_scale

    def accel_sigma_factor(self) -> float:
        """The accelerometer factors' effective noise over their noise models'."""
        return 1.0 / self._accel_scale

    def accel_sigma(self) -> float:
        """The accelerometer factors' effective median noise now (m/s^2)."""
        return float(np.median(self.accel_sigmas[self.data.force_ok]) / self._accel_scale)

    def preintegration_sigma(self) -> float:
        """The preintegrated factors' effective reading noise now (rad/s)."""
        return self.gyro_sigma / self._pre_scale

    def preintegration_chi2_per_dof(self) -> float:
        """Mean squared whitened preintegrated-gyro residual per degree of freedom at the
        current noise (nan without such factors)."""
        if not len(self.preintegrated):
            return float("nan")
        return float(np.mean((self.p_scaled / self.preintegration_sigmas[:, None]) ** 2))

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
            self._R = so3_exp(self.C[4:7])
            rate, self._rate_slope, force, self._force_slope = d.read_at(self.C[3])
            self._force_imu = force
            self._force = force @ self._R.T - self._lever(W)
        self._X, self._W = X, W
        self._u = W[:, :3] @ self._R  # the states' rates in the IMU frame
        self.g = gyro_residuals(np.c_[(1.0 + self.C[:3]) * self._u, W[:, 3:]], self.imu[:3],
                                rate)
        self.a = self._accel(False)[0]
        self.a_scaled = self.a * self._accel_scale
        """The accelerometer residuals the factors see: ``a`` scaled to the current noise."""
        if len(self.preintegrated):
            self._preintegrate()

    def _substeps(self, sigma_rad_s: float) -> None:
        """The preintegration's sub-step grid: per preintegrated step its sub-step length
        ``_h`` (s), the sub-steps' middle times ``_grid`` (n, M) and mask ``_inside``, and
        each step's noise ``preintegration_sigmas`` (rad)."""
        d, k = self.data, self.preintegrated
        period = float(np.median(np.diff(d.stream.time)))
        dt = d.dt[k]
        n = np.clip(np.ceil(dt / period).astype(int), 1, MAX_SUBSTEPS)
        self._h = dt / n
        m = np.arange(int(n.max()))
        self._inside = m[None] < n[:, None]
        self._grid = d.state_time[k][:, None] + (np.minimum(m[None], n[:, None] - 1) + 0.5) \
            * self._h[:, None]
        self.preintegration_sigmas = sigma_rad_s * np.sqrt(dt * period)

    def _preintegrate(self) -> None:
        """``_dR`` (n, 3, 3) and ``_J_bias`` (n, 3, 3: d Log(dR) / d gyro bias) of every
        preintegrated step at the current bias and calibration, and the residuals ``p``."""
        s = self.data.stream
        t = self._grid + self.C[3]
        gyro = np.stack([np.interp(t, s.time, s.gyro_rad_s[:, j]) for j in range(3)], axis=-1)
        omega = ((gyro - self.imu[:3]) / (1.0 + self.C[:3])) @ self._R.T  # board frame
        n = len(self.preintegrated)
        dR = np.repeat(np.eye(3)[None], n, axis=0)
        J = np.zeros((n, 3, 3))
        for m in range(omega.shape[1]):
            phi = omega[:, m] * (self._h * self._inside[:, m])[:, None]
            E = so3_exp(phi)
            # d omega / d b = -R / (1 + s): the bias enters every sub-step's rate
            Jb = -so3_right_jacobian(phi) @ (self._R / (1.0 + self.C[:3])[None, :]) \
                * (self._h * self._inside[:, m])[:, None, None]
            J = np.swapaxes(E, 1, 2) @ J + Jb
            dR = dR @ E
        self._dR, self._J_bias = dR, J
        k = self.preintegrated
        R0, R1 = self._X[k, :3, :3], self._X[k + 1, :3, :3]
        self.p = so3_log(np.swapaxes(dR, 1, 2) @ np.swapaxes(R0, 1, 2) @ R1)
        self.p_scaled = self.p * self._pre_scale
        """The residuals the factors see: ``p`` scaled to the current noise."""

    def jacobians(self) -> None:
        """``Hg``, ``Ha`` and ``Ha_scaled`` (the accelerometer factors' at the current noise)
        at the point of the last :meth:`read`."""
        self._jacobians()
        self.Ha_scaled = tuple(H * self._accel_scale for H in self.Ha)

    def _jacobians(self) -> None:
        _, Ha = self._accel(True)
        H_bias = np.zeros((len(Ha[4]), 3, 6))
        H_bias[:, :, 3:] = Ha[4]
        self.Ha = (*Ha[:4], H_bias, Ha[5])
        if len(self.preintegrated):
            self._preintegration_jacobians()
        if self.calibration is None:
            return
        K = len(self._W)
        scale = np.diag(1.0 + self.C[:3])
        J_theta = so3_right_jacobian(self.C[4:7])
        H_twist = np.zeros((K, 3, 6))
        H_twist[:, :, :3] = scale @ self._R.T
        H_gyro_bias = np.zeros((K, 3, 6))
        H_gyro_bias[:, :, :3] = np.eye(3)
        H_cal = np.zeros((K, 3, IMU_CALIBRATION.dim))
        H_cal[:, [0, 1, 2], [0, 1, 2]] = self._u
        H_cal[:, :, 3] = -self._rate_slope
        # d (R^T omega) / d theta = [R^T omega]x J_r(theta)
        H_cal[:, :, 4:7] = scale @ skew(self._u) @ J_theta
        self.Hg = (H_twist, H_gyro_bias, H_cal)
        R0 = self._X[:-1, :3, :3]
        H_accel_cal = np.zeros((K - 1, 3, IMU_CALIBRATION.dim))
        H_accel_cal[:, :, 3] = -np.einsum("kij,jl,kl->ki", R0, self._R, self._force_slope)
        # d (R f) / d theta = -R [f]x J_r(theta)
        H_accel_cal[:, :, 4:7] = R0 @ self._R @ skew(self._force_imu) @ J_theta
        # the residual holds -R0 (f - lever): the lever arm's position and twist terms
        dL_dp, dL_dw0, dL_dw1 = self._lever_jacobians()
        H_accel_cal[:, :, 7:] = R0 @ dL_dp
        self.Ha[1][:, :, :3] += R0 @ dL_dw0
        self.Ha[3][:, :, :3] += R0 @ dL_dw1
        self.Ha = (*self.Ha, H_accel_cal)

    def _step_rates(self, W: Array) -> tuple[Array, Array]:
        """Each step's mean angular rate and angular acceleration (K - 1, 3), board frame,
        from the twists ``W`` of its two states (zero acceleration over a zero-length
        step)."""
        dt = self.data.dt[:, None]
        rise = W[1:, :3] - W[:-1, :3]
        alpha = np.divide(rise, dt, out=np.zeros_like(rise), where=dt > 0)
        return 0.5 * (W[:-1, :3] + W[1:, :3]), alpha

    def _lever(self, W: Array) -> Array:
        """What the accelerometer at the IMU's position ``p`` reads beyond the board origin's
        specific force over each step, board frame (K - 1, 3): ``alpha x p + omega x (omega
        x p)``."""
        omega, alpha = self._step_rates(W)
        p = self.C[7:]
        return np.cross(alpha, p) + np.cross(omega, np.cross(omega, p))

    def _lever_jacobians(self) -> tuple[Array, Array, Array]:
        """Derivatives (K - 1, 3, 3) of :meth:`_lever` by the IMU position and by the two
        states' angular rates."""
        omega, alpha = self._step_rates(self._W)
        p = self.C[7:]
        dt = self.data.dt[:, None, None]
        d_p = skew(alpha) + skew(omega) @ skew(omega)
        # d (omega x (omega x p)) / d omega = (omega . p) I + omega p^T - 2 p omega^T
        d_omega = (np.einsum("kj,j->k", omega, p)[:, None, None] * np.eye(3)
                   + np.einsum("ki,j->kij", omega, p) - 2.0 * np.einsum("i,kj->kij", p, omega))
        # d (alpha x p) / d alpha = -[p]x, alpha = (w1 - w0) / dt
        d_alpha = np.divide(-skew(p), dt, out=np.zeros((len(dt), 3, 3)), where=dt > 0)
        return d_p, 0.5 * d_omega - d_alpha, 0.5 * d_omega + d_alpha

    def _preintegration_jacobians(self) -> None:
        """``Hp``: the preintegrated factors' Jacobians (pose k, pose k + 1, IMU bias), each
        (n, 3, 6): ``r = Log(dR^T R_k^T R_k+1)`` moves by ``-J_l^-1(r) dR^T`` with pose k's
        rotation, ``J_r^-1(r)`` with pose k + 1's and ``-J_l^-1(r) J_bias`` with the gyro
        bias (``J_l^-1(r) = J_r^-1(-r)``)."""
        n = len(self.preintegrated)
        Jl_inv = so3_right_jacobian(-self.p, inverse=True)
        H0, H1, Hb = (np.zeros((n, 3, 6)) for _ in range(3))
        H0[:, :, :3] = -Jl_inv @ np.swapaxes(self._dR, 1, 2)
        H1[:, :, :3] = so3_right_jacobian(self.p, inverse=True)
        Hb[:, :, :3] = -Jl_inv @ self._J_bias
        self.Hp = tuple(H * self._pre_scale for H in (H0, H1, Hb))

    def cost(self) -> float:
        """Half the squared whitened gyro, accelerometer, gravity-magnitude and calibration
        prior residuals (what the IMU factors add to ``graph.error``)."""
        d = self.data
        g = self.g[d.rate_ok] / self.gyro_sigma
        a = self.a_scaled[d.force_ok] / self.accel_sigmas[d.force_ok, None]
        m = (np.linalg.norm(self.imu[6:]) - STANDARD_GRAVITY_MPS2) / GRAVITY_SIGMA_MPS2
        c = self.C / self.calibration_sigmas if self.calibration is not None else np.zeros(0)
        p = (self.p_scaled / self.preintegration_sigmas[:, None] if len(self.preintegrated)
             else np.zeros(0))
        return 0.5 * float(np.sum(g * g) + np.sum(a * a) + m * m + np.sum(c * c)
                           + np.sum(p * p))

    def residuals(self) -> tuple[Array, Array]:
        """Gyro (K, 3) and accelerometer (K - 1, 3) residuals, NaN where the IMU has no
        sample."""
        return (np.where(self.data.rate_ok[:, None], self.g, np.nan),
                np.where(self.data.force_ok[:, None], self.a, np.nan))

    def summary(self) -> dict[str, float]:
        """The biases' norms, the gravity's magnitude, the rms residuals, with the
        calibration the gyro scales (``1 + s``) and the time offset (s), and with the
        preintegrated gyro its effective reading noise (rad/s)."""
        gyro, accel = self.residuals()
        calibration = {} if self.calibration is None else {
            "gyro_scale_x": 1.0 + float(self.C[0]), "gyro_scale_y": 1.0 + float(self.C[1]),
            "gyro_scale_z": 1.0 + float(self.C[2]), "imu_time_offset_s": float(self.C[3]),
            "imu_rotation_deg": float(np.degrees(np.linalg.norm(self.C[4:7]))),
            "imu_position_x_m": float(self.C[7]), "imu_position_y_m": float(self.C[8]),
            "imu_position_z_m": float(self.C[9])}
        if len(self.preintegrated):
            calibration["preintegration_sigma_rad_s"] = self.preintegration_sigma()
        return calibration | {"accel_sigma_mps2": self.accel_sigma(),
                              "gyro_bias_rad_s": float(np.linalg.norm(self.imu[:3])),
                              "accel_bias_mps2": float(np.linalg.norm(self.imu[3:6])),
                              "gravity_mps2": float(np.linalg.norm(self.imu[6:])),
                              "gyro_rms_rad_s": float(np.sqrt(np.nanmean(gyro**2))),
                              "accel_rms_mps2": float(np.sqrt(np.nanmean(accel**2)))}

    def _accel(self, jacobians: bool) -> tuple[Array, tuple | None]:
        X, W = self._X, self._W
        return accel_residuals(X[:-1], W[:-1], X[1:], W[1:], self.data.dt, self._force,
                               self.imu[3:6], self.imu[6:], jacobians)
