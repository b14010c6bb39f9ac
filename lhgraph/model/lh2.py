"""Lighthouse v2 measurement model (pure, vectorised numpy): a rotor-frame point -> the rotor
angle at which each light plane crosses it, used through
:func:`lhgraph.model.station.sweep_angle`.

An LH2 station spins one rotor about its +z axis carrying two light planes tilted
``PLANE_TILT_RAD = (-30°, +30°)`` (SPEC §8); axis 0 of the angles CSV is the first plane,
axis 1 the second. A point ``(x, y, z)`` (station frame: +x forward, +y left, +z up) is
crossed by plane i at the ideal rotor angle

    alpha_i = atan2(y, x) + asin(z tan(t_i) / sqrt(x^2 + y^2)),   t_i = PLANE_TILT_RAD[i]

and the factory calibration (per plane ``phase, tilt, gibphase, gibmag``; our terms are
Bitcraze's, their meaning settled on the real LH2 log: docs/model.md) distorts it:

    a_i = atan2(y, x) + asin(z tan(t_i - tilt_i) / r) - phase_i
          + gibmag_i cos(atan2(y, x) + gibphase_i)

The deck firmware's correction inverts exactly this model (its ``correctedAngle``
reproduced to 0.2 µrad). The ``curve`` and ``ogee`` terms (libsurvive's model) are carried
in the files but not applied: the real log could not yet tell whether, and with which
signs, they improve the fit.

Angles in radians.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from lhgraph.model.factory import FactoryCalibration

Array = NDArray[np.float64]

PLANE_TILT_RAD = np.array([-np.pi / 6, np.pi / 6])
"""Nominal tilt of the first and second light plane about the rotor axis (SPEC §8)."""
_K = np.tan(np.pi / 6)


def ideal_angles(p_lh: ArrayLike) -> Array:
    """The two planes' ideal rotor angles ``(..., 2)`` (rad) of station-frame points
    ``(..., 3)``."""
    p = np.asarray(p_lh, dtype=float)
    az = np.arctan2(p[..., 1], p[..., 0])
    s = np.clip(p[..., 2] * _K / np.hypot(p[..., 0], p[..., 1]), -1.0, 1.0)
    return np.stack([az - np.arcsin(s), az + np.arcsin(s)], axis=-1)


def direction(alpha0: ArrayLike, alpha1: ArrayLike) -> Array:
    """Station-frame direction ``(..., 3)`` (x = 1) of ideal plane angles (rad); the
    inverse of :func:`ideal_angles`."""
    az, el = lh1_equivalent(alpha0, alpha1)
    return np.stack([np.ones_like(az), np.tan(az), np.tan(el)], axis=-1)


def lh1_equivalent(alpha0: ArrayLike, alpha1: ArrayLike) -> tuple[Array, Array]:
    """Ideal LH1 angles ``(azimuth, elevation)`` (rad) of the direction whose ideal plane
    angles are ``alpha0, alpha1`` (SPEC §8): azimuth ``(a0 + a1) / 2``, elevation
    ``atan2(sin(a1 - a0), tan(30°) (cos a0 + cos a1))``."""
    a0 = np.asarray(alpha0, dtype=float)
    a1 = np.asarray(alpha1, dtype=float)
    return 0.5 * (a0 + a1), np.arctan2(np.sin(a1 - a0), _K * (np.cos(a0) + np.cos(a1)))


def plane_angle(q: Array, plane: Array, cal: FactoryCalibration, *,
                jacobian: bool = False) -> Array | tuple[Array, Array]:
    """Measured rotor angle (rad) at which light plane ``plane`` ``(N,)`` crosses rotor-frame
    points ``q`` ``(N, 3)`` (m) under the factory calibration ``cal``; with
    ``jacobian=True`` also ``d angle / d q`` ``(N, 3)``. Callers use
    :func:`lhgraph.model.station.sweep_angle`."""
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    k = np.tan(PLANE_TILT_RAD[plane] - cal.tilt[plane])
    r2 = x * x + y * y
    r = np.sqrt(r2)
    s_raw = k * z / r
    s = np.clip(s_raw, -1.0, 1.0)
    az = np.arctan2(y, x)
    gib = cal.gibmag[plane] * np.cos(az + cal.gibphase[plane])
    angle = az + np.arcsin(s) - cal.phase[plane] + gib
    if not jacobian:
        return angle
    # d az = (-y, x, 0) / r^2 ; d asin(s) = k / sqrt(1 - s^2) (dz / r - z dr / r^2); a point
    # the plane never crosses (|s| >= 1: beyond 60° of elevation) sits on the clipped,
    # flat part (an unbounded slope would make the linear system indeterminate)
    inside = np.abs(s_raw) < 1.0
    d_asin = np.where(inside, k / np.sqrt(np.where(inside, 1.0 - s * s, 1.0)), 0.0)
    d_az = 1.0 - cal.gibmag[plane] * np.sin(az + cal.gibphase[plane])
    J = np.empty(q.shape)
    J[..., 0] = -d_az * y / r2 - d_asin * z * x / (r2 * r)
    J[..., 1] = d_az * x / r2 - d_asin * z * y / (r2 * r)
    J[..., 2] = d_asin / r
    return angle, J
