"""Planar PnP: single-station board poses from sensor directions (vectorised over many
measurements), and what every pose solver of this family shares (:class:`PnPResult`, the
facing test :func:`facing_fraction`).

A station is a pinhole camera looking along +x: a point's ideal angles give the normalised
image coordinates ``(y/x, z/x) = (tan azimuth, tan elevation)``. Each measurement (one
azimuth and one elevation sweep of one station) gives a board pose ``T_lh_board`` by a
homography on the board's dominant plane, refined by Gauss-Newton with Huber weights on the
full station model. Both solutions of the planar mirror ambiguity are refined and the better
one is kept. Curved boards whose sensors no plane fits well (the Vive Tracker) are better
served by the multi-start solver in :mod:`lhgraph.estimation.init.pnp_nonplanar`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.geometry.transforms import cross, make_pose, se3_exp, so3_exp
from lhgraph.model.station import IDEAL, StationModel, board_jacobian, sweep_angle

Array = NDArray[np.float64]

# Gauss-Newton iterations both mirror twins get before the better one is kept
_CANDIDATE_ITERATIONS = 4

# camera coordinates (X_c, Y_c, Z_c) = (y, z, x) of the station frame
_P_CAM_LH = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class PnPResult:
    """Board poses ``T_lh_board`` (M, 4, 4), rms angle residual (rad) and sensors used."""

    T_lh_board: Array
    rms_rad: Array
    n_sensors: NDArray[np.int64]

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Measurements with a finite pose."""
        return np.isfinite(self.rms_rad)


def _seen_planes(positions: Array, normals: Array, mask: NDArray[np.bool_]
                 ) -> tuple[Array, Array]:
    """Per measurement, centroid ``c`` (M, 3) and basis ``B`` (M, 3, 3) (columns e1, e2, n)
    of the plane that best fits the *seen* sensors; n faces like their mean normal. On a
    curved board each station mostly sees one face, so this plane beats the whole board's."""
    w = mask.astype(float)
    count = np.maximum(w.sum(axis=1, keepdims=True), 1.0)
    c = (w @ positions) / count
    d = positions[None] - c[:, None]
    cov = np.einsum("ms,msi,msj->mij", w, d, d)
    _, vecs = np.linalg.eigh(cov)  # ascending: the plane normal is the first column
    B = vecs[..., ::-1].copy()
    n_mean = (w @ normals) / count
    flip = np.sum(B[..., 2] * n_mean, axis=1) < 0
    B[flip, :, 2] *= -1
    B[..., 1] = cross(B[..., 2], B[..., 0])  # right-handed
    return c, B


def _homography_poses(uv: Array, mask: NDArray[np.bool_], plane_xy: Array) -> Array:
    """Camera-from-plane poses (M, 4, 4) by a DLT homography per measurement; ``plane_xy``
    (M, S, 2) are the sensors' plane coordinates."""
    scale = np.abs(plane_xy).max()
    X, Y = plane_xy[..., 0] / scale, plane_xy[..., 1] / scale
    u, v = np.nan_to_num(uv[..., 0]), np.nan_to_num(uv[..., 1])
    M, S = u.shape
    X, Y = np.broadcast_to(X, (M, S)), np.broadcast_to(Y, (M, S))
    one, zero = np.ones((M, S)), np.zeros((M, S))
    A = np.zeros((M, 2 * S, 9))
    A[:, 0::2, :] = np.stack([X, Y, one, zero, zero, zero, -u * X, -u * Y, -u], axis=-1)
    A[:, 1::2, :] = np.stack([zero, zero, zero, X, Y, one, -v * X, -v * Y, -v], axis=-1)
    weights = mask.astype(float)
    for _ in range(4):  # iteratively reweighted DLT: Cauchy weights on the transfer error
        Aw = A * np.repeat(weights, 2, axis=1)[..., None]
        _, vecs = np.linalg.eigh(np.swapaxes(Aw, 1, 2) @ Aw)  # 9x9 normal matrix, not SVD
        h = vecs[:, :, 0]
        proj = np.stack([X, Y, one], axis=-1) @ h.reshape(M, 3, 3).transpose(0, 2, 1)
        err = np.hypot(proj[..., 0] / proj[..., 2] - u, proj[..., 1] / proj[..., 2] - v)
        typical = np.nanmedian(np.where(mask, err, np.nan), axis=1, keepdims=True)
        scale_err = np.maximum(1.5 * typical, 1e-3)
        weights = mask / (1.0 + (err / scale_err) ** 2)
    H = h.reshape(M, 3, 3) * np.array([1 / scale, 1 / scale, 1.0])
    h1, h2, h3 = H[:, :, 0], H[:, :, 1], H[:, :, 2]
    lam = 2.0 / (np.linalg.norm(h1, axis=1) + np.linalg.norm(h2, axis=1))
    lam *= np.where(h3[:, 2] < 0, -1.0, 1.0)
    r1, r2 = lam[:, None] * h1, lam[:, None] * h2
    R = np.stack([r1, r2, cross(r1, r2)], axis=-1)
    U, _, Wt = np.linalg.svd(R)
    R = U @ Wt
    R[np.linalg.det(R) < 0] *= -1  # degenerate fits only; refined or rejected later
    t = lam[:, None] * h3
    return make_pose(R, t)


def _refine(
    T: Array, meas: Array, mask: NDArray[np.bool_], positions: Array, model: StationModel,
    iterations: int, huber_rad: float,
) -> tuple[Array, Array, Array]:
    """Gauss-Newton (Huber-weighted) on the full model, over the seen sensors only; each
    measurement stops as soon as its own step is below 1e-8.

    Returns poses, rms residual (rad) and each sensor's larger absolute residual (M, S).
    """
    M, S = mask.shape
    T = T.copy()
    mi, si = np.nonzero(mask)  # seen (measurement, sensor) entries, grouped by measurement
    s_seen, z_seen = positions[si], meas[mi, si]
    counts = mask.sum(axis=1)
    active = counts > 0
    I6 = np.eye(6)
    for _ in range(iterations):
        act = np.flatnonzero(active)
        if len(act) == 0:
            break
        e = active[mi]
        r, H = _residuals(T[mi[e]], s_seen[e], z_seen[e], model, jacobians=True)
        w = np.minimum(1.0, huber_rad / np.maximum(np.abs(r), 1e-15))
        Hw = H * w[..., None]
        offsets = np.r_[0, np.cumsum(counts[act])[:-1]]
        JtJ = np.add.reduceat(np.swapaxes(Hw, 1, 2) @ H, offsets, axis=0)
        Jtr = np.add.reduceat(np.einsum("eai,ea->ei", Hw, r), offsets, axis=0)
        # degenerate views (a sensor on a rotor axis, too few sensors) must not stop the rest
        bad = ~(np.isfinite(JtJ).all(axis=(1, 2)) & np.isfinite(Jtr).all(axis=1))
        JtJ[bad], Jtr[bad] = I6, 0.0
        JtJ += (1e-9 * np.trace(JtJ, axis1=1, axis2=2)[:, None, None] + 1e-12) * I6
        try:
            delta = -np.linalg.solve(JtJ, Jtr[..., None])[..., 0]
        except np.linalg.LinAlgError:  # rare: fall back to the (slower) pseudo-inverse
            delta = -(np.linalg.pinv(JtJ) @ Jtr[..., None])[..., 0]
        T[act] = T[act] @ se3_exp(delta)
        active[act[np.max(np.abs(delta), axis=1) < 1e-8]] = False
    r = _residuals(T[mi], s_seen, z_seen, model)
    rms = np.sqrt(np.bincount(mi, np.sum(r**2, axis=1), minlength=M)
                  / np.maximum(2 * counts, 1))
    worst = np.zeros((M, S))
    worst[mi, si] = np.max(np.abs(r), axis=1)
    return T, rms, worst


def _residuals(T_lh_board: Array, s: Array, z: Array, model: StationModel,
               jacobians: bool = False) -> Array | tuple[Array, Array]:
    """Azimuth and elevation residuals (E, 2) of sensors ``s`` at poses ``T_lh_board`` (E, ...)
    against measured ``z`` (E, 2), with board-pose Jacobians (E, 2, 6) when asked (right
    perturbations ``[omega, v]``, as :func:`lhgraph.model.lh1.predict`)."""
    R = T_lh_board[..., :3, :3]
    p = np.einsum("eij,ej->ei", R, s) + T_lh_board[..., :3, 3]
    p2 = np.concatenate([p, p])
    axis = np.repeat(np.array([0, 1]), len(s))
    if not jacobians:
        return sweep_angle(p2, axis, model).reshape(2, -1).T - z
    angle, J_p = sweep_angle(p2, axis, model, jacobian=True)
    r = angle.reshape(2, -1).T - z
    return r, np.swapaxes(board_jacobian(J_p.reshape(2, -1, 3), R, s), 0, 1)


def facing_fraction(T_lh_board: Array, positions: Array, normals: Array,
                    seen: NDArray[np.bool_] | None = None) -> Array:
    """Fraction of sensors whose normal points toward the station, per pose ``(M, 4, 4)``.

    ``positions``/``normals`` (S, 3) in the board frame; ``seen`` (M, S) restricts each pose
    to the sensors it was fitted on (default: all). A photodiode only sees a station in front
    of it, so a correct pose has every seen sensor facing (1.0); a mirror solution ~0.
    """
    p = T_lh_board[:, None, :3, :3] @ positions[None, :, :, None]
    p = p[..., 0] + T_lh_board[:, None, :3, 3]
    n = (T_lh_board[:, None, :3, :3] @ normals[None, :, :, None])[..., 0]
    toward = np.sum(n * p, axis=-1) < 0
    seen = np.ones(toward.shape, dtype=bool) if seen is None else seen
    return np.sum(toward & seen, axis=1) / np.maximum(seen.sum(axis=1), 1)


def _twin_candidates(
    uv: Array, meas: Array, mask: NDArray[np.bool_], positions: Array, normals: Array,
    model: StationModel, iterations: int, huber_rad: float,
) -> tuple[tuple[Array, Array, Array], tuple[Array, Array, Array]]:
    """Homography pose and its planar mirror, each refined ``iterations`` times: (poses, rms,
    each sensor's residual) of twin a, then of twin b (:func:`_refine`)."""
    c, B = _seen_planes(positions, normals, mask)
    plane_xy = np.einsum("msi,mij->msj", positions[None] - c[:, None], B[..., :2])
    T_cam_plane = _homography_poses(uv, mask, plane_xy)
    # T_lh_board = P^T T_cam_plane [B^T, -B^T c]
    Bt = np.swapaxes(B, 1, 2)
    T_plane_board = make_pose(Bt, -(Bt @ c[..., None])[..., 0])
    T_lh_cam = make_pose(_P_CAM_LH.T, np.zeros(3))
    T0 = T_lh_cam @ T_cam_plane @ T_plane_board
    # mirror candidate: reflect the board normal about the line of sight, rotate to match
    n_lh = (T0[:, :3, :3] @ B[..., 2, None])[..., 0]
    d = T0[:, :3, 3] / np.linalg.norm(T0[:, :3, 3], axis=1, keepdims=True)
    n_alt = 2 * np.sum(n_lh * d, axis=1, keepdims=True) * d - n_lh
    axis = cross(n_lh, n_alt)
    angle = np.arctan2(np.linalg.norm(axis, axis=1), np.sum(n_lh * n_alt, axis=1))
    axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
    R_rot = so3_exp(axis * angle[:, None])
    c_lh = (T0[:, :3, :3] @ c[..., None])[..., 0] + T0[:, :3, 3]
    T1 = T0.copy()
    T1[:, :3, :3] = R_rot @ T0[:, :3, :3]
    T1[:, :3, 3] = c_lh - (T1[:, :3, :3] @ c[..., None])[..., 0]
    return (_refine(T0, meas, mask, positions, model, iterations, huber_rad),
            _refine(T1, meas, mask, positions, model, iterations, huber_rad))


def _solve_candidates(
    uv: Array, meas: Array, mask: NDArray[np.bool_], positions: Array, normals: Array,
    model: StationModel, iterations: int, huber_rad: float,
) -> tuple[Array, Array, Array]:
    """Homography pose and its planar mirror, both refined; the better one per measurement."""
    # both twins get a few iterations, only the better one the rest
    first = min(iterations, _CANDIDATE_ITERATIONS)
    (Ta, rms_a, _), (Tb, rms_b, _) = _twin_candidates(uv, meas, mask, positions, normals,
                                                      model, first, huber_rad)
    # a seen sensor must face the station: that rejects the wrong twin on curved boards
    face_a = facing_fraction(Ta, positions, normals, mask) > 0.8
    face_b = facing_fraction(Tb, positions, normals, mask) > 0.8
    better_b = np.where(face_a == face_b, (rms_b < rms_a) | ~np.isfinite(rms_a), face_b)
    T = np.where(better_b[:, None, None], Tb, Ta)
    return _refine(T, meas, mask, positions, model, iterations - first, huber_rad)


def _seen_measurements(azimuth: Array, elevation: Array, min_sensors: int
                       ) -> tuple[NDArray[np.int64], NDArray[np.bool_], Array, Array,
                                  NDArray[np.bool_]]:
    """What both planar solvers start from: sensors seen on both axes per measurement ``n``
    (M,), the measurements with at least ``min_sensors`` of them ``ok`` (M,), and for those
    the angle pairs ``meas`` (K, S, 2; 0 where unseen), their tangents ``uv`` and the seen
    mask (K, S)."""
    azimuth = np.asarray(azimuth, dtype=float)
    elevation = np.asarray(elevation, dtype=float)
    mask = np.isfinite(azimuth) & np.isfinite(elevation)
    n = mask.sum(axis=1)
    ok = n >= min_sensors
    az, el = azimuth[ok], elevation[ok]
    meas = np.stack([np.nan_to_num(az), np.nan_to_num(el)], axis=-1)
    uv = np.stack([np.tan(az), np.tan(el)], axis=-1)
    return n, ok, meas, uv, mask[ok]


@dataclass(frozen=True)
class PlanarTwins:
    """Both solutions of the planar mirror ambiguity per measurement: ``T_lh_board``
    (M, 2, 4, 4), ``rms_rad`` (M, 2) (NaN: no pose), ``facing`` (M, 2) the fraction of
    sensors kept facing the station, ``n_sensors`` (M,) sensors kept (seen on both axes, less
    the outliers dropped)."""

    T_lh_board: Array
    rms_rad: Array
    facing: Array
    n_sensors: NDArray[np.int64]


def planar_twins(azimuth: Array, elevation: Array, positions: Array, normals: Array,
                 model: StationModel = IDEAL, iterations: int = 15, min_sensors: int = 4,
                 huber_rad: float = 1e-3, outlier_factor: float = 5.0,
                 outlier_floor_rad: float = 3e-3) -> PlanarTwins:
    """Both mirror twins of every measurement's planar pose, each refined on the full model.

    Angles ``(M, S)`` (rad, NaN = not seen) of sensors ``positions``/``normals`` (S, 3),
    board frame. With few sensors (a 4-diode deck far away) the twins fit about equally
    well, so the choice is left to the caller (:func:`~lhgraph.estimation.init.twins.
    resolve_twins` picks the temporally consistent one). Sensors whose residual under the
    better twin exceeds ``outlier_factor`` times the measurement's median (and
    ``outlier_floor_rad``: a reflection) are dropped and both twins solved again, as in
    :func:`board_poses`, while ``min_sensors`` remain; ``rms_rad`` and ``n_sensors`` are
    over the sensors kept. Measurements with fewer than ``min_sensors`` sensors on both
    axes, or a twin behind the station, get NaN.
    """
    n, ok, meas, uv, mk = _seen_measurements(azimuth, elevation, min_sensors)
    M = len(n)
    T_out = np.full((M, 2, 4, 4), np.nan)
    rms_out = np.full((M, 2), np.nan)
    facing = np.zeros((M, 2))
    n_out = n.copy()
    if np.any(ok):
        used = mk
        for _ in range(2):  # the second round drops gross outliers (reflections)
            solved = used  # the sensors the poses below are fitted to
            (Ta, rms_a, worst_a), (Tb, rms_b, worst_b) = _twin_candidates(
                uv, meas, solved, positions, normals, model, iterations, huber_rad)
            worst = np.where((rms_b < rms_a)[:, None], worst_b, worst_a)
            typical = np.nanmedian(np.where(used, worst, np.nan), axis=1, keepdims=True)
            inlier = mk & (worst < np.maximum(outlier_factor * typical, outlier_floor_rad))
            kept = np.where((inlier.sum(axis=1) >= min_sensors)[:, None], inlier, mk)
            if np.array_equal(kept, used):
                break
            used = kept
        T = np.stack([Ta, Tb], axis=1)
        rms = np.stack([rms_a, rms_b], axis=1)
        front = T[:, :, 0, 3] > 0
        T_out[ok] = np.where(front[..., None, None], T, np.nan)
        rms_out[ok] = np.where(front, rms, np.nan)
        facing[ok] = np.stack([facing_fraction(Ta, positions, normals, solved),
                               facing_fraction(Tb, positions, normals, solved)], axis=1)
        n_out[ok] = solved.sum(axis=1)
    return PlanarTwins(T_out, rms_out, facing, n_out)


def board_poses(
    azimuth: Array,
    elevation: Array,
    positions: Array,
    normals: Array,
    model: StationModel = IDEAL,
    iterations: int = 15,
    min_sensors: int = 5,
    huber_rad: float = 1e-3,
    outlier_factor: float = 5.0,
    outlier_floor_rad: float = 3e-3,
) -> PnPResult:
    """Board poses ``T_lh_board`` from measured angles ``(M, S)`` (rad, NaN = not seen).

    ``positions``/``normals`` (S, 3) are the board sensors (board frame). Measurements with
    fewer than ``min_sensors`` sensors seen on both axes get NaN poses and rms. Sensors whose
    residual exceeds ``outlier_factor`` times the measurement's median (and
    ``outlier_floor_rad``) are dropped and the pose solved again; ``rms_rad`` is over the
    sensors kept.
    """
    n, ok, meas, uv, mk = _seen_measurements(azimuth, elevation, min_sensors)
    M = len(n)
    T_out = np.full((M, 4, 4), np.nan)
    rms_out = np.full(M, np.nan)
    if not np.any(ok):
        return PnPResult(T_out, rms_out, n)
    used = mk
    for _ in range(2):  # the second round drops gross outliers (reflections)
        T, rms, worst = _solve_candidates(uv, meas, used, positions, normals, model,
                                          iterations, huber_rad)
        typical = np.nanmedian(np.where(used, worst, np.nan), axis=1, keepdims=True)
        inlier = mk & (worst < np.maximum(outlier_factor * typical, outlier_floor_rad))
        kept = np.where((inlier.sum(axis=1) >= min_sensors)[:, None], inlier, mk)
        if np.array_equal(kept, used):
            break  # no outliers to drop
        used = kept
    in_front = T[:, 0, 3] > 0
    T_out[ok] = np.where(in_front[:, None, None], T, np.nan)
    rms_out[ok] = np.where(in_front, rms, np.nan)
    return PnPResult(T_out, rms_out, n)
