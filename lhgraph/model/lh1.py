"""Lighthouse v1 measurement model: station-frame point -> sweep angle (pure, vectorised numpy).

Station frame (SPEC §4): +x forward (optical axis), +y left, +z up. Axis 0 measures azimuth
``atan2(y, x)`` (rotor axis along z), axis 1 measures elevation ``atan2(z, x)`` (rotor axis
along y). Each rotor may sit at an offset from the station origin. The factory calibration
(OOTX ``phase, tilt, curve, gibphase, gibmag`` per axis) distorts the ideal angle:

    axis 0:  t' = atan2(y, x) - phase0 - asin(tan(tilt0) z / sqrt(x^2 + y^2))
             a0 = t' + g gibmag0 sin(gibphase0 + t') + c curve0 atan2(z, x)^2
    axis 1:  t' = atan2(z, x) - phase1 + asin(tan(tilt1) y / sqrt(x^2 + z^2))
             a1 = t' + g gibmag1 sin(gibphase1 + t') + c curve1 atan2(y, x)^2

with the sign convention ``(g, c)`` an explicit parameter (:class:`Convention`). Angles are
in radians. Jacobians follow GTSAM's ``Pose3`` tangent convention (right perturbation,
``[omega, v]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.geometry.transforms import cross

Array = NDArray[np.float64]

CALIBRATION_KEYS = ("phase", "tilt", "curve", "gibphase", "gibmag")


@dataclass(frozen=True)
class Convention:
    """Signs of the gib and curve terms. Public implementations disagree; the default
    (gib -1, curve +1) fits two real recordings best (docs/model.md)."""

    gib_sign: float = -1.0
    curve_sign: float = 1.0


@dataclass(frozen=True)
class FactoryCalibration:
    """Per-axis factory calibration of one station, each field ``[axis0, axis1]`` (rad)."""

    phase: Array = field(default_factory=lambda: np.zeros(2))
    tilt: Array = field(default_factory=lambda: np.zeros(2))
    curve: Array = field(default_factory=lambda: np.zeros(2))
    gibphase: Array = field(default_factory=lambda: np.zeros(2))
    gibmag: Array = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        for key in CALIBRATION_KEYS:
            value = np.asarray(getattr(self, key), dtype=float).reshape(2)
            object.__setattr__(self, key, value)

    def as_dict(self) -> dict[str, list[float]]:
        """Plain ``{key: [axis0, axis1]}`` for files."""
        return {key: [float(x) for x in getattr(self, key)] for key in CALIBRATION_KEYS}

    def is_zero(self) -> bool:
        """True when every term is zero (the ideal station)."""
        return all(not np.any(getattr(self, key)) for key in CALIBRATION_KEYS)


@dataclass(frozen=True)
class StationModel:
    """Everything that maps a station-frame point to the two sweep angles of one station.

    ``rotor_offsets[k]`` is the position (m, station frame) of axis k's rotor centre.
    """

    calibration: FactoryCalibration = field(default_factory=FactoryCalibration)
    rotor_offsets: Array = field(default_factory=lambda: np.zeros((2, 3)))
    convention: Convention = field(default_factory=Convention)

    def __post_init__(self) -> None:
        offsets = np.asarray(self.rotor_offsets, dtype=float).reshape(2, 3)
        object.__setattr__(self, "rotor_offsets", offsets)


IDEAL = StationModel()


def ideal_angles(p_lh: ArrayLike) -> Array:
    """``[azimuth, elevation]`` (rad) of station-frame points ``(..., 3)`` -> ``(..., 2)``."""
    p = np.asarray(p_lh, dtype=float)
    return np.stack(
        [np.arctan2(p[..., 1], p[..., 0]), np.arctan2(p[..., 2], p[..., 0])], axis=-1
    )


def _axis_components(q: Array, axis: Array) -> tuple[Array, Array, Array, Array]:
    """Split rotor-frame points into (x, u, w, tilt sign) for each hit's axis.

    u is the swept coordinate (y for axis 0, z for axis 1) and w the other one.
    """
    x = q[..., 0]
    u = np.where(axis == 0, q[..., 1], q[..., 2])
    w = np.where(axis == 0, q[..., 2], q[..., 1])
    tilt_sign = np.where(axis == 0, -1.0, 1.0)
    return x, u, w, tilt_sign


def sweep_angle(
    p_lh: ArrayLike,
    axis: ArrayLike,
    model: StationModel = IDEAL,
    *,
    jacobian: bool = False,
) -> Array | tuple[Array, Array]:
    """Measured sweep angle (rad) of station-frame points ``(N, 3)`` for ``axis`` ``(N,)``.

    With ``jacobian=True`` also returns ``d angle / d p_lh`` ``(N, 3)``.
    """
    p = np.asarray(p_lh, dtype=float)
    axis = np.asarray(axis, dtype=int)
    cal, conv = model.calibration, model.convention
    q = p - model.rotor_offsets[axis]
    x, u, w, s_t = _axis_components(q, axis)
    phase, tilt = cal.phase[axis], cal.tilt[axis]
    curve, gibphase, gibmag = cal.curve[axis], cal.gibphase[axis], cal.gibmag[axis]

    r2 = x * x + u * u
    r = np.sqrt(r2)
    k = np.tan(tilt)
    s = np.clip(k * w / r, -1.0, 1.0)
    base = np.arctan2(u, x)
    primed = base - phase + s_t * np.arcsin(s)
    c_angle = np.arctan2(w, x)
    gib_arg = gibphase + primed
    angle = primed + conv.gib_sign * gibmag * np.sin(gib_arg) + conv.curve_sign * curve * c_angle**2
    if not jacobian:
        return angle

    # d base: (-u, x, 0) / r^2 ; d asin(s): k / sqrt(1 - s^2) * (dw / r - w dr / r^2)
    d_asin = k / np.sqrt(np.maximum(1.0 - s * s, 1e-12))
    d_primed_x = -u / r2 + s_t * d_asin * (-w * x / (r2 * r))
    d_primed_u = x / r2 + s_t * d_asin * (-w * u / (r2 * r))
    d_primed_w = s_t * d_asin / r
    outer = 1.0 + conv.gib_sign * gibmag * np.cos(gib_arg)
    xw2 = x * x + w * w
    curve_coeff = 2.0 * conv.curve_sign * curve * c_angle
    d_x = outer * d_primed_x + curve_coeff * (-w / xw2)
    d_u = outer * d_primed_u
    d_w = outer * d_primed_w + curve_coeff * (x / xw2)
    J = np.empty(p.shape)
    J[..., 0] = d_x
    J[..., 1] = np.where(axis == 0, d_u, d_w)
    J[..., 2] = np.where(axis == 0, d_w, d_u)
    return angle, J


def _relative_pose(T_world_lh: Array, T_world_board: Array) -> tuple[Array, Array]:
    """Rotation ``(..., 3, 3)`` and translation ``(..., 3)`` of ``T_lh_board``."""
    R_l = np.swapaxes(T_world_lh[..., :3, :3], -1, -2)
    R = R_l @ T_world_board[..., :3, :3]
    t = (R_l @ (T_world_board[..., :3, 3] - T_world_lh[..., :3, 3])[..., None])[..., 0]
    return R, t


def sensor_in_station(T_world_lh: ArrayLike, T_world_board: ArrayLike, s_board: ArrayLike) -> Array:
    """Station-frame position ``(N, 3)`` of board-frame sensor points ``(N, 3)``.

    ``T_world_lh`` and ``T_world_board`` are ``(4, 4)`` or ``(N, 4, 4)``.
    """
    R, t = _relative_pose(np.asarray(T_world_lh, dtype=float),
                          np.asarray(T_world_board, dtype=float))
    s = np.asarray(s_board, dtype=float)
    return (R @ s[..., None])[..., 0] + t


def board_jacobian(J_p: Array, R_lh_board: Array, s_board: Array) -> Array:
    """Derivative ``(..., 6)`` of an angle w.r.t. a right perturbation ``[omega, v]`` of
    ``T_world_board``, from its derivative ``J_p`` ``(..., 3)`` w.r.t. the station-frame point
    ``p = R_lh_board s_board + t``: ``d p / d xi = R_lh_board [-[s]x, I]``, so the result is
    ``[s x J_b, J_b]`` with ``J_b = J_p R_lh_board`` (broadcasting over leading axes)."""
    J_b = (J_p[..., None, :] @ R_lh_board)[..., 0, :]
    return np.concatenate([cross(s_board, J_b), J_b], axis=-1)


def predict(
    T_world_lh: ArrayLike,
    T_world_board: ArrayLike,
    s_board: ArrayLike,
    axis: ArrayLike,
    model: StationModel = IDEAL,
    *,
    jacobians: bool = False,
) -> Array | tuple[Array, Array, Array]:
    """Predicted angles ``(N,)`` of sensors ``s_board`` (board frame, m) seen by one station.

    With ``jacobians=True`` also returns ``H_lh`` and ``H_board`` ``(N, 6)``: the derivatives
    w.r.t. right perturbations ``[omega, v]`` of ``T_world_lh`` and ``T_world_board``.
    """
    R, t = _relative_pose(np.asarray(T_world_lh, dtype=float),
                          np.asarray(T_world_board, dtype=float))
    s = np.asarray(s_board, dtype=float)
    p_lh = (R @ s[..., None])[..., 0] + t
    if not jacobians:
        return sweep_angle(p_lh, axis, model)
    angle, J_p = sweep_angle(p_lh, axis, model, jacobian=True)
    # p_lh = R_l^T (R_b s + t_b - t_l)
    # d p_lh / d xi_lh    = [ [p_lh]x , -I ]       -> J [p]x = J x p
    H_lh = np.concatenate([cross(J_p, p_lh), -J_p], axis=-1)
    return angle, H_lh, board_jacobian(J_p, R, s)


def ideal_from_measured(
    azimuth: ArrayLike, elevation: ArrayLike, model: StationModel = IDEAL, iterations: int = 8
) -> tuple[Array, Array]:
    """Invert the factory-calibration distortion of a direction's measured angle pair.

    Returns the ideal ``(azimuth, elevation)`` (rad) whose direction ``(1, tan az, tan el)``
    the model maps to the measured pair; rotor offsets are ignored (far-field). Used by the
    baseline, which works on ideal angles.
    """
    az_m = np.asarray(azimuth, dtype=float)
    el_m = np.asarray(elevation, dtype=float)
    az, el = az_m.copy(), el_m.copy()
    far = StationModel(model.calibration, np.zeros((2, 3)), model.convention)
    for _ in range(iterations):
        d = np.stack([np.ones_like(az), np.tan(az), np.tan(el)], axis=-1).reshape(-1, 3)
        pred_az = sweep_angle(d, np.zeros(len(d), dtype=int), far).reshape(az.shape)
        pred_el = sweep_angle(d, np.ones(len(d), dtype=int), far).reshape(el.shape)
        az = az + (az_m - pred_az)
        el = el + (el_m - pred_el)
    return az, el
