"""Sweep times of receivers that log a station's two sweeps together (the Crazyflie deck).

A decoder that times every hit (our board, libsurvive) stamps a station's azimuth and
elevation sweeps of one rotor cycle one slot (T/2 = 8.333 ms) apart. The Crazyflie deck logs
both sweeps of a cycle at the same moment, after its elevation (axis 1) sweep, one event per
diode a few microseconds apart: the stamps say when the cycle was logged, not when each
sweep passed. At 2 m/s, taking the azimuth sweep at its stamp misplaces the board by 17 mm.
:func:`co_logged_fraction` recognises such stamps; :func:`retime_co_logged` puts every hit of
a sweep at its sweep's stamp, the azimuth sweeps one slot earlier (the LH1 schedule sweeps
axis 0, then axis 1, of one station in consecutive slots), and each hit at the moment the
plane passed its angle (``angle T / 2 pi`` after the sweep's centre: up to 1.5 ms).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.angles import Angles

Array = NDArray[np.float64]

SLOT_S = 1.0 / 120.0
"""One LH1 slot (half a rotor turn): one axis of one station per slot."""

CO_LOGGED_S = 2e-3
"""An axis-0 sweep is co-logged with an axis-1 sweep of its station stamped this close."""


def _sweeps(angles: Angles) -> tuple[NDArray[np.int64], Array, NDArray[np.int64],
                                     NDArray[np.int64]]:
    """Sweep id of every hit; per sweep its mean stamp, station and axis."""
    ids = angles.sweep_ids()
    count = np.bincount(ids)
    t = np.bincount(ids, weights=angles.time) / np.maximum(count, 1)
    first = np.zeros(len(count), dtype=np.int64)
    first[ids[::-1]] = np.arange(len(ids))[::-1]
    return ids, t, angles.lighthouse[first], angles.axis[first]


def _nearest_gap(t: Array, other: Array) -> Array:
    """Distance (s) from each of ``t`` to the nearest of the sorted ``other`` (inf if none)."""
    if len(other) == 0:
        return np.full(len(t), np.inf)
    i = np.clip(np.searchsorted(other, t), 1, max(len(other) - 1, 1))
    lo = np.abs(t - other[i - 1])
    hi = np.abs(other[np.minimum(i, len(other) - 1)] - t)
    return np.minimum(lo, hi)


def rotor_grid(t: Array, period_s: float = 4 * SLOT_S, max_residual_s: float = 2e-3,
               rounds: int = 4) -> Array:
    """Stamps ``t`` (sorted, s) of one station's cycles put on the fitted cycle grid
    ``a + b n``: the period ``b`` on the receiver's clock starts at the median spacing of
    consecutive cycles within 10 % of ``period_s``, each stamp gets its cycle number ``n``
    from the rounded gaps, and a line is fitted to the stamps within ``max_residual_s``
    (``rounds`` times). A stamp the grid misses by more than that keeps its value."""
    if len(t) < 3:
        return t.copy()
    gap = np.diff(t)
    near = np.abs(gap - period_s) < 0.1 * period_s
    b = float(np.median(gap[near])) if near.any() else period_s
    n = np.r_[0, np.cumsum(np.maximum(np.round(gap / b), 1))]
    good = np.ones(len(t), dtype=bool)
    for _ in range(rounds):
        b, a = np.polyfit(n[good], t[good], 1)
        good = np.abs(t - (a + b * n)) < max_residual_s
        if good.sum() < 3:
            return t.copy()
    grid = a + b * n
    return np.where(good, grid, t)


def co_logged_fraction(angles: Angles) -> dict[int, float]:
    """Per station, the fraction of its axis-0 sweeps stamped within ``CO_LOGGED_S`` of one
    of its axis-1 sweeps (~0 for hit-timed captures, ~1 for a deck log)."""
    _, t, station, axis = _sweeps(angles)
    out = {}
    for s in np.unique(station).tolist():
        t0 = t[(station == s) & (axis == 0)]
        t1 = np.sort(t[(station == s) & (axis == 1)])
        out[int(s)] = float(np.mean(_nearest_gap(t0, t1) < CO_LOGGED_S)) if len(t0) else 0.0
    return out


def retime_co_logged(angles: Angles, min_fraction: float = 0.5,
                     slot_s: float = SLOT_S) -> Angles | None:
    """``angles`` with the sweeps of every co-logged station (``co_logged_fraction`` above
    ``min_fraction``) at their hit times: a hit at its cycle's stamp on the station's
    fitted rotor grid (:func:`rotor_grid`: the log's scheduling jitter removed) plus
    ``angle 2 slot_s / 2 pi`` (when the plane passed it), axis-0 sweeps ``slot_s`` earlier;
    rows sorted by the new times (the common delay of the log stays: it shifts every state
    alike). The extra column ``sweep`` becomes the board state of each hit: one per logged
    cycle of a co-logged station (its two sweeps, 8.3 ms apart, share a state; the bearing
    factor propagates each hit by its time offset with the state's twist), one per sweep
    elsewhere. None when no station is
    co-logged (the stamps are hit times: nothing to do)."""
    fraction = co_logged_fraction(angles)
    stations = [s for s, f in fraction.items() if f > min_fraction]
    if not stations:
        return None
    ids, t, station, axis = _sweeps(angles)
    sweep_time = np.full(len(t), np.nan)
    state = np.arange(len(t))  # one board state per sweep, per cycle where co-logged
    for s in stations:  # both sweeps of a cycle carry its stamp: one grid per station
        rows = np.flatnonzero(station == s)
        rows = rows[np.argsort(t[rows], kind="stable")]
        cycle = np.r_[True, np.diff(t[rows]) > CO_LOGGED_S]
        start = np.flatnonzero(cycle)
        stamps = np.add.reduceat(t[rows], start) / np.diff(np.r_[start, len(rows)])
        snapped = rotor_grid(stamps, 4 * slot_s)
        sweep_time[rows] = snapped[np.cumsum(cycle) - 1] - slot_s * (axis[rows] == 0)
        state[rows] = rows[start][np.cumsum(cycle) - 1]
    hit_time = sweep_time[ids] + angles.angle * slot_s / np.pi
    time = np.where(np.isnan(hit_time), angles.time, hit_time)
    order = np.argsort(time, kind="stable")
    retimed = Angles(time, angles.lighthouse, angles.axis, angles.sensor, angles.angle,
                     {**angles.extra, "sweep": state[ids]})
    return retimed.select(order)
