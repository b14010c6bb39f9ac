"""Sweep times and one board state per rotor cycle for few-diode receivers (the Crazyflie deck).

A decoder that times every hit (our board, libsurvive) stamps a station's azimuth and
elevation sweeps of one rotor cycle one slot (T/2 = 8.333 ms) apart. The Crazyflie deck logs
both sweeps of a cycle at the same moment, after its elevation (axis 1) sweep, one event per
diode a few microseconds apart: the stamps say when the cycle was logged, not when each
sweep passed. At 2 m/s, taking the azimuth sweep at its stamp misplaces the board by 17 mm.
:func:`co_logged_fraction` recognises such stamps. :func:`retime_cycles` puts every sweep of
a few-diode capture at its sweep's time on the station's fitted rotor grid (co-logged: the
stamp, the azimuth sweep one slot earlier, as the LH1 schedule sweeps axis 0, then axis 1, of
one station in consecutive slots; hit-timed: from the hit times), each hit at the moment the
plane passed its angle (``angle T / 2 pi`` after the sweep's centre: up to 1.5 ms), and gives
both sweeps of a station's rotor cycle one board state.
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


def sweep_table(angles: Angles) -> tuple[NDArray[np.int64], Array, NDArray[np.int64],
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
    _, t, station, axis = sweep_table(angles)
    out = {}
    for s in np.unique(station).tolist():
        t0 = t[(station == s) & (axis == 0)]
        t1 = np.sort(t[(station == s) & (axis == 1)])
        out[int(s)] = float(np.mean(_nearest_gap(t0, t1) < CO_LOGGED_S)) if len(t0) else 0.0
    return out


def co_logged_stations(angles: Angles, min_fraction: float = 0.5) -> set[int]:
    """Stations of ``angles`` that log their two sweeps of a cycle together:
    :func:`co_logged_fraction` above ``min_fraction``."""
    return {s for s, f in co_logged_fraction(angles).items() if f > min_fraction}


def retime_cycles(angles: Angles, co_logged: set[int] | None = None,
                  slot_s: float = SLOT_S) -> Angles:
    """``angles`` at the hit times of each station's fitted rotor grid, one board state per
    rotor cycle: for few-diode receivers (the Crazyflie deck), whether their stamps are log
    times (co-logged sweeps) or hit times.

    Every sweep gets the moment its plane passed the station's axis: a co-logged station's
    (``co_logged``, default :func:`co_logged_stations`) stamp of the cycle, one slot earlier for the
    azimuth sweep; a hit-timed sweep's mean of ``time - angle 2 slot_s / 2 pi``. A station's
    azimuth sweep and the elevation sweep one slot after it (within ``CO_LOGGED_S``) form a
    cycle; the cycles' moments are put on the station's fitted rotor grid
    (:func:`rotor_grid`: the receiver's scheduling jitter removed, a cycle the grid misses
    keeps its value) and every hit at its sweep's grid moment + ``angle 2 slot_s / 2 pi``.
    Rows come sorted by the new times; the extra column ``sweep`` becomes each hit's board
    state: one per cycle of a station (its two sweeps, 8.3 ms apart, share it; the bearing
    factor propagates each hit by its time offset with the state's twist). A common delay of
    a log's stamps stays (it shifts every state alike)."""
    if co_logged is None:
        co_logged = co_logged_stations(angles)
    ids, t, station, axis = sweep_table(angles)
    count = np.maximum(np.bincount(ids, minlength=len(t)), 1)
    passed = np.bincount(ids, weights=angles.time - angles.angle * slot_s / np.pi,
                         minlength=len(t)) / count
    logged = np.isin(station, list(co_logged))
    # the moment of the cycle's elevation sweep that each sweep belongs to
    cycle_moment = np.where(logged, t, passed + slot_s * (axis == 0))
    sweep_time = np.empty(len(t))
    state = np.empty(len(t), dtype=np.int64)
    for s in np.unique(station).tolist():
        rows = np.flatnonzero(station == s)
        rows = rows[np.argsort(cycle_moment[rows], kind="stable")]
        m = cycle_moment[rows]
        cycle = np.r_[True, np.diff(m) > CO_LOGGED_S]
        start = np.flatnonzero(cycle)
        moments = np.add.reduceat(m, start) / np.diff(np.r_[start, len(rows)])
        snapped = rotor_grid(moments, 4 * slot_s)
        sweep_time[rows] = snapped[np.cumsum(cycle) - 1] - slot_s * (axis[rows] == 0)
        state[rows] = rows[start][np.cumsum(cycle) - 1]
    time = sweep_time[ids] + angles.angle * slot_s / np.pi
    order = np.argsort(time, kind="stable")
    retimed = Angles(time, angles.lighthouse, angles.axis, angles.sensor, angles.angle,
                     {**angles.extra, "sweep": state[ids]})
    return retimed.select(order)


LH2_CYCLE_GAP_S = 0.015
"""An LH2 station's second plane passes a diode 4-8 ms after its first (SPEC §8, the real
log); a plane-1 sweep joins the plane-0 sweep before it when it comes within this."""


def plane_cycles(angles: Angles) -> Angles:
    """``angles`` (LH2 hit times) with one board state per rotor turn of each station: the
    extra column ``sweep`` joins each first-plane sweep with the station's second-plane
    sweep that follows it within ``LH2_CYCLE_GAP_S`` (a 4-diode deck then has both planes'
    8 hits per state, as the LH1 grid gives both axes; the bearing factor propagates each
    hit by its time offset with the state's twist)."""
    ids, t, station, axis = sweep_table(angles)
    state = np.arange(len(t))
    for s in np.unique(station).tolist():
        rows = np.flatnonzero(station == s)
        rows = rows[np.argsort(t[rows], kind="stable")]
        joins = ((axis[rows[1:]] == 1) & (axis[rows[:-1]] == 0)
                 & (np.diff(t[rows]) < LH2_CYCLE_GAP_S))
        state[rows[1:][joins]] = rows[:-1][joins]
    return Angles(angles.time, angles.lighthouse, angles.axis, angles.sensor, angles.angle,
                  {**angles.extra, "sweep": state[ids]})


LH2_REVOLUTION_S = (18.0e-3, 20.5e-3)
"""One LH2 revolution (the channels' periods, 18.48-19.98 ms, SPEC §8), with room for
jitter: an LH2 station's light planes pass once per revolution."""
LH1_TURN_TOLERANCE_S = 2e-3
"""An LH1 station sweeps an axis a whole number of rotor turns (1/60 s) apart, to within
this (hive's stamps: 1.3 ms median; an LH2 revolution misses the grid by 1.8 ms or more)."""


def swept_generations(angles: Angles, min_gaps: int = 10) -> dict[int, int | None]:
    """Per station, the generation its sweeps' timing shows (SPEC §3, §8): 2 when most gaps
    between consecutive sweeps of one axis are one LH2 revolution (:data:`LH2_REVOLUTION_S`),
    1 when most are whole LH1 rotor turns (:data:`LH1_TURN_TOLERANCE_S`), None when neither
    or with fewer than ``min_gaps`` gaps."""
    _, t, station, axis = sweep_table(angles)
    turn = 2 * SLOT_S
    out: dict[int, int | None] = {}
    for s in np.unique(station).tolist():
        gaps = np.concatenate([np.diff(np.sort(t[(station == s) & (axis == a)]))
                               for a in (0, 1)])
        turns = np.round(gaps / turn)
        lh1 = np.mean((turns >= 1) & (np.abs(gaps - turns * turn) <= LH1_TURN_TOLERANCE_S))
        lh2 = np.mean((gaps >= LH2_REVOLUTION_S[0]) & (gaps <= LH2_REVOLUTION_S[1]))
        out[s] = (None if len(gaps) < min_gaps else 2 if lh2 > 0.5 else 1 if lh1 > 0.5
                  else None)
    return out
