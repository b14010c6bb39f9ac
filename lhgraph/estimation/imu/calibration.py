"""The IMU's calibration found from a light-only solution, for IMU factors that cannot solve
it themselves (GTSAM's combined factors, :mod:`lhgraph.estimation.imu.combined`).

The light gives the board's mean angular rate ``omega_k`` (rad/s, board frame) over a short
window from every state; the gyro, read ``tau`` later on the light's clock (its stamps run
``tau`` late), reads on average ``M omega_k + b`` over the window, with
``M = diag(scale) R^T`` (``R``: the IMU's frame in the board's) and a bias ``b``.
:func:`fit_imu_calibration` finds ``tau`` by a search over a window (for each candidate the
linear least squares of ``M`` and ``b``, robustly: rates more than 3 robust standard
deviations off are left out), then ``scale`` and ``R`` from ``M`` (the rows' norms and the
nearest rotation). :meth:`ImuCalibration.apply` turns the stream into the board's frame and
the light's clock, its gyro divided by the scale: what ``imu.csv`` means.

Measured (docs/track.md): on a simulated 8 s capture whose gyro reads 0.5 / 0.47 / 0.52 of
the rate, stamped 6 ms late, its frame turned by 1.5 deg: scales within 0.002, the offset
8.6 ms, the frame 1.2 deg; on hive's tracker 0.499 / 0.506 / 0.497 and -6.0 ms (the twist
factors solve 0.495 / 0.510 / 0.497 and -5.3 ms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.spread import robust_sigma
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import nearest_rotation, rotation_angle, so3_log
from lhgraph.io.imu import ImuStream

Array = NDArray[np.float64]
OFFSET_STEP_S = 5e-4
"""The time-offset search's grid (s), refined by a parabola through the best three."""
WINDOW_S = 0.1
"""The windows (s) over which the light's rotation and the gyro's mean rate are compared."""
OUTLIER_SIGMAS = 3.0
"""Rates whose fit residual exceeds this many robust standard deviations are left out (the
light's angular rate at a state in a mirror pose, a turn no station sees)."""


@dataclass(frozen=True)
class ImuCalibration:
    """Per-axis gyro ``scale`` (3,: the gyro reads ``scale`` times the rate), the time offset
    ``time_offset_s`` at which the IMU is read on the light's clock (its stamps run that much
    late) and ``R_board_imu`` (3, 3), the IMU's frame in the board's."""

    scale: Array
    time_offset_s: float
    R_board_imu: Array

    def apply(self, stream: ImuStream) -> ImuStream:
        """``stream`` on the light's clock, in the board frame, its gyro rescaled to the
        true rate (its bias, left for the IMU factors to solve, rotated and rescaled too)."""
        gyro = (stream.gyro_rad_s / self.scale) @ self.R_board_imu.T
        return ImuStream(stream.time - self.time_offset_s,
                         stream.accel_mps2 @ self.R_board_imu.T, gyro)

    def summary(self) -> dict[str, float]:
        """The diagnostics' keys of the twist factors' calibration: gyro scales, time offset
        (s), the IMU frame's rotation (deg)."""
        return {"gyro_scale_x": float(self.scale[0]), "gyro_scale_y": float(self.scale[1]),
                "gyro_scale_z": float(self.scale[2]),
                "imu_time_offset_s": float(self.time_offset_s),
                "imu_rotation_deg": float(np.degrees(rotation_angle(self.R_board_imu)))}


def _fit(gyro: Array, omega: Array, scale: bool, rotation: bool
         ) -> tuple[Array, float]:
    """``M`` of ``gyro ~ M omega + b`` over the rates kept, and the kept residuals' mean
    square: ``M`` full with ``scale`` and ``rotation``, diagonal with ``scale`` alone, a
    rotation with ``rotation`` alone (Kabsch), the identity with neither."""
    keep = np.ones(len(gyro), dtype=bool)
    for _ in range(3):
        A = np.c_[omega[keep], np.ones(keep.sum())]
        if scale and rotation:
            coef = np.linalg.lstsq(A, gyro[keep], rcond=None)[0]
            M, b = coef[:3].T, coef[3]
        elif scale:
            M, b = np.eye(3), np.zeros(3)
            for j in range(3):
                s, b[j] = np.linalg.lstsq(A[:, [j, 3]], gyro[keep, j], rcond=None)[0]
                M[j, j] = s
        elif rotation:
            T = weighted_kabsch(omega[keep], gyro[keep])
            M, b = T[:3, :3], T[:3, 3]
        else:
            M, b = np.eye(3), np.mean(gyro[keep] - omega[keep], axis=0)
        e = np.linalg.norm(gyro - omega @ M.T - b, axis=1)
        keep = e <= OUTLIER_SIGMAS * max(robust_sigma(e[keep]), 1e-12)
    return M, float(np.mean(e[keep] ** 2))


def fit_imu_calibration(stream: ImuStream, state_time: Array, T_world_board: Array,
                        scale: bool = True, offset: bool = True, rotation: bool = True,
                        max_offset_s: float = 0.05, window_s: float = WINDOW_S
                        ) -> ImuCalibration:
    """The IMU's calibration from the light's poses ``T_world_board`` (K, 4, 4) at
    ``state_time`` (K,; s): over windows of about ``window_s`` from every state, the light's
    mean angular rate (the rotation vector from the window's first pose to its last, over
    its length; board frame) against the gyro's mean over the same window, read ``tau``
    later; the time offset searched within ``max_offset_s`` (with ``offset``), the per-axis
    scale (with ``scale``) and the IMU frame's rotation (with ``rotation``); an unasked part
    stays at 1, 0, the identity. Rotations over a window, not the solution's angular rates:
    the motion prior smooths those (their peaks low, the scales found 2-4 % low)."""
    t = stream.time
    end = np.searchsorted(state_time, state_time + window_s)
    ok = end < len(state_time)
    k, j = np.flatnonzero(ok), end[ok]
    span = state_time[j] - state_time[k]
    R = T_world_board[:, :3, :3]
    omega = so3_log(np.swapaxes(R[k], 1, 2) @ R[j]) / span[:, None]
    area = np.r_[np.zeros((1, 3)), np.cumsum(0.5 * (stream.gyro_rad_s[1:]
                                                   + stream.gyro_rad_s[:-1])
                                             * np.diff(t)[:, None], axis=0)]

    def sampled(tau: float) -> tuple[Array, Array]:
        inside = (state_time[k] + tau >= t[0]) & (state_time[j] + tau <= t[-1])
        a, b = state_time[k][inside] + tau, state_time[j][inside] + tau
        mean = np.stack([np.interp(b, t, area[:, i]) - np.interp(a, t, area[:, i])
                         for i in range(3)], axis=1) / (b - a)[:, None]
        return mean, omega[inside]

    def cost(tau: float) -> float:
        return _fit(*sampled(tau), scale, rotation)[1]

    tau = 0.0
    if offset:
        grid = np.arange(-max_offset_s, max_offset_s + OFFSET_STEP_S / 2, OFFSET_STEP_S)
        costs = np.array([cost(x) for x in grid])
        i = int(np.clip(np.argmin(costs), 1, len(grid) - 2))
        c0, c1, c2 = costs[i - 1:i + 2]
        curvature = c0 - 2 * c1 + c2
        shift = 0.5 * (c0 - c2) / curvature if curvature > 0 else 0.0
        tau = float(grid[i] + np.clip(shift, -1, 1) * OFFSET_STEP_S)
    M = _fit(*sampled(tau), scale, rotation)[0]
    s = np.linalg.norm(M, axis=1)  # M = diag(s) R^T: row j is s_j times R's column j
    return ImuCalibration(s, tau, nearest_rotation(M / s[:, None]).T)
