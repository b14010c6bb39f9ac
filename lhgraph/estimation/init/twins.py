"""The planar mirror ambiguity resolved over time: a two-state Viterbi over a sequence of
twin poses.

A flat target seen by one station has two poses that fit its image almost equally well
(the board normal reflected about the line of sight); with few sensors far away the fit
alone cannot tell them apart. A board moves smoothly, though: :func:`resolve_twins` picks,
per measurement, the twin that makes the whole sequence most consistent, trading each twin's
own fit (an emission cost) against the rotation between consecutive choices (a random walk
on the orientation).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lhgraph.geometry.transforms import rotation_angle

Array = NDArray[np.float64]


def resolve_twins(time: Array, R: Array, emission: Array, turn_sigma: float = 1.0,
                  min_dt_s: float = 1e-3) -> NDArray[np.int64]:
    """The temporally consistent twin (0 or 1) of each measurement.

    ``time`` (M,) s, increasing; ``R`` (M, 2, 3, 3) the two twins' rotations (any common
    frame, e.g. ``R_lh_board`` of one station); ``emission`` (M, 2) each twin's own cost (a
    chi-square; ``inf`` or NaN = impossible). The orientation is a random walk with
    ``turn_sigma`` rad/sqrt(s): the cost of going from twin i at m to twin j at m + 1 is
    ``angle(R[m, i]^T R[m + 1, j])^2 / (turn_sigma^2 max(dt, min_dt_s))``. Measurements
    with neither twin possible get -1 and do not break the chain. Minimises the summed
    cost exactly (dynamic programming, two states).
    """
    emission = np.where(np.isfinite(emission), emission, np.inf)
    choice = np.full(len(time), -1, dtype=np.int64)
    rows = np.flatnonzero(np.isfinite(emission).any(axis=1))
    if len(rows) == 0:
        return choice
    e = emission[rows]
    Rr = R[rows]
    dt = np.maximum(np.diff(time[rows]), min_dt_s)
    # (M-1, 2, 2): transition i -> j between consecutive kept measurements
    rel = np.swapaxes(Rr[:-1, :, None], -1, -2) @ Rr[1:, None, :]
    trans = rotation_angle(rel) ** 2 / (turn_sigma**2 * dt[:, None, None])
    trans = np.where(np.isfinite(trans), trans, np.inf)
    cost = e[0].copy()
    back = np.zeros((len(rows), 2), dtype=np.int64)
    for m in range(1, len(rows)):
        total = cost[:, None] + trans[m - 1]  # (from, to)
        back[m] = np.argmin(total, axis=0)
        cost = total[back[m], [0, 1]] + e[m]
    path = np.empty(len(rows), dtype=np.int64)
    path[-1] = int(np.argmin(cost))
    for m in range(len(rows) - 1, 0, -1):
        path[m - 1] = back[m, path[m]]
    choice[rows] = path
    return choice
