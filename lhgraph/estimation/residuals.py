"""Pure, vectorised residuals of the factor graph with their analytic Jacobians.

Board state k (time ``t_k``): pose ``T_world_board`` X_k and body twist V_k = ``[omega, v]``
(rad/s, m/s, board frame). A hit at time ``t_i`` sees the board at
``X_k Exp(dt_i V_k)``, ``dt_i = t_i - t_k``, so diodes hit at different times within one
sweep are propagated by the state's velocity. Jacobians are w.r.t. right perturbations
(GTSAM convention) of X, plain perturbations of V and right perturbations of the stations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.geometry.transforms import cross, inverse, se3_log, skew
from lhgraph.model.station import StationModel, board_jacobian, sweep_angle

Array = NDArray[np.float64]
_EYE6 = np.eye(6)
MIN_PRIOR_DT_S = 1e-3  # shortest step the motion prior's covariance assumes (s)


def adjoint(T: Array) -> Array:
    """Adjoint matrices ``(..., 6, 6)`` of poses ``(..., 4, 4)`` for ``[omega, v]`` tangents."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    Ad = np.zeros(T.shape[:-2] + (6, 6))
    Ad[..., :3, :3] = R
    Ad[..., 3:, 3:] = R
    Ad[..., 3:, :3] = skew(t) @ R
    return Ad


def ad_matrix(xi: Array) -> Array:
    """Lie-bracket matrices ``ad(xi)`` ``(..., 6, 6)`` of tangents ``(..., 6)``."""
    W, U = skew(xi[..., :3]), skew(xi[..., 3:])
    A = np.zeros(xi.shape[:-1] + (6, 6))
    A[..., :3, :3] = W
    A[..., 3:, 3:] = W
    A[..., 3:, :3] = U
    return A


def right_jacobian_inverse(xi: Array) -> Array:
    """Inverse SE(3) right Jacobian (Logmap derivative), Bernoulli series to fourth order."""
    A = ad_matrix(xi)
    A2 = A @ A
    return _EYE6 + A / 2 + A2 / 12 - A2 @ A2 / 720


@dataclass(frozen=True)
class BearingHits:
    """Every hit of a capture, arranged for vectorised evaluation.

    ``state`` board-state index, ``station`` station slot (index into the station pose
    array), ``s_board`` (N, 3) sensor position (m, board frame), ``axis``, ``dt`` = hit time
    minus state time (s), ``angle`` measured (rad).
    """

    state: NDArray[np.int64]
    station: NDArray[np.int64]
    s_board: Array
    axis: NDArray[np.int64]
    dt: Array
    angle: Array


def bearing_residuals(
    hits: BearingHits,
    X: Array,
    V: Array,
    L: Array,
    models: list[StationModel],
    jacobians: bool = True,
) -> tuple[Array, Array | None, Array | None, Array | None]:
    """Angle residual (predicted - measured, rad) of every hit, and ``H_X, H_V, H_L`` (N, 6).

    ``X`` (K, 4, 4) board poses ``T_world_board``, ``V`` (K, 6) twists, ``L`` (S, 4, 4)
    station poses ``T_world_lh``; ``models[s]`` is station slot s's model. A hit ``dt`` after
    its state sees the sensor at ``s' = s + dt (omega x s + v)`` in the state's board frame
    (first order in ``dt V``: over the < 0.2 ms spread of one sweep the neglected term is
    below 1e-8 m); Jacobians are exact for this model.
    """
    # station-from-board transform of every (state, station) pair (far fewer than hits),
    # gathered per hit
    R_l = np.swapaxes(L[:, :3, :3], 1, 2)                                  # (S, 3, 3)
    R_pair = R_l[None] @ X[:, None, :3, :3]                                 # (K, S, 3, 3)
    t_pair = np.einsum("sij,ksj->ksi", R_l, X[:, None, :3, 3] - L[None, :, :3, 3])
    R_lb = R_pair[hits.state, hits.station]
    t_lb = t_pair[hits.state, hits.station]
    Vh = V[hits.state]
    s_board = hits.s_board
    s_moved = s_board + hits.dt[:, None] * (cross(Vh[:, :3], s_board) + Vh[:, 3:])
    p_lh = np.einsum("nij,nj->ni", R_lb, s_moved) + t_lb
    n = len(hits.angle)
    r = np.empty(n)
    J_p = np.empty((n, 3)) if jacobians else None
    for slot, model in enumerate(models):
        m = hits.station == slot
        if not np.any(m):
            continue
        if jacobians:
            r[m], J_p[m] = sweep_angle(p_lh[m], hits.axis[m], model, jacobian=True)
        else:
            r[m] = sweep_angle(p_lh[m], hits.axis[m], model)
    r -= hits.angle
    if not jacobians:
        return r, None, None, None
    # d p_lh / d xi_lh = [[p]x, -I];  d p_lh / d xi_X = R_lb [-[s']x, I]
    H_L = np.concatenate([cross(J_p, p_lh), -J_p], axis=1)
    H_X = board_jacobian(J_p, R_lb, s_moved)
    # d s' / d V = dt [-[s]x, I]: the board Jacobian at s, scaled by dt
    H_V = board_jacobian(J_p, R_lb, s_board) * hits.dt[:, None]
    return r, H_X, H_V, H_L


def wnoa_covariance(dt: Array, qc_rot: float, qc_pos: float) -> Array:
    """Covariance ``(K, 12, 12)`` of the white-noise-on-acceleration prior over steps ``dt``.

    ``qc_rot`` (rad^2/s^3) and ``qc_pos`` (m^2/s^3) are the power spectral densities of the
    angular and linear acceleration noise. Steps shorter than ``MIN_PRIOR_DT_S`` count as that
    long: two nearly simultaneous sweeps (stations whose time stamps overlap) would otherwise
    get a near-singular covariance (``dt^3``) and an indeterminate linear system.
    """
    Qc = np.diag([qc_rot] * 3 + [qc_pos] * 3)
    dt = np.maximum(np.asarray(dt, dtype=float), MIN_PRIOR_DT_S)[:, None, None]
    Q = np.zeros((dt.shape[0], 12, 12))
    Q[:, :6, :6] = dt**3 / 3 * Qc
    Q[:, :6, 6:] = dt**2 / 2 * Qc
    Q[:, 6:, :6] = dt**2 / 2 * Qc
    Q[:, 6:, 6:] = dt * Qc
    return Q


def motion_residuals(
    X0: Array, V0: Array, X1: Array, V1: Array, dt: Array, jacobians: bool = True
) -> tuple[Array, tuple[Array, Array, Array, Array] | None]:
    """Constant-velocity (WNOA) prior residuals ``(K, 12)`` between consecutive states.

    ``e = [Log(X0^-1 X1) - dt V0, V1 - V0]`` (body twists; over one 8 ms step the frame
    change of the twist is negligible); Jacobians ``(H_X0, H_V0, H_X1, H_V1)``, each
    ``(K, 12, 6)``.
    """
    D = inverse(X0) @ X1
    xi = se3_log(D)
    e = np.concatenate([xi - dt[:, None] * V0, V1 - V0], axis=1)
    if not jacobians:
        return e, None
    K = len(dt)
    eye = np.broadcast_to(_EYE6, (K, 6, 6))
    zero = np.zeros((K, 6, 6))
    Jinv = right_jacobian_inverse(xi)
    H_X0 = np.concatenate([-Jinv @ adjoint(inverse(D)), zero], axis=1)
    H_X1 = np.concatenate([Jinv, zero], axis=1)
    H_V0 = np.concatenate([-dt[:, None, None] * eye, -eye], axis=1)
    H_V1 = np.concatenate([zero, eye], axis=1)
    return e, (H_X0, H_V0, H_X1, H_V1)


def gyro_residuals(V: Array, bias: Array, rate: Array) -> Array:
    """Gyro residuals ``(K, 3)``: state k's angular rate ``V[k, :3]`` plus the gyro ``bias``
    (3,) minus the gyro's reading ``rate[k]`` at the state's time (rad/s, board frame). Linear:
    the Jacobian is ``[I 0]`` on the twist and ``I`` on the bias."""
    return V[:, :3] + bias - rate


def accel_residuals(
    X0: Array, V0: Array, X1: Array, V1: Array, dt: Array, force: Array, accel_bias: Array,
    gravity: Array, jacobians: bool = True,
) -> tuple[Array, tuple[Array, Array, Array, Array, Array, Array] | None]:
    """Accelerometer residuals ``(K, 3)`` (m/s^2, world frame) between consecutive states.

    The world-frame velocity ``u = R v`` changes over the step by the mean acceleration:
    ``e = (R1 v1 - R0 v0) / dt - R0 (force - accel_bias) - gravity``, ``force`` (K, 3) the
    specific force over the step in state 0's board frame (what an accelerometer at the board
    origin reads, +9.81 m/s^2 up at rest), ``accel_bias`` (3,) its bias, ``gravity`` (3,) the
    gravity vector in the world (pointing down). Jacobians ``(H_X0, H_V0, H_X1, H_V1, H_bias,
    H_gravity)``: ``(K, 3, 6)`` for the poses (right perturbations; the translation columns
    are zero) and twists, ``(K, 3, 3)`` for the bias and gravity."""
    R0, R1 = X0[:, :3, :3], X1[:, :3, :3]
    v0, v1 = V0[:, 3:], V1[:, 3:]
    inv_dt = 1.0 / dt[:, None]
    specific = force - accel_bias
    e = (np.einsum("kij,kj->ki", R1, v1) - np.einsum("kij,kj->ki", R0, v0)) * inv_dt \
        - np.einsum("kij,kj->ki", R0, specific) - gravity
    if not jacobians:
        return e, None
    K = len(dt)
    H_X0 = np.zeros((K, 3, 6))
    H_X1 = np.zeros((K, 3, 6))
    H_V0 = np.zeros((K, 3, 6))
    H_V1 = np.zeros((K, 3, 6))
    # d(R exp(theta) a)/d theta = -R [a]x
    H_X0[:, :, :3] = R0 @ skew(v0 * inv_dt + specific)
    H_X1[:, :, :3] = -R1 @ skew(v1 * inv_dt)
    H_V0[:, :, 3:] = -R0 * inv_dt[:, :, None]
    H_V1[:, :, 3:] = R1 * inv_dt[:, :, None]
    H_bias = R0.copy()
    H_gravity = np.broadcast_to(-np.eye(3), (K, 3, 3)).copy()
    return e, (H_X0, H_V0, H_X1, H_V1, H_bias, H_gravity)
