"""Vectorised rigid-body helpers (numpy), in GTSAM's conventions.

Poses are 4x4 homogeneous matrices ``T_a_b`` mapping b-frame points into frame a; stacks of
poses are ``(..., 4, 4)``. Tangent vectors are ``[omega, v]`` (rotation first) and
perturbations are on the right, ``T * Exp(xi)``, as for ``gtsam.Pose3``. Quaternions are
``[w, x, y, z]``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

_SMALL = 1e-8


def cross(a: ArrayLike, b: ArrayLike) -> Array:
    """Cross products of vectors ``(..., 3)`` (broadcasting); faster than ``np.cross`` on
    both the small arrays of single factors and large broadcast stacks."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def skew(v: ArrayLike) -> Array:
    """Cross-product matrices ``[v]x`` of vectors ``(..., 3)`` -> ``(..., 3, 3)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def so3_exp(omega: ArrayLike) -> Array:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` (rad), Rodrigues."""
    omega = np.asarray(omega, dtype=float)
    theta = np.linalg.norm(omega, axis=-1)[..., None, None]
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(th) / th)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    W = skew(omega)
    return np.eye(3) + a * W + b * (W @ W)


def so3_right_jacobian(phi: ArrayLike, inverse: bool = False) -> Array:
    """SO(3) right Jacobians ``J_r(phi)`` ``(..., 3, 3)`` of rotation vectors ``(..., 3)``
    (``Exp(phi + d) = Exp(phi) Exp(J_r(phi) d)`` to first order), or their inverses
    (``Log(Exp(phi) Exp(d)) = phi + J_r(phi)^-1 d``); closed forms, series near 0."""
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    W = skew(phi)
    if inverse:
        c = np.where(small, 1.0 / 12.0,
                     1.0 / th**2 - (1.0 + np.cos(th)) / (2.0 * th * np.sin(th)))
        return np.eye(3) + 0.5 * W + c * (W @ W)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (th - np.sin(th)) / th**3)
    return np.eye(3) - a * W + b * (W @ W)


def so3_log(R: ArrayLike) -> Array:
    """Rotation vectors ``(..., 3)`` (rad) of rotation matrices ``(..., 3, 3)``.

    From the trace and the skew part; within 1e-3 rad of 180 degrees (where that loses
    precision) from the quaternion instead.
    """
    R = np.asarray(R, dtype=float)
    c = np.minimum(np.maximum((R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0) / 2.0, -1.0),
                   1.0)
    theta = np.arccos(c)
    w = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                  R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    small = theta < 1e-4
    scale = np.where(small, 0.5 + theta**2 / 12.0,
                     theta / (2.0 * np.sin(np.where(small, 1.0, theta))))
    out = w * scale[..., None]
    near_pi = theta > np.pi - 1e-3
    if np.any(near_pi):
        q = matrix_to_quat(R[near_pi])  # w >= 0: angle in [0, pi]
        s = np.linalg.norm(q[..., 1:], axis=-1)
        out[near_pi] = q[..., 1:] * (2.0 * np.arctan2(s, q[..., 0]) / s)[..., None]
    return out


def so3_left_jacobian(omega: ArrayLike) -> Array:
    """Left Jacobian ``J_l(omega)`` of SO(3), ``(..., 3, 3)``; ``t = J_l v`` in ``Pose3.Expmap``."""
    omega = np.asarray(omega, dtype=float)
    theta = np.linalg.norm(omega, axis=-1)[..., None, None]
    W = skew(omega)
    small = theta < 1e-5
    th = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (th - np.sin(th)) / th**3)
    return np.eye(3) + a * W + b * (W @ W)


def se3_exp(xi: ArrayLike) -> Array:
    """Poses ``(..., 4, 4)`` from tangent vectors ``(..., 6)`` = ``[omega, v]`` (gtsam Expmap)."""
    xi = np.asarray(xi, dtype=float)
    T = np.zeros(xi.shape[:-1] + (4, 4))
    T[..., :3, :3] = so3_exp(xi[..., :3])
    T[..., :3, 3] = np.einsum("...ij,...j->...i", so3_left_jacobian(xi[..., :3]), xi[..., 3:])
    T[..., 3, 3] = 1.0
    return T


def se3_log(T: ArrayLike) -> Array:
    """Tangent vectors ``(..., 6)`` = ``[omega, v]`` of poses ``(..., 4, 4)`` (gtsam Logmap)."""
    T = np.asarray(T, dtype=float)
    omega = so3_log(T[..., :3, :3])
    # v = J_l(omega)^-1 t = t - [omega]x t / 2 + c [omega]x^2 t
    theta2 = np.sum(omega * omega, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    c = np.where(small, 1.0 / 12.0 + theta2 / 720.0,
                 (1.0 - th * np.sin(th) / (2.0 * (1.0 - np.cos(th)))) / th**2)
    t = T[..., :3, 3]
    wt = cross(omega, t)
    v = t - wt / 2.0 + c[..., None] * cross(omega, wt)
    return np.concatenate([omega, v], axis=-1)


def make_pose(R: ArrayLike, t: ArrayLike) -> Array:
    """Stack rotation ``(..., 3, 3)`` and translation ``(..., 3)`` into ``(..., 4, 4)``."""
    R = np.asarray(R, dtype=float)
    t = np.asarray(t, dtype=float)
    shape = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def inverse(T: ArrayLike) -> Array:
    """Inverse of poses ``(..., 4, 4)``."""
    T = np.asarray(T, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return make_pose(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def transform_points(T: ArrayLike, p: ArrayLike) -> Array:
    """Apply poses ``(..., 4, 4)`` to points ``(..., 3)`` (broadcasting)."""
    T = np.asarray(T, dtype=float)
    p = np.asarray(p, dtype=float)
    return np.einsum("...ij,...j->...i", T[..., :3, :3], p) + T[..., :3, 3]


def quat_to_matrix(q_wxyz: ArrayLike) -> Array:
    """Rotation matrices from quaternions ``[w, x, y, z]`` (normalised first)."""
    q = np.asarray(q_wxyz, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = (q[..., i] for i in range(4))
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat(R: ArrayLike) -> Array:
    """Quaternions ``[w, x, y, z]`` (w >= 0) of rotation matrices ``(..., 3, 3)``.

    Shepperd's method: each quaternion is read from the largest of its four squared
    components, so it stays accurate near 180 degrees.
    """
    R = np.asarray(R, dtype=float)
    m = R.reshape(-1, 3, 3)
    tr = np.trace(m, axis1=1, axis2=2)
    diag = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    k = np.argmax(diag, axis=1)
    q = np.empty((len(m), 4))
    r = np.sqrt(np.maximum(1.0 + 2.0 * diag[np.arange(len(m)), k] - tr, 1e-300))
    # k = 0: w largest
    i = k == 0
    q[i] = np.stack([r[i] / 2, (m[i, 2, 1] - m[i, 1, 2]) / (2 * r[i]),
                     (m[i, 0, 2] - m[i, 2, 0]) / (2 * r[i]),
                     (m[i, 1, 0] - m[i, 0, 1]) / (2 * r[i])], axis=1)
    i = k == 1
    q[i] = np.stack([(m[i, 2, 1] - m[i, 1, 2]) / (2 * r[i]), r[i] / 2,
                     (m[i, 0, 1] + m[i, 1, 0]) / (2 * r[i]),
                     (m[i, 0, 2] + m[i, 2, 0]) / (2 * r[i])], axis=1)
    i = k == 2
    q[i] = np.stack([(m[i, 0, 2] - m[i, 2, 0]) / (2 * r[i]),
                     (m[i, 0, 1] + m[i, 1, 0]) / (2 * r[i]), r[i] / 2,
                     (m[i, 1, 2] + m[i, 2, 1]) / (2 * r[i])], axis=1)
    i = k == 3
    q[i] = np.stack([(m[i, 1, 0] - m[i, 0, 1]) / (2 * r[i]),
                     (m[i, 0, 2] + m[i, 2, 0]) / (2 * r[i]),
                     (m[i, 1, 2] + m[i, 2, 1]) / (2 * r[i]), r[i] / 2], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q.reshape(R.shape[:-2] + (4,))


def pose_from_quat(position: ArrayLike, q_wxyz: ArrayLike) -> Array:
    """Pose ``(..., 4, 4)`` from position ``(..., 3)`` and quaternion ``[w, x, y, z]``."""
    return make_pose(quat_to_matrix(q_wxyz), position)


def euler_zyx(R: ArrayLike) -> Array:
    """``[roll, pitch, yaw]`` (rad) of ``R = Rz(yaw) Ry(pitch) Rx(roll)``, ``(..., 3)``."""
    R = np.asarray(R, dtype=float)
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    return np.stack([roll, pitch, yaw], axis=-1)


def nearest_rotation(M: ArrayLike) -> Array:
    """The proper rotation (3, 3) nearest to the 3x3 matrix ``M`` in the Frobenius norm (its
    polar factor, the smallest singular direction flipped when ``M``'s is a reflection)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float).reshape(3, 3))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def rotation_angle(R: ArrayLike) -> Array:
    """Rotation angle (rad) of rotation matrices ``(..., 3, 3)``."""
    R = np.asarray(R, dtype=float)
    c = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def interpolate_poses(times: ArrayLike, T: ArrayLike, query: ArrayLike) -> Array:
    """Board poses at ``query`` times: slerp of rotation, linear position, clamped at ends.

    ``times`` (N,) increasing, ``T`` (N, 4, 4), ``query`` (M,) -> (M, 4, 4).
    """
    times = np.asarray(times, dtype=float)
    T = np.asarray(T, dtype=float)
    q = np.clip(np.asarray(query, dtype=float), times[0], times[-1])
    if len(times) == 1:
        return np.repeat(T[:1], len(q), axis=0)
    i = np.clip(np.searchsorted(times, q, side="right") - 1, 0, len(times) - 2)
    dt = times[i + 1] - times[i]
    s = np.where(dt > 0, (q - times[i]) / np.where(dt > 0, dt, 1.0), 0.0)
    Ra, Rb = T[i, :3, :3], T[i + 1, :3, :3]
    dR = so3_log(np.swapaxes(Ra, -1, -2) @ Rb)
    R = Ra @ so3_exp(s[:, None] * dR)
    p = (1 - s)[:, None] * T[i, :3, 3] + s[:, None] * T[i + 1, :3, 3]
    return make_pose(R, p)
