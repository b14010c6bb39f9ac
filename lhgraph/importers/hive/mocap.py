"""Comparison of an estimated board path with the OptiTrack ground truth of a hive recording:
:func:`align_to_mocap` (world alignment, hand-eye and time offset)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import SolverError
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import (
    interpolate_poses,
    make_pose,
    nearest_rotation,
    se3_exp,
    so3_log,
)
from lhgraph.io.trajectory import Trajectory

Array = NDArray[np.float64]


@dataclass(frozen=True)
class MocapAlignment:
    """A board path aligned to OptiTrack: ``T_world_opti`` (world alignment), ``T_body_board``
    (hand-eye: marker body -> board frame), ``time_offset_s`` (mocap time = path time +
    offset), and per compared pose the position error (m) and rotation error (rad)."""

    T_world_opti: Array
    T_body_board: Array
    time_offset_s: float
    time: Array
    position_error_m: Array
    rotation_error_rad: Array

    def rmse_mm(self) -> float:
        """Root-mean-square position error (mm)."""
        return float(np.sqrt(np.mean(self.position_error_m**2)) * 1e3)

    def rmse_deg(self) -> float:
        """Root-mean-square rotation error (deg)."""
        return float(np.degrees(np.sqrt(np.mean(self.rotation_error_rad**2))))


def align_to_mocap(path: Trajectory, mocap: Trajectory, max_gap_s: float = 0.05,
                   max_offset_s: float = 0.1, rotation_scale_m: float = 0.1,
                   robust_scale_m: float = 0.005) -> MocapAlignment:
    """Fit ``T_world_board(t) ~ T_world_opti T_opti_body(t + dt) T_body_board`` by nonlinear
    least squares (scipy, soft-L1 loss of scale ``robust_scale_m``) over the 13 unknowns.

    ``path``: estimated board poses (world = reference station); ``mocap``: marker-body poses
    ``T_opti_body`` (its ``T_world_board`` field), interpolated (:func:`interpolate_poses`) at
    the path times + ``dt`` (|dt| <= ``max_offset_s``); path times without mocap samples within
    ``max_gap_s`` on both sides are skipped. Residual per pose: position error (m) and
    rotation error (rad) times ``rotation_scale_m``. Start: Kabsch on positions, chordal mean
    of the body-to-board rotations, zero lever arm and offset.
    """
    from scipy.optimize import least_squares

    t_m, T_m = mocap.time, mocap.T_world_board
    i = np.searchsorted(t_m, path.time)
    ok = (i > 0) & (i < len(t_m))
    ic = np.clip(i, 1, len(t_m) - 1)
    ok &= (path.time - t_m[ic - 1] < max_gap_s) & (t_m[ic] - path.time < max_gap_s)
    ok &= (path.time > t_m[0] + max_offset_s) & (path.time < t_m[-1] - max_offset_s)
    ok &= np.all(np.isfinite(path.T_world_board.reshape(len(path.time), -1)), axis=1)
    t, T_est = path.time[ok], path.T_world_board[ok]
    if len(t) < 10:
        raise SolverError(f"only {len(t)} path poses overlap the mocap recording")
    T_body = interpolate_poses(t_m, T_m, t)
    W0 = weighted_kabsch(T_body[:, :3, 3], T_est[:, :3, 3])
    H0 = make_pose(nearest_rotation(np.sum(np.swapaxes(W0[:3, :3] @ T_body[:, :3, :3], 1, 2)
                                           @ T_est[:, :3, :3], axis=0)), np.zeros(3))

    def unpack(x: Array) -> tuple[Array, Array, float]:
        return se3_exp(x[:6]) @ W0, H0 @ se3_exp(x[6:12]), float(x[12])

    def errors(x: Array) -> tuple[Array, Array]:
        W, H, dt = unpack(x)
        T_pred = W @ interpolate_poses(t_m, T_m, t + dt) @ H
        e_pos = T_pred[:, :3, 3] - T_est[:, :3, 3]
        e_rot = so3_log(np.swapaxes(T_est[:, :3, :3], 1, 2) @ T_pred[:, :3, :3])
        return e_pos, e_rot

    def residuals(x: Array) -> Array:
        e_pos, e_rot = errors(x)
        return np.concatenate([e_pos, rotation_scale_m * e_rot], axis=1).ravel()

    lim = np.r_[np.full(12, np.inf), max_offset_s]
    fit = least_squares(residuals, np.zeros(13), bounds=(-lim, lim), loss="soft_l1",
                        f_scale=robust_scale_m, x_scale=np.r_[np.full(12, 0.01), 0.01])
    W, H, dt = unpack(fit.x)
    e_pos, e_rot = errors(fit.x)
    return MocapAlignment(W, H, dt, t, np.linalg.norm(e_pos, axis=1),
                          np.linalg.norm(e_rot, axis=1))
