"""Paper step 2: per measurement, the board pose with the station at the origin, by
Nelder-Mead on ``K1 = ||C(L, P) - M||_F^2`` (:func:`estimate_board_poses`), and the rejection
of outlier fits (ours, :func:`reject_outlier_poses`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize

from lhgraph.estimation.baseline.cost import angle_cost, rotation, start_simplex
from lhgraph.estimation.baseline.options import PaperOptions, Progress
from lhgraph.estimation.reconstruct import Measurements
from lhgraph.estimation.spread import robust_sigma
from lhgraph.geometry.transforms import make_pose, so3_exp
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board

Array = NDArray[np.float64]


@dataclass(frozen=True)
class BoardPoses:
    """Per-measurement board poses of one station, the station at the origin.

    ``T_lh_board`` (M, 4, 4) (NaN where not ``valid``); ``cost`` (M,) the remaining K1
    (rad^2); ``n_sensors`` (M,) sensors with both angles; ``evaluations`` (M,) K1 calls.
    """

    lighthouse: int
    time: Array
    T_lh_board: Array
    cost: Array
    n_sensors: NDArray[np.int64]
    valid: NDArray[np.bool_]
    evaluations: NDArray[np.int64]

    def mean_square(self) -> Array:
        """Mean squared angle residual per measurement, ``K1 / (2 n_sensors)`` (rad^2)."""
        return self.cost / np.maximum(2 * self.n_sensors, 1)

    def path(self) -> Trajectory:
        """The valid poses as a trajectory (``T_lh_board`` over time)."""
        return Trajectory(self.time[self.valid], self.T_lh_board[self.valid])


def _minimise_board(s: Array, measured: Array, T0: Array, step_rot: float, step_pos: float,
                    options: PaperOptions) -> tuple[Array, float, int]:
    """Nelder-Mead on K1 around ``T0``: ``R = Exp(omega) R0``, ``t = t0 + v``."""
    s0 = s @ T0[:3, :3].T
    t0 = T0[:3, 3]

    def k1(x: Array) -> float:
        return angle_cost(s0 @ rotation(x[:3]).T + (t0 + x[3:]), measured)

    res = minimize(k1, np.zeros(6), method="Nelder-Mead", options={
        "xatol": options.pose_xatol, "fatol": options.pose_fatol,
        "maxfev": options.pose_maxfev, "initial_simplex": start_simplex(step_rot, step_pos)})
    R = rotation(res.x[:3]) @ T0[:3, :3]
    return make_pose(R, t0 + res.x[3:]), float(res.fun), int(res.nfev)


def _rotation_between(a: Array, b: Array) -> Array:
    """Smallest rotation taking unit vector ``a`` to unit vector ``b``."""
    axis = np.cross(a, b)
    sin, cos = np.linalg.norm(axis), float(a @ b)
    if sin < 1e-9:
        if cos > 0:
            return np.eye(3)
        perp = np.cross(a, np.eye(3)[np.argmin(np.abs(a))])
        return so3_exp(np.pi * perp / np.linalg.norm(perp))
    return so3_exp(axis / sin * math.atan2(sin, cos))


def initial_board_pose(azimuth: ArrayLike, elevation: ArrayLike, s_board: ArrayLike,
                       n_board: ArrayLike) -> Array:
    """Initial ``T_lh_board`` from one measurement's ideal angles, the station at the origin.

    ``azimuth``, ``elevation`` (n,) rad of the sensors at ``s_board`` (n, 3) (board frame, m)
    with normals ``n_board`` (n, 3). The board centre lies along the mean azimuth/elevation
    (the paper); its depth is the ratio of the sensors' largest principal spread on the board
    (m) to that of their ray slopes ``(tan az, tan el)``; the board faces the station (mean
    normal of the seen sensors toward the origin), turned about the line of sight by the 2-D
    Procrustes angle that best matches the seen layout.
    """
    az = np.asarray(azimuth, dtype=float)
    el = np.asarray(elevation, dtype=float)
    s = np.asarray(s_board, dtype=float)
    centre = s.mean(axis=0)
    B = s - centre
    slopes = np.stack([np.tan(az), np.tan(el)], axis=1)
    spread_img = np.linalg.svd(slopes - slopes.mean(axis=0), compute_uv=False)[0]
    spread_board = np.linalg.svd(B, compute_uv=False)[0]
    depth = spread_board / max(spread_img, 1e-9)
    p_c = depth * np.array([1.0, math.tan(az.mean()), math.tan(el.mean())])
    d = p_c / np.linalg.norm(p_c)

    normal = np.asarray(n_board, dtype=float).sum(axis=0)
    if np.linalg.norm(normal) < 1e-9:
        normal = np.linalg.svd(B)[2][2]
    R_face = _rotation_between(normal / np.linalg.norm(normal), -d)

    e1 = np.cross(d, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-6:
        e1 = np.cross(d, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    E = np.stack([e1, np.cross(d, e1)], axis=1)  # (3, 2) basis of the plane normal to d
    rays = np.stack([np.ones_like(az), slopes[:, 0], slopes[:, 1]], axis=1)
    on_plane = rays * ((p_c @ d) / (rays @ d))[:, None] - p_c
    observed = on_plane @ E
    model = (B @ R_face.T) @ E
    psi = math.atan2(np.sum(model[:, 0] * observed[:, 1] - model[:, 1] * observed[:, 0]),
                     np.sum(model * observed))
    R = so3_exp(psi * d) @ R_face
    return make_pose(R, p_c - R @ centre)


def mirror_pose(T_lh_board: ArrayLike, s_board: ArrayLike) -> Array:
    """The planar-board mirror of a pose: same view of the sensors, tilt reflected.

    The board's best-fit plane normal (board frame) and the line of sight to the sensors'
    centroid are both reflected, so the lateral layout seen from the station is unchanged
    while the depth offsets flip (the weak-perspective ambiguity of a planar target).
    """
    T = np.asarray(T_lh_board, dtype=float)
    s = np.asarray(s_board, dtype=float)
    centre = s.mean(axis=0)
    n = np.linalg.svd(s - centre)[2][2]
    p_c = T[:3, :3] @ centre + T[:3, 3]
    d = p_c / np.linalg.norm(p_c)
    R = (np.eye(3) - 2 * np.outer(d, d)) @ T[:3, :3] @ (np.eye(3) - 2 * np.outer(n, n))
    return make_pose(R, p_c - R @ centre)


def estimate_board_pose(azimuth: ArrayLike, elevation: ArrayLike, s_board: ArrayLike,
                        n_board: ArrayLike, T_init: ArrayLike | None = None,
                        options: PaperOptions | None = None) -> tuple[Array, float, int]:
    """Board pose ``T_lh_board`` from one measurement, the station at the origin (paper K1).

    ``azimuth``, ``elevation`` (n,) ideal angles (rad) of the sensors at ``s_board`` (n, 3)
    (board frame, m; normals ``n_board``), all with both angles. Nelder-Mead on
    ``K1 = sum (C(L, P) - M)^2`` from :func:`initial_board_pose` (cold start) or from
    ``T_init`` (warm start); with ``options.mirror_check`` the mirror of the result is refined
    too and the better kept. Returns ``(T_lh_board, K1 rad^2, K1 calls)``.
    """
    options = options or PaperOptions()
    s = np.asarray(s_board, dtype=float)
    measured = np.stack([np.asarray(azimuth, dtype=float), np.asarray(elevation, dtype=float)],
                        axis=1)
    if T_init is not None:
        T0 = np.asarray(T_init, dtype=float)
        depth = float(np.linalg.norm(T0[:3, 3]))
        T, cost, nfev = _minimise_board(s, measured, T0, 0.02, 0.005 * depth, options)
    else:
        T0 = initial_board_pose(measured[:, 0], measured[:, 1], s, n_board)
        depth = float(np.linalg.norm(T0[:3, 3]))
        T, cost, nfev = _minimise_board(s, measured, T0, 0.2, 0.05 * depth, options)
    if options.mirror_check:
        Tm, cost_m, nfev_m = _minimise_board(s, measured, mirror_pose(T, s), 0.05,
                                             0.01 * depth, options)
        nfev += nfev_m
        if cost_m < cost:
            T, cost = Tm, cost_m
    return T, cost, nfev


def typical_spacing(t: ArrayLike) -> float:
    """Typical spacing (s) of sorted times: half the median two-step difference.

    Robust to alternating schedules (a station's sweeps come 8.3 ms then 25 ms apart) and
    to occasional gaps; inf with fewer than three times.
    """
    t = np.asarray(t, dtype=float)
    return float(np.median(t[2:] - t[:-2])) / 2 if len(t) > 2 else np.inf


PARALLEL_MIN_FITS = 24
"""Cold fits below this count run in this process: a process pool's start (~1 s) would
cost more than it saves (one fit takes ~0.1 s)."""
PROGRESS_EVERY = 50


def _fit_cold(tasks: list[tuple[Array, Array, Array, Array]], options: PaperOptions
              ) -> list[tuple[Array, float, int]]:
    """Cold-start fits of several measurements (``(azimuth, elevation, s, n)`` each)."""
    return [estimate_board_pose(az, el, s, n, None, options) for az, el, s, n in tasks]


def fit_workers(n_jobs: int, n_fits: int) -> int:
    """Processes for ``n_fits`` independent fits: 1 below :data:`PARALLEL_MIN_FITS`, else
    ``n_jobs`` (0 = every core) but never more than the fits."""
    if n_fits < PARALLEL_MIN_FITS or n_jobs == 1:
        return 1
    from joblib import cpu_count

    return max(1, min(cpu_count() if n_jobs == 0 else n_jobs, n_fits))


def _cold_fits(tasks: list[tuple[Array, Array, Array, Array]], options: PaperOptions,
               report: Callable[[int], None]) -> list[tuple[Array, float, int]]:
    """Every cold fit, in order: in this process, or in ``options.n_jobs`` processes
    (joblib) when there are enough (:func:`fit_workers`). The fits are independent, so the
    results are the same either way; ``report(done)`` is called as chunks finish."""
    workers = fit_workers(options.n_jobs, len(tasks))
    size = PROGRESS_EVERY if workers == 1 else max(1, math.ceil(len(tasks) / (4 * workers)))
    chunks = [tasks[i:i + size] for i in range(0, len(tasks), size)]
    if workers == 1:
        done = (_fit_cold(c, options) for c in chunks)
    else:
        from joblib import Parallel, delayed

        done = Parallel(n_jobs=workers, return_as="generator")(
            delayed(_fit_cold)(c, options) for c in chunks)
    out: list[tuple[Array, float, int]] = []
    for fits in done:
        out += fits
        report(len(out))
    return out


def estimate_board_poses(meas: Measurements, board: Board, options: PaperOptions | None = None,
                         progress: Progress | None = None) -> BoardPoses:
    """Board pose of every measurement of one station (station at the origin), paper step 2.

    ``meas`` must hold ideal angles over ``board``'s sensors (see :func:`to_ideal`).
    Measurements with fewer than ``options.min_sensors`` sensors having both angles are
    marked invalid. With ``options.warm_start`` each fit starts from the previous valid
    pose when it is at most ``max_gap_periods`` measurement spacings old (one after the
    other); cold fits are independent and run on ``options.n_jobs`` processes.
    """
    options = options or PaperOptions()
    both = meas.both()
    n_used = both.sum(axis=1).astype(np.int64)
    M = len(meas)
    T = np.full((M, 4, 4), np.nan)
    cost = np.full(M, np.nan)
    nfev = np.zeros(M, dtype=np.int64)
    valid = n_used >= options.min_sensors
    max_gap = options.max_gap_periods * typical_spacing(meas.time)
    stage = f"board poses, station {meas.lighthouse}"
    say = (lambda done: None) if progress is None else (lambda done: progress(stage, done, M))
    say(0)
    if not options.warm_start:
        ks = np.flatnonzero(valid)
        tasks = [(meas.azimuth[k, both[k]], meas.elevation[k, both[k]],
                  board.positions[both[k]], board.normals[both[k]]) for k in ks]
        fits = _cold_fits(tasks, options, lambda done: say(int(ks[done - 1]) + 1))
        for k, (T_k, cost_k, nfev_k) in zip(ks, fits, strict=True):
            T[k], cost[k], nfev[k] = T_k, cost_k, nfev_k
    last = None
    for k in range(M) if options.warm_start else ():
        if k % PROGRESS_EVERY == 0:
            say(k)
        if not valid[k]:
            continue
        u = both[k]
        warm = None
        if last is not None and meas.time[k] - meas.time[last] <= max_gap:
            warm = T[last]
        T[k], cost[k], nfev[k] = estimate_board_pose(
            meas.azimuth[k, u], meas.elevation[k, u], board.positions[u], board.normals[u],
            warm, options)
        last = k
    say(M)
    return BoardPoses(meas.lighthouse, meas.time.copy(), T, cost, n_used, valid, nfev)


def outliers(values: ArrayLike, n_mads: float) -> NDArray[np.bool_]:
    """Where ``values`` exceed their median by more than ``n_mads`` x 1.4826 x MAD (ours).

    1.4826 x MAD is a robust standard deviation; ``n_mads = inf`` flags nothing.
    """
    v = np.asarray(values, dtype=float)
    if len(v) == 0 or not math.isfinite(n_mads):
        return np.zeros(len(v), dtype=bool)
    return v > float(np.median(v)) + n_mads * robust_sigma(v)


def reject_outlier_poses(poses: BoardPoses, n_mads: float) -> BoardPoses:
    """``poses`` with the fits whose K1 residual is an outlier marked invalid (ours).

    A valid pose is rejected when its rms angle residual ``sqrt(K1 / (2 n_sensors))`` (rad)
    is an :func:`outliers` among the station's valid poses. Such a fit explains its angles
    far worse than the others: on the hive recording it comes from a stray sweep mixed into
    a measurement with few sensors, and the pose is off by up to 1.7 m (docs/baseline.md).
    Returns a copy.
    """
    keep = poses.valid.copy()
    keep[keep] = ~outliers(np.sqrt(poses.mean_square()[keep]), n_mads)
    return replace(poses, valid=keep)
