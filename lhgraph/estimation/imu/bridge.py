"""Joining two stations that never see the board at the same moment through the receiver's IMU
(stations facing each other and a one-sided board: each sees it only while it faces that way).

The board's pose in the parent station's frame, known from the parent's path up to the
moment it turns away, is carried forward (or back) to a moment the child station sees it by
integrating the IMU: the gyro turns it, the accelerometer (less gravity) moves it from the
path's own velocity there. Each such moment proposes ``T_parent_child``; the proposals that
agree with their median are averaged by a weighted Kabsch on the board's sensor points,
weighted by how short the bridge is (the dead reckoning's error grows with its length).

Frames: the paths are ``T_lh_board`` in each station's frame, the IMU is in the board frame
on the paths' clock (:class:`~lhgraph.io.imu.ImuStream`); the gravity in the parent's frame
is minus the mean specific force over its path, carried into its frame by the path's
rotations (over a capture's seconds the board's mean acceleration is small).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import inverse, so3_exp, transform_points
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2, ImuStream
from lhgraph.model.board import Board

Array = NDArray[np.float64]
Path = tuple[Array, Array, Array]
"""A station's path: ``(times s, T_lh_board (N, 4, 4), rms rad)``."""
MAX_BRIDGE_S = 0.6
"""Longest dead reckoning a proposal may rest on."""
VELOCITY_SPAN_S = 0.06
"""The path's velocity at a bridge's start: a line through its positions within this of it
(on the side away from the bridge)."""
STEP_S = 1e-3
"""Integration step of the dead reckoning."""
MIN_PROPOSALS = 3


def _sample(imu: ImuStream, t: Array) -> tuple[Array, Array]:
    """Gyro and accelerometer (M, 3) interpolated at ``t`` (M,)."""
    gyro = np.stack([np.interp(t, imu.time, imu.gyro_rad_s[:, j]) for j in range(3)], axis=1)
    accel = np.stack([np.interp(t, imu.time, imu.accel_mps2[:, j]) for j in range(3)], axis=1)
    return gyro, accel


def gravity_in(path: Path, imu: ImuStream) -> Array:
    """Gravity (m/s^2, 3) in the frame of ``path``'s station: minus the mean specific force
    carried into it by the path's rotations, scaled to the standard gravity."""
    t, T, _ = path
    _, accel = _sample(imu, t)
    mean = np.einsum("kij,kj->i", T[:, :3, :3], accel) / len(t)
    return -mean / max(float(np.linalg.norm(mean)), 1e-9) * STANDARD_GRAVITY_MPS2


def dead_reckon(imu: ImuStream, t0: Array, T0: Array, v0: Array, gravity: Array, t1: Array
                ) -> Array:
    """Board poses ``(M, 4, 4)`` at ``t1`` carried from poses ``T0`` at ``t0`` (M,) with
    velocities ``v0`` (M, 3), in a frame where the gravity is ``gravity`` (3,): rotation by the
    gyro, position by the velocity and the accelerometer less gravity, integrated in steps of
    at most ``STEP_S`` (backward when ``t1 < t0``)."""
    n = np.maximum(np.ceil(np.abs(t1 - t0) / STEP_S).astype(int), 1)
    dt = (t1 - t0) / n
    R, p, v = T0[:, :3, :3].copy(), T0[:, :3, 3].copy(), v0.copy()
    for i in range(int(n.max())):
        active = i < n
        t = t0 + (i + 0.5) * dt
        gyro, accel = _sample(imu, t)
        a = np.einsum("kij,kj->ki", R, accel) + gravity
        step = np.where(active, dt, 0.0)[:, None]
        p = p + v * step + 0.5 * a * step**2
        v = v + a * step
        R = R @ so3_exp(gyro * step)
    T1 = np.repeat(np.eye(4)[None], len(t0), axis=0)
    T1[:, :3, :3], T1[:, :3, 3] = R, p
    return T1


def _velocity(path: Path, i: Array, towards: Array) -> Array:
    """Velocity (M, 3) of ``path`` at samples ``i``: a line through its positions within
    ``VELOCITY_SPAN_S`` on the side away from ``towards`` (+1: later times, -1: earlier)."""
    t, T, _ = path
    out = np.zeros((len(i), 3))
    for m, (k, d) in enumerate(zip(i.tolist(), towards.tolist(), strict=True)):
        near = (np.abs(t - t[k]) <= VELOCITY_SPAN_S) & ((t - t[k]) * d <= 0)
        if np.count_nonzero(near) >= 2:
            out[m] = np.polyfit(t[near] - t[k], T[near, :3, 3], 1)[0]
    return out


def bridged_relative_pose(board: Board, parent: Path, child: Path, imu: ImuStream,
                          max_bridge_s: float = MAX_BRIDGE_S) -> Array | None:
    """``T_parent_child`` from moments the child saw the board within ``max_bridge_s`` of a
    moment the parent did, bridged by the IMU (module docstring); None with fewer than
    ``MIN_PROPOSALS`` such moments."""
    t_p, T_p, _ = parent
    t_c, T_c, rms_c = child
    if len(t_p) < 2 or len(t_c) == 0:
        return None
    j = np.clip(np.searchsorted(t_p, t_c), 1, len(t_p) - 1)
    nearest = np.where(np.abs(t_p[j - 1] - t_c) <= np.abs(t_p[j] - t_c), j - 1, j)
    gap = t_c - t_p[nearest]
    use = np.flatnonzero((np.abs(gap) <= max_bridge_s) & (t_c >= imu.time[0])
                         & (t_c <= imu.time[-1]))
    if len(use) < MIN_PROPOSALS:
        return None
    k = nearest[use]
    v0 = _velocity(parent, k, np.sign(gap[use]))
    carried = dead_reckon(imu, t_p[k], T_p[k], v0, gravity_in(parent, imu), t_c[use])
    proposals = carried @ inverse(T_c[use])
    centre = np.median(proposals[:, :3, 3], axis=0)
    spread = np.linalg.norm(proposals[:, :3, 3] - centre, axis=1)
    agree = spread <= max(3 * np.median(spread), 0.02)
    src = transform_points(T_c[use][agree][:, None], board.positions[None])
    dst = transform_points(carried[agree][:, None], board.positions[None])
    weight = 1.0 / ((gap[use][agree] ** 2 + 1e-4) * (rms_c[use][agree] ** 2 + 1e-10))
    return weighted_kabsch(src.reshape(-1, 3), dst.reshape(-1, 3),
                           np.repeat(weight, len(board.positions)))
