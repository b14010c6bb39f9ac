"""The paper's calibration pipeline (Jansen et al.), ``method = "paper"``: our baseline.

Steps (paper §"Proposed Automatic Calibration Algorithm"):

1. per station, reconstruct measurements with both angles (:mod:`lhgraph.estimation.reconstruct`),
   after removing the factory-calibration distortion when a model is given;
2. per measurement, the board pose with the station at the origin: Nelder-Mead on
   ``K1 = ||C(L, P) - M||_F^2`` (:func:`estimate_board_pose`, :func:`estimate_board_poses`);
   poses whose K1 residual is an outlier among the station's are dropped
   (:func:`reject_outlier_poses`, ours, not the paper's);
3. the reference ("master") station's board path; every other ("slave") station's path
   interpolated to the master's timestamps (:func:`interpolate_path`);
4. weighted Kabsch superposition of the two paths -> initial ``T_ref_slave``
   (:func:`initial_station_pose`);
5. Nelder-Mead on ``K2 = sum_n ||C(L, P_n) - M_n||_F^2`` over the slave's measurements with
   the master path fixed (:func:`refine_station_pose`), without the measurements dropped
   in step 2.

:func:`solve_paper` runs it all. Frames: ``T_lh_board`` maps board points (m) into a
station frame (+x forward, +y left, +z up); the world is the reference station's frame.
Angles in rad, times in s. See docs/baseline.md for every choice the paper leaves open.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import OptimizeResult, minimize

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.reconstruct import (
    VARIANTS,
    Measurements,
    reconstruct_measurements,
    to_ideal,
)
from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import interpolate_poses, make_pose, so3_exp, transform_points
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Station, Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.lh1 import IDEAL, StationModel, predict

Array = NDArray[np.float64]
Progress = Callable[[str, int, int], None]
"""``progress(stage, done, total)``: called as work advances (stage is a short label)."""

KABSCH_POINTS = ("board", "sensors")


@dataclass(frozen=True)
class PaperOptions:
    """Settings of the paper pipeline; defaults follow the paper (docs/baseline.md).

    - ``reconstruction``: ``"full"`` | ``"half"`` | ``"merge"``.
    - ``max_gap_periods``: no interpolation (angles, paths) across gaps longer than this many
      periods of the interpolated series.
    - ``warm_start``: start each measurement's Nelder-Mead from the previous measurement's
      pose (faster, not the paper's; the first one and any after a gap start cold).
    - ``mirror_check``: also refine the planar-board mirror of each fitted pose, keep the
      better fit (warm starts included: without it they can follow the wrong branch).
    - ``min_sensors``: a measurement needs this many sensors with both angles.
    - ``min_measurements``: a station needs this many usable measurements.
    - ``outlier_mads``: a board pose whose rms angle residual ``sqrt(K1 / (2 n_sensors))``
      exceeds the median of its station's by more than this many robust standard deviations
      (1.4826 x MAD) is dropped from the paths, the superposition and K2; K2 drops its own
      outlier measurements likewise and is fitted again (``inf``: keep all, the paper).
    - ``kabsch_points``: ``"board"`` superposes the board centres (paper), ``"sensors"``
      every sensor position of every matched board pose.
    - ``weight_floor``: Kabsch weight ``w = 1 / (eps + e_master + e_slave)`` with ``e`` the
      mean squared angle residual of a pose fit and ``eps = weight_floor * median(e_m + e_s)``.
    - ``pose_xatol`` (rad, m), ``pose_fatol`` (rad^2), ``pose_maxfev``: Nelder-Mead on K1.
    - ``refine``: run the final K2 refinement; ``refine_*``: its Nelder-Mead settings.
    """

    reconstruction: str = "full"
    max_gap_periods: float = 2.5
    warm_start: bool = False
    mirror_check: bool = True
    min_sensors: int = 6
    min_measurements: int = 10
    outlier_mads: float = 5.0
    kabsch_points: str = "board"
    weight_floor: float = 0.1
    pose_xatol: float = 1e-6
    pose_fatol: float = 1e-14
    pose_maxfev: int = 6000
    refine: bool = True
    refine_xatol: float = 1e-9
    refine_fatol: float = 1e-15
    refine_maxfev: int = 6000

    def __post_init__(self) -> None:
        if self.reconstruction not in VARIANTS:
            raise InputError(f"unknown reconstruction '{self.reconstruction}' (expected one of "
                             f"{', '.join(VARIANTS)})", where="reconstruction")
        if self.kabsch_points not in KABSCH_POINTS:
            raise InputError(f"unknown kabsch_points '{self.kabsch_points}' (expected one of "
                             f"{', '.join(KABSCH_POINTS)})", where="kabsch_points")
        if self.min_sensors < 4:
            raise InputError("min_sensors must be >= 4", where="min_sensors")
        if not self.outlier_mads > 0:
            raise InputError("outlier_mads must be > 0", where="outlier_mads")


@dataclass
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


# --- per-measurement pose (K1) -----------------------------------------------------------------


def _rotation(w: Array) -> Array:
    """Rotation matrix of one rotation vector (Rodrigues; scalar maths for speed)."""
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    th2 = x * x + y * y + z * z
    if th2 < 1e-24:
        return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])
    th = math.sqrt(th2)
    a = math.sin(th) / th
    b = (1.0 - math.cos(th)) / th2
    return np.array([
        [1.0 - b * (y * y + z * z), b * x * y - a * z, b * x * z + a * y],
        [b * x * y + a * z, 1.0 - b * (x * x + z * z), b * y * z - a * x],
        [b * x * z - a * y, b * y * z + a * x, 1.0 - b * (x * x + y * y)],
    ])


def _angle_errors(p: Array, measured: Array) -> Array:
    """``C - M``: ideal ``[az, el]`` (rad) of station-frame points ``(n, 3)`` minus the
    measured ones ``(n, 2)``."""
    return np.arctan2(p[:, 1:], p[:, :1]) - measured


def _angle_cost(p: Array, measured: Array) -> float:
    """``sum (C - M)^2`` of station-frame points ``(n, 3)`` vs measured ``[az, el]`` ``(n, 2)``."""
    d = _angle_errors(p, measured)
    return float(np.einsum("ij,ij->", d, d))


def _simplex(scale_rot: float, scale_pos: float) -> Array:
    """Nelder-Mead start simplex around 0 in ``[omega, v]`` with the given step sizes."""
    steps = np.r_[np.full(3, scale_rot), np.full(3, scale_pos)]
    return np.vstack([np.zeros(6), np.diag(steps)])


def _minimise_board(s: Array, measured: Array, T0: Array, step_rot: float, step_pos: float,
                    options: PaperOptions) -> tuple[Array, float, int]:
    """Nelder-Mead on K1 around ``T0``: ``R = Exp(omega) R0``, ``t = t0 + v``."""
    s0 = s @ T0[:3, :3].T
    t0 = T0[:3, 3]

    def k1(x: Array) -> float:
        return _angle_cost(s0 @ _rotation(x[:3]).T + (t0 + x[3:]), measured)

    res = minimize(k1, np.zeros(6), method="Nelder-Mead", options={
        "xatol": options.pose_xatol, "fatol": options.pose_fatol,
        "maxfev": options.pose_maxfev, "initial_simplex": _simplex(step_rot, step_pos)})
    R = _rotation(res.x[:3]) @ T0[:3, :3]
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


def estimate_board_poses(meas: Measurements, board: Board, options: PaperOptions | None = None,
                         progress: Progress | None = None) -> BoardPoses:
    """Board pose of every measurement of one station (station at the origin), paper step 2.

    ``meas`` must hold ideal angles over ``board``'s sensors (see :func:`to_ideal`).
    Measurements with fewer than ``options.min_sensors`` sensors having both angles are
    marked invalid. With ``options.warm_start`` each fit starts from the previous valid
    pose when it is at most ``max_gap_periods`` measurement spacings old.
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
    last = None
    for k in range(M):
        if progress is not None and k % 50 == 0:
            progress(stage, k, M)
        if not valid[k]:
            continue
        u = both[k]
        warm = None
        if options.warm_start and last is not None and meas.time[k] - meas.time[last] <= max_gap:
            warm = T[last]
        T[k], cost[k], nfev[k] = estimate_board_pose(
            meas.azimuth[k, u], meas.elevation[k, u], board.positions[u], board.normals[u],
            warm, options)
        last = k
    if progress is not None:
        progress(stage, M, M)
    return BoardPoses(meas.lighthouse, meas.time.copy(), T, cost, n_used, valid, nfev)


def outliers(values: ArrayLike, n_mads: float) -> NDArray[np.bool_]:
    """Where ``values`` exceed their median by more than ``n_mads`` x 1.4826 x MAD (ours).

    1.4826 x MAD is a robust standard deviation; ``n_mads = inf`` flags nothing.
    """
    v = np.asarray(values, dtype=float)
    if len(v) == 0 or not math.isfinite(n_mads):
        return np.zeros(len(v), dtype=bool)
    median = float(np.median(v))
    return v > median + n_mads * 1.4826 * float(np.median(np.abs(v - median)))


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


# --- paths, superposition, refinement -------------------------------------------------------------


def _bracketed(times: Array, query: Array, max_gap_s: float) -> NDArray[np.bool_]:
    """Where ``query`` lies inside sorted ``times``, between samples <= ``max_gap_s`` apart."""
    if len(times) < 2:
        return np.zeros(len(query), dtype=bool)
    i = np.clip(np.searchsorted(times, query, side="right"), 1, len(times) - 1)
    inside = (query >= times[0]) & (query <= times[-1])
    return inside & (times[i] - times[i - 1] <= max_gap_s)


def interpolate_path(poses: BoardPoses, query: ArrayLike, max_gap_s: float | None = None
                     ) -> tuple[Array, Array, NDArray[np.bool_]]:
    """A station's board path at ``query`` times (paper step 3).

    Rotation slerp and linear position between the valid poses around each query time.
    Returns ``(T_lh_board (Q, 4, 4), mean squared residual (Q,) rad^2 interpolated likewise,
    ok (Q,))``; ``ok`` is False outside the path or where its poses are more than
    ``max_gap_s`` apart (default ``max_gap_periods`` x the typical spacing; those rows are
    clamped values, not to be used).
    """
    q = np.asarray(query, dtype=float)
    t = poses.time[poses.valid]
    if max_gap_s is None:
        max_gap_s = PaperOptions().max_gap_periods * typical_spacing(t)
    if len(t) == 0:
        return np.full((len(q), 4, 4), np.nan), np.full(len(q), np.nan), np.zeros(len(q), bool)
    T = interpolate_poses(t, poses.T_lh_board[poses.valid], q)
    ms = np.interp(q, t, poses.mean_square()[poses.valid])
    return T, ms, _bracketed(t, q, max_gap_s)


def initial_station_pose(master: BoardPoses, slave: BoardPoses, board: Board,
                         options: PaperOptions | None = None) -> Array:
    """Initial ``T_ref_slave`` by weighted Kabsch superposition of the two board paths.

    The slave path (``T_slave_board``) is interpolated to the master's valid timestamps
    (``T_ref_board``) and superposed onto it (paper steps 3-4); see :class:`PaperOptions`
    for the points superposed and the weights. Raises :class:`SolverError` when fewer than
    ``options.min_measurements`` timestamps overlap.
    """
    options = options or PaperOptions()
    t = master.time[master.valid]
    max_gap = options.max_gap_periods * typical_spacing(slave.time[slave.valid])
    T_slave, ms_slave, ok = interpolate_path(slave, t, max_gap)
    if ok.sum() < options.min_measurements:
        raise SolverError(f"station {slave.lighthouse}: only {int(ok.sum())} board poses overlap "
                          f"in time with station {master.lighthouse}'s "
                          f"(need >= {options.min_measurements})")
    T_master = master.T_lh_board[master.valid][ok]
    e = master.mean_square()[master.valid][ok] + ms_slave[ok]
    w = 1.0 / (options.weight_floor * np.median(e) + e + 1e-300)
    if options.kabsch_points == "board":
        c = board.positions.mean(axis=0)
        src, dst = transform_points(T_slave[ok], c), transform_points(T_master, c)
    else:
        s = board.positions[None]
        src = transform_points(T_slave[ok][:, None], s).reshape(-1, 3)
        dst = transform_points(T_master[:, None], s).reshape(-1, 3)
        w = np.repeat(w, len(board.positions))
    return weighted_kabsch(src, dst, w)


@dataclass
class Refinement:
    """Result of the K2 refinement of one station: pose, K2 (rad^2) over the measurements
    kept, K2 calls and iterations summed over the fits, convergence of the last fit, the
    measurements overlapping the reference path and how many of them were rejected."""

    T_ref_lh: Array
    cost: float
    evaluations: int
    iterations: int
    converged: bool
    n_measurements: int
    n_rejected: int = 0


MAX_K2_FITS = 3
"""K2 fits at most: all measurements, then refits without the outliers until they repeat."""


def _minimise_station(world: Array, measured: Array, T0: Array, options: PaperOptions
                      ) -> tuple[Array, OptimizeResult]:
    """Nelder-Mead on K2 around ``T0`` (``R = Exp(omega) R0``, ``t = t0 + v``): the pose
    ``T_ref_lh`` seeing the reference-frame points ``world`` (n, 3) at ``measured`` (n, 2)."""
    R0, t0 = T0[:3, :3], T0[:3, 3]

    def k2(x: Array) -> float:
        return _angle_cost((world - (t0 + x[3:])) @ (_rotation(x[:3]) @ R0), measured)

    res = minimize(k2, np.zeros(6), method="Nelder-Mead", options={
        "xatol": options.refine_xatol, "fatol": options.refine_fatol,
        "maxfev": options.refine_maxfev, "initial_simplex": _simplex(0.01, 0.01)})
    return make_pose(_rotation(res.x[:3]) @ R0, t0 + res.x[3:]), res


def refine_station_pose(T_ref_lh: ArrayLike, meas: Measurements, trajectory: Trajectory,
                        board: Board, options: PaperOptions | None = None,
                        max_gap_s: float | None = None) -> Refinement:
    """Final station pose: Nelder-Mead on ``K2 = sum_n ||C(L, P_n) - M_n||_F^2`` (paper step 5).

    ``T_ref_lh`` is the initial pose of the station in the reference frame, ``meas`` its
    measurements (ideal angles), ``trajectory`` the reference board path ``T_ref_board``,
    fixed and interpolated to each measurement's time (measurements outside it or across
    gaps > ``max_gap_s``, default ``max_gap_periods`` x its typical spacing, are skipped).
    Parameterised as ``R = Exp(omega) R0``, ``t = t0 + v``. With a finite
    ``options.outlier_mads`` (ours, not the paper's), measurements whose rms angle residual
    at the fitted pose is an outlier (:func:`outliers`) are dropped and K2 is fitted again
    from that pose, until the dropped set repeats (at most ``MAX_K2_FITS`` fits).
    """
    options = options or PaperOptions()
    T = np.asarray(T_ref_lh, dtype=float)
    if max_gap_s is None:
        max_gap_s = options.max_gap_periods * typical_spacing(trajectory.time)
    ok = _bracketed(trajectory.time, meas.time, max_gap_s)
    both = meas.both() & ok[:, None]
    n_meas = int(np.any(both, axis=1).sum())
    if n_meas < options.min_measurements:
        raise SolverError(f"station {meas.lighthouse}: only {n_meas} measurements overlap the "
                          f"reference board path (need >= {options.min_measurements})")
    rows, cols = np.nonzero(both)
    P = trajectory.at(meas.time[rows])
    world = transform_points(P, board.positions[cols])
    measured = np.stack([meas.azimuth[rows, cols], meas.elevation[rows, cols]], axis=1)
    per_meas = np.bincount(rows, minlength=len(meas))
    seen = per_meas > 0
    rejected = np.zeros(len(meas), dtype=bool)
    evaluations = iterations = 0
    for fit in range(1, MAX_K2_FITS + 1):
        use = ~rejected[rows]
        T, res = _minimise_station(world[use], measured[use], T, options)
        evaluations, iterations = evaluations + int(res.nfev), iterations + int(res.nit)
        if fit == MAX_K2_FITS or not math.isfinite(options.outlier_mads):
            break
        d = _angle_errors((world - T[:3, 3]) @ T[:3, :3], measured)
        square = np.bincount(rows, weights=np.einsum("ij,ij->i", d, d), minlength=len(meas))
        now = np.zeros(len(meas), dtype=bool)
        now[seen] = outliers(np.sqrt(square[seen] / (2 * per_meas[seen])), options.outlier_mads)
        if np.array_equal(now, rejected):
            break
        rejected = now
    return Refinement(T, float(res.fun), evaluations, iterations, bool(res.success), n_meas,
                      int(rejected.sum()))


# --- the pipeline ---------------------------------------------------------------------------------


def hit_residuals(angles: Angles, board: Board, stations: Stations, trajectory: Trajectory
                  ) -> Residuals:
    """Per-hit residuals (measured - predicted, rad; weight 1) of a solution.

    Each hit is predicted from the board pose interpolated at its time (clamped at the
    ends) and its station's pose and model (factory calibration included).
    """
    idx = angles.check_board(board)
    T_board = trajectory.at(angles.time)
    pred = np.empty(len(angles))
    for k in stations.indices():
        sel = angles.lighthouse == k
        st = stations.stations[k]
        pred[sel] = predict(st.T_world_lh, T_board[sel], board.positions[idx[sel]],
                            angles.axis[sel], st.model)
    return Residuals(angles.time.copy(), angles.lighthouse.copy(), angles.axis.copy(),
                     angles.sensor.copy(), angles.angle - pred, np.ones(len(angles)))


@dataclass
class _StationData:
    """One station: the measurements K2 uses (rejected fits removed), its board poses."""

    meas: Measurements
    poses: BoardPoses
    model: StationModel = field(default_factory=StationModel)


def solve_paper(board: Board, angles: Angles, models: dict[int, StationModel] | None = None,
                reference: int | None = None, options: PaperOptions | None = None,
                progress: Progress | None = None) -> SolveResult:
    """Calibrate every station against the reference one with the paper's method.

    ``models`` (station index -> :class:`StationModel`) gives factory calibrations: measured
    angles are converted to ideal ones before the pipeline. ``reference`` defaults to the
    lowest station index present. Returns a :class:`SolveResult` with the stations in the
    reference frame (covariance None), the reference board path as trajectory, per-hit
    residuals, ``final_error`` = sum of the final K2 (rad^2) and ``iterations`` = sum of the
    K2 Nelder-Mead iterations. Raises :class:`InputError` for sensor ids not on the board and
    :class:`SolverError` when the data cannot determine the poses.
    """
    options = options or PaperOptions()
    models = models or {}
    timings: dict[str, float] = {}
    present = angles.stations()
    if reference is None:
        if not present:
            raise SolverError("the angles table is empty")
        reference = present[0]
    if reference not in present:
        raise SolverError(f"reference station {reference} never seen in the angles "
                          f"(stations present: {present})")
    if len(present) < 2:
        raise SolverError(f"only station {reference} seen: need at least two stations")
    angles.check_board(board)

    data: dict[int, _StationData] = {}
    for k in present:
        tic = _time.perf_counter()
        model = models.get(k, IDEAL)
        meas = to_ideal(reconstruct_measurements(
            angles.select(angles.lighthouse == k), board, options.reconstruction,
            max_gap_periods=options.max_gap_periods), model)
        timings["reconstruct"] = timings.get("reconstruct", 0.0) + _time.perf_counter() - tic
        tic = _time.perf_counter()
        fitted = estimate_board_poses(meas, board, options, progress)
        poses = reject_outlier_poses(fitted, options.outlier_mads)
        timings["board_poses"] = timings.get("board_poses", 0.0) + _time.perf_counter() - tic
        rejected = fitted.valid & ~poses.valid
        meas = meas.select(~rejected)
        if poses.valid.sum() < options.min_measurements:
            raise SolverError(
                f"station {k}: only {int(poses.valid.sum())} usable measurements (need >= "
                f"{options.min_measurements} with >= {options.min_sensors} sensors each)")
        data[k] = _StationData(meas, poses, model)

    master = data[reference].poses
    trajectory = master.path()
    result_stations = {reference: Station(np.eye(4), None, data[reference].model)}
    status, iterations, final_error = "converged", 0, 0.0
    warnings: list[str] = []
    slaves = [k for k in present if k != reference]
    for n, k in enumerate(slaves):
        if progress is not None:
            progress("station poses", n, len(slaves))
        tic = _time.perf_counter()
        T = initial_station_pose(master, data[k].poses, board, options)
        timings["kabsch"] = timings.get("kabsch", 0.0) + _time.perf_counter() - tic
        if options.refine:
            tic = _time.perf_counter()
            ref = refine_station_pose(T, data[k].meas, trajectory, board, options)
            timings["refine"] = timings.get("refine", 0.0) + _time.perf_counter() - tic
            T, iterations, final_error = ref.T_ref_lh, iterations + ref.iterations, \
                final_error + ref.cost
            if not ref.converged:
                status = "max_iterations"
                warnings.append(f"station {k}: K2 refinement stopped at {ref.evaluations} "
                                f"evaluations before converging")
        result_stations[k] = Station(T, None, data[k].model)
    if progress is not None:
        progress("station poses", len(slaves), len(slaves))
    stations = Stations(reference, result_stations)
    tic = _time.perf_counter()
    residuals = hit_residuals(angles, board, stations, trajectory)
    timings["residuals"] = _time.perf_counter() - tic
    if not options.refine:
        final_error = float("nan")
    return SolveResult("paper", stations, trajectory, residuals, status, iterations,
                       final_error, timings, warnings)
