"""A station's 1-sigma in the axes the tables print: position along the world's x, y, z and
the ZYX Euler angles (roll, pitch, yaw) of :func:`~lhgraph.geometry.transforms.euler_zyx`.

The stations' covariances are GTSAM Pose3 covariances, ``[rotation, translation]`` in the
station's own (body) frame: the position block is rotated into the world, the rotation
block pushed through the Jacobian of the Euler angles (central differences).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.geometry.transforms import euler_zyx, so3_exp

_STEP_RAD = 1e-6


@dataclass(frozen=True)
class PoseSigma:
    """1-sigma of one station: ``position_m`` along world x, y, z (m), ``euler_rad`` of
    roll, pitch, yaw (rad), ``body_rad`` of the rotation about the station's own x, y, z
    axes (rad; the axes of the errors' alpha, beta, gamma to first order)."""

    position_m: NDArray[np.float64]
    euler_rad: NDArray[np.float64]
    body_rad: NDArray[np.float64]

    def norms(self) -> tuple[float, float]:
        """``(sqrt(sx^2 + sy^2 + sz^2) m, same of the body rotation rad)``: the CLI's sigma."""
        return float(np.linalg.norm(self.position_m)), float(np.linalg.norm(self.body_rad))


def euler_jacobian(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """d(roll, pitch, yaw) / d(body rotation vector) at ``R`` (3, 3)."""
    J = np.empty((3, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = _STEP_RAD
        diff = euler_zyx(R @ so3_exp(d)) - euler_zyx(R @ so3_exp(-d))
        J[:, i] = np.angle(np.exp(1j * diff)) / (2 * _STEP_RAD)
    return J


def pose_sigma(T_world_lh: NDArray[np.float64], covariance: NDArray[np.float64]) -> PoseSigma:
    """The 1-sigma of a station pose ``T_world_lh`` with its 6x6 body-frame covariance."""
    R = T_world_lh[:3, :3]
    cov_rot, cov_pos = covariance[:3, :3], covariance[3:, 3:]
    J = euler_jacobian(R)
    return PoseSigma(np.sqrt(np.clip(np.diag(R @ cov_pos @ R.T), 0, None)),
                     np.sqrt(np.clip(np.diag(J @ cov_rot @ J.T), 0, None)),
                     np.sqrt(np.clip(np.diag(cov_rot), 0, None)))
