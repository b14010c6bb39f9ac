"""Non-planar PnP: a single-station board pose by multi-start Levenberg-Marquardt.

No planarity assumption, so it suits curved boards such as the Vive Tracker, whose sensors
lie on a shell that no homography fits: each measurement's pose is fitted from random
orientations (vectorised over the starts), the board placed 2 m along the mean bearing, and
the best pose in front of the station kept. One measurement at a time (~15 ms each), so it
is slower than the vectorised planar solver of :mod:`lhgraph.estimation.init.pnp`, whose
result type and facing test it shares.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.init.pnp import PnPResult, facing_fraction
from lhgraph.geometry.transforms import make_pose, se3_exp
from lhgraph.model.station import StationModel, predict

Array = NDArray[np.float64]


def single_station_pnp(positions: Array, normals: Array, axis: NDArray, angle: Array,
                       model: StationModel | None = None, n_starts: int = 16,
                       iterations: int = 30, seed: int = 0) -> tuple[Array, float, float]:
    """Board pose ``T_lh_board`` from one station's hits (any mix of axes, rad).

    ``positions``/``normals`` (n, 3) are the hit sensors (board frame, repeated per hit).
    Multi-start Levenberg-Marquardt over ``n_starts`` random orientations (vectorised over the
    starts). Returns the pose with the smallest residual among those in front of the station,
    its rms residual (rad) and the fraction of hit sensors facing the station.
    """
    from scipy.spatial.transform import Rotation

    model = model or StationModel()
    axis = np.asarray(axis, dtype=np.int64)
    n = len(angle)
    az = angle[axis == 0].mean() if np.any(axis == 0) else 0.0
    el = angle[axis == 1].mean() if np.any(axis == 1) else 0.0
    d = np.array([1.0, np.tan(az), np.tan(el)])
    d /= np.linalg.norm(d)
    R0 = Rotation.random(n_starts, random_state=seed).as_matrix()
    T = make_pose(R0, 2.0 * d - R0 @ positions.mean(axis=0))
    s_all = np.tile(positions, (n_starts, 1))
    ax_all = np.tile(axis, n_starts)

    def residuals(T: Array) -> tuple[Array, Array]:
        """Residuals (starts, n) and board-pose Jacobians (starts, n, 6) at poses ``T``."""
        pred, _, H = predict(np.eye(4), np.repeat(T, n, axis=0), s_all, ax_all, model,
                             jacobians=True)
        return (pred - np.tile(angle, n_starts)).reshape(n_starts, n), H.reshape(n_starts, n, 6)

    lam = np.full(n_starts, 1e-3)
    r, H = residuals(T)
    cost = np.sum(r**2, axis=1)
    for _ in range(iterations):
        JtJ = np.swapaxes(H, 1, 2) @ H
        g = (np.swapaxes(H, 1, 2) @ r[..., None])[..., 0]
        A = JtJ + lam[:, None, None] * (np.eye(6) * np.diagonal(JtJ, axis1=1, axis2=2)[:, None]
                                        + 1e-12 * np.eye(6))
        delta = -np.linalg.solve(A, g[..., None])[..., 0]
        T_new = T @ se3_exp(delta)
        r_new, H_new = residuals(T_new)
        cost_new = np.sum(r_new**2, axis=1)
        better = np.isfinite(cost_new) & (cost_new < cost)
        T = np.where(better[:, None, None], T_new, T)
        r = np.where(better[:, None], r_new, r)
        H = np.where(better[:, None, None], H_new, H)
        cost = np.where(better, cost_new, cost)
        lam = np.where(better, lam * 0.3, lam * 10.0)
    cost = np.where(T[:, 0, 3] > 0, cost, np.inf)
    best = int(np.argmin(cost))
    facing = float(facing_fraction(T[best][None], positions, normals)[0])
    return T[best], float(np.sqrt(cost[best] / n)), facing


def tracker_board_poses(azimuth: Array, elevation: Array, positions: Array, normals: Array,
                        model: StationModel | None = None, min_sensors: int = 5,
                        n_starts: int = 8) -> PnPResult:
    """A pose solver for curved boards (Vive Tracker), a drop-in for
    :func:`lhgraph.estimation.init.pnp.board_poses` (e.g. as the ``pose_solver`` of
    :class:`~lhgraph.estimation.init.pnp_kabsch.PnPKabschInitialiser`):
    :func:`single_station_pnp` on each measurement's sensors seen on both axes.

    ``azimuth``/``elevation`` (M, S) rad (NaN = not seen) over the board's sensors
    ``positions``/``normals`` (S, 3); measurements with fewer than ``min_sensors`` get NaN.
    """
    mask = np.isfinite(azimuth) & np.isfinite(elevation)
    n = mask.sum(axis=1)
    M = len(azimuth)
    T, rms = np.full((M, 4, 4), np.nan), np.full(M, np.nan)
    for m in np.flatnonzero(n >= min_sensors):
        k = np.flatnonzero(mask[m])
        angle = np.stack([azimuth[m, k], elevation[m, k]], axis=1).ravel()
        T[m], rms[m], _ = single_station_pnp(
            np.repeat(positions[k], 2, axis=0), np.repeat(normals[k], 2, axis=0),
            np.tile([0, 1], len(k)), angle, model, n_starts)
    return PnPResult(T, rms, n)
