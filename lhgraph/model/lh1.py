"""Lighthouse v1 measurement model (pure, vectorised numpy): a rotor-frame point -> the sweep
angle, used through :func:`lhgraph.model.station.sweep_angle`.

Station frame (SPEC §4): +x forward (optical axis), +y left, +z up. Axis 0 measures azimuth
``atan2(y, x)`` (rotor axis along z), axis 1 measures elevation ``atan2(z, x)`` (rotor axis
along y). Each rotor may sit at an offset from the station origin. The factory calibration
(OOTX ``phase, tilt, curve, gibphase, gibmag`` per axis) distorts the ideal angle:

    axis 0:  t' = atan2(y, x) - phase0 - asin(tan(tilt0) z / sqrt(x^2 + y^2))
             a0 = t' + g gibmag0 sin(gibphase0 + t') + c curve0 atan2(z, x)^2
    axis 1:  t' = atan2(z, x) - phase1 + asin(tan(tilt1) y / sqrt(x^2 + z^2))
             a1 = t' + g gibmag1 sin(gibphase1 + t') + c curve1 atan2(y, x)^2

with the sign convention ``(g, c)`` an explicit parameter
(:class:`~lhgraph.model.factory.Convention`). Angles are in radians.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from lhgraph.model.factory import Convention, FactoryCalibration

Array = NDArray[np.float64]


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


def rotor_angle(q: Array, axis: Array, cal: FactoryCalibration, conv: Convention, *,
                jacobian: bool = False) -> Array | tuple[Array, Array]:
    """Measured LH1 sweep angle (rad) of rotor-frame points ``q`` ``(N, 3)`` (m: the
    station-frame point less its axis's rotor offset) for ``axis`` ``(N,)`` under the factory
    calibration ``cal`` (signs ``conv``); with ``jacobian=True`` also ``d angle / d q``
    ``(N, 3)``. Callers use :func:`lhgraph.model.station.sweep_angle`."""
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
    J = np.empty(q.shape)
    J[..., 0] = d_x
    J[..., 1] = np.where(axis == 0, d_u, d_w)
    J[..., 2] = np.where(axis == 0, d_w, d_u)
    return angle, J


def direction(azimuth: ArrayLike, elevation: ArrayLike) -> Array:
    """Station-frame direction ``(..., 3)`` ``(1, tan az, tan el)`` of ideal angles (rad)."""
    az = np.asarray(azimuth, dtype=float)
    return np.stack([np.ones_like(az), np.tan(az), np.tan(np.asarray(elevation, float))],
                    axis=-1)
