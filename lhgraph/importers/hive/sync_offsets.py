"""Per-sweep sync-bit offsets in hive's angles: found from the data and corrected.

On part of a station's sweeps hive reads every diode one OOTX data-bit flash length low: the
data bit lengthens the sync flash by 2 x 10.42 us (SPEC section 2), 7.85 mrad of rotor angle
at 60 rev/s, and hive evidently times such sweeps from a point of the flash that moves with
its length (docs/hive.md, ``benchmarks/hive_sync_offsets.py``). The offset is common to all
diodes of a sweep and comes in runs of a few sweeps. (A diode hit twice in one sweep counts
with its last hit.)

:func:`sync_bit_levels` labels each sweep of one station and axis *high* or *low* by a
Viterbi over the sweeps in time order: a diode's angle moves smoothly from sweep to sweep,
so a sweep's angles, less the line through the same diodes' angles on the sweeps before and
after it (the *bend*, median over the diodes the three sweeps share), are near zero once
every low sweep is raised by the gap. The state is the pair (level of the previous sweep,
level of this one); each bend costs a Huber loss of its remainder after the levels'
correction (scale ``bend_scale_rad``: the board's motion bends the series by ~1 mrad at
30 Hz), each change of level ``switch_cost``, so isolated bends of fast motion stay high,
and each low sweep ``low_cost`` (a run at one level bends nothing: it stays high).
Across a gap longer than ``max_gap_s`` the levels are free. The gap is then fitted to the
labelled bends. :func:`correct_sync_bits` does this per station and axis and raises the low
sweeps, unless fewer than ``min_fraction`` of a series' sweeps are low (no offset: the series
is left as it is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.angles import Angles

Array = NDArray[np.float64]

DATA_BIT_RAD = 2 * np.pi * 60.0 * 2 * 10.42e-6
"""The OOTX data bit's length in rotor angle: 2 x 10.42 us at 60 rev/s (7.856 mrad)."""


@dataclass(frozen=True)
class SyncBitLevels:
    """One station's and axis's sweeps: ``low`` (S,) bool per sweep in time order, the
    fitted ``gap_rad`` between the levels, and ``bends`` the number of sweeps with a bend."""

    low: NDArray[np.bool_]
    gap_rad: float
    bends: int

    @property
    def fraction_low(self) -> float:
        return float(self.low.mean()) if len(self.low) else 0.0


@dataclass(frozen=True)
class SyncBitCorrection:
    """What :func:`correct_sync_bits` found per (station, axis): the levels, and whether the
    low sweeps were raised (``corrected``; not where the fitted gap is off the data bit's
    length by ``max_gap_error`` or more, relative)."""

    levels: dict[tuple[int, int], SyncBitLevels]
    corrected: dict[tuple[int, int], bool]
    max_gap_error: float = 0.1

    def summary(self) -> str:
        """One line per station and axis."""
        lines = []
        for (lh, ax), lev in sorted(self.levels.items()):
            n = int(lev.low.sum())
            found = (f"{n} of {len(lev.low)} sweeps ({lev.fraction_low:.0%}) read "
                     f"{lev.gap_rad * 1e3:.3f} mrad low")
            if self.corrected[(lh, ax)]:
                what = f"{found}: raised"
            elif abs(lev.gap_rad / DATA_BIT_RAD - 1) >= self.max_gap_error and n:
                what = (f"{found}, not the data bit's {DATA_BIT_RAD * 1e3:.3f} mrad: left as "
                        "they are")
            else:
                what = (f"no sync-bit offset ({n} of {len(lev.low)} sweeps look low, too "
                        "few: left as they are)")
            lines.append(f"sync-bit offset lh{lh}/ax{ax}: {what}")
        return "\n".join(lines)


def _bends(time: Array, sweep: NDArray[np.int64], sensor: NDArray[np.int64],
           angle: Array, max_gap_s: float) -> tuple[Array, Array, NDArray[np.bool_]]:
    """Per sweep (in time order, ``sweep`` numbered 0..S-1): the bend (median over the diodes
    it shares with both neighbours of its angle less the line through theirs, NaN without
    one), the neighbours' interpolation weight ``w`` of the next sweep, and whether the gap
    to the previous sweep is short enough to link the levels."""
    S = int(sweep.max()) + 1
    t = np.bincount(sweep, weights=time, minlength=S) / np.bincount(sweep, minlength=S)
    ids = np.unique(sensor)
    table = np.full((S, len(ids)), np.nan)
    table[sweep, np.searchsorted(ids, sensor)] = angle
    w = np.full(S, 0.5)
    bend = np.full(S, np.nan)
    linked = np.r_[False, np.diff(t) < max_gap_s]
    if S >= 3:
        w[1:-1] = (t[1:-1] - t[:-2]) / np.maximum(t[2:] - t[:-2], 1e-9)
        line = table[:-2] + (table[2:] - table[:-2]) * w[1:-1, None]
        d = table[1:-1] - line
        ok = np.isfinite(d).any(axis=1) & linked[1:-1] & linked[2:]
        bend[1:-1][ok] = np.nanmedian(d[ok], axis=1)
    return bend, w, linked


def _huber(x: Array) -> Array:
    a = np.abs(x)
    return np.where(a <= 1.0, 0.5 * x**2, a - 0.5)


def sync_bit_levels(time: Array, sweep: NDArray[np.int64], sensor: NDArray[np.int64],
                    angle: Array, gap_rad: float = DATA_BIT_RAD, bend_scale_rad: float = 1e-3,
                    switch_cost: float = 2.0, low_cost: float = 0.05,
                    max_gap_s: float = 0.05) -> SyncBitLevels:
    """The high/low level of every sweep of one station and axis (hits: ``time`` s,
    ``sweep`` ids 0..S-1 in time order, ``sensor``, ``angle`` rad), see the module
    docstring; the returned gap is fitted to the labelled bends (``gap_rad`` where no bend
    changes level)."""
    bend, w, linked = _bends(time, sweep, sensor, angle, max_gap_s)
    S = len(bend)
    if S < 2:
        return SyncBitLevels(np.zeros(S, bool), gap_rad, 0)
    # pair state j = 2 a + b: (level of sweep k - 1, level of sweep k); 1 = low
    a, b = np.divmod(np.arange(4), 2)
    cost = switch_cost * (a != b) * linked[1] + low_cost * (a + b)  # at k = 1
    back = np.zeros((S, 4), dtype=np.int64)
    for k in range(1, S - 1):
        # from (a, b) at k to (b, c) at k + 1: the switch b -> c and the bend of sweep k
        c = np.arange(2)[:, None]  # rows: c; columns: the old state (a, b)
        total = (cost[None, :] + switch_cost * (b[None, :] != c) * linked[k + 1]
                 + low_cost * c)
        if np.isfinite(bend[k]):
            # measured = true - gap level: the true bend adds gap (level k - the line's)
            rest = bend[k] + gap_rad * (b[None, :] - (1 - w[k]) * a[None, :] - w[k] * c)
            total = total + _huber(rest / bend_scale_rad)
        new = np.full(4, np.inf)
        for j_new in range(4):  # (b, c) = divmod(j_new, 2): old states with that b
            bb, cc = divmod(j_new, 2)
            cand = np.where(b == bb, total[cc], np.inf)
            back[k + 1, j_new] = int(np.argmin(cand))
            new[j_new] = cand[back[k + 1, j_new]]
        cost = new
    low = np.zeros(S, dtype=bool)
    j = int(np.argmin(cost))
    for k in range(S - 1, 0, -1):
        low[k - 1], low[k] = divmod(j, 2)
        j = int(back[k, j])
    level = low.astype(float)
    change = np.full(S, np.nan)
    change[1:-1] = level[1:-1] - (1 - w[1:-1]) * level[:-2] - w[1:-1] * level[2:]
    use = np.isfinite(bend) & (np.abs(np.nan_to_num(change)) > 0.25)
    fitted = (float(-np.sum(bend[use] * change[use]) / np.sum(change[use] ** 2))
              if use.any() else gap_rad)
    return SyncBitLevels(low, fitted, int(np.isfinite(bend).sum()))


def correct_sync_bits(angles: Angles, min_fraction: float = 0.05, max_gap_error: float = 0.1
                      ) -> tuple[Angles, SyncBitCorrection]:
    """``angles`` with every low sweep of a station and axis raised by its fitted gap where
    at least ``min_fraction`` of that series' sweeps are low and the fitted gap is within
    ``max_gap_error`` (relative) of the data bit's length (otherwise the labels are not a
    sync-bit offset: the series is left as it is and the summary says why), and what was
    found."""
    ids = angles.sweep_ids()
    out = angles.angle.copy()
    levels: dict[tuple[int, int], SyncBitLevels] = {}
    corrected: dict[tuple[int, int], bool] = {}
    for lh in angles.stations():
        for ax in (0, 1):
            rows = np.flatnonzero((angles.lighthouse == lh) & (angles.axis == ax))
            if len(rows) == 0:
                continue
            rows = rows[np.argsort(angles.time[rows], kind="stable")]
            # the series' sweeps numbered 0.. in the order of their first hits
            _, first, which = np.unique(ids[rows], return_index=True, return_inverse=True)
            number = np.empty(len(first), dtype=np.int64)
            number[np.argsort(first)] = np.arange(len(first))
            sweep = number[which]
            lev = sync_bit_levels(angles.time[rows], sweep, angles.sensor[rows],
                                  angles.angle[rows])
            levels[(lh, ax)] = lev
            corrected[(lh, ax)] = (lev.fraction_low >= min_fraction
                                   and abs(lev.gap_rad / DATA_BIT_RAD - 1) < max_gap_error)
            if corrected[(lh, ax)]:
                out[rows] += lev.gap_rad * lev.low[sweep]
    fixed = Angles(angles.time, angles.lighthouse, angles.axis, angles.sensor, out,
                   dict(angles.extra))
    return fixed, SyncBitCorrection(levels, corrected, max_gap_error)
