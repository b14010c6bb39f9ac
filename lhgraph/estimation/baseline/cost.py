"""The paper's angle cost (K1 per board pose, K2 per station pose) and the parameterisation
its Nelder-Mead fits share: ``R = Exp(omega) R0``, ``t = t0 + v`` around a start pose."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def rotation(w: Array) -> Array:
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


def angle_errors(p: Array, measured: Array) -> Array:
    """``C - M``: ideal ``[az, el]`` (rad) of station-frame points ``(n, 3)`` minus the
    measured ones ``(n, 2)``."""
    return np.arctan2(p[:, 1:], p[:, :1]) - measured


def angle_cost(p: Array, measured: Array) -> float:
    """``sum (C - M)^2`` of station-frame points ``(n, 3)`` vs measured ``[az, el]`` ``(n, 2)``."""
    d = angle_errors(p, measured)
    return float(np.einsum("ij,ij->", d, d))


def start_simplex(scale_rot: float, scale_pos: float) -> Array:
    """Nelder-Mead start simplex around 0 in ``[omega, v]`` with the given step sizes."""
    steps = np.r_[np.full(3, scale_rot), np.full(3, scale_pos)]
    return np.vstack([np.zeros(6), np.diag(steps)])
