"""Rests: where the board lies still, found from the angles alone, and their sweeps thinned
for the calibration (``GraphOptions.rest_keep_every``).

Why thin them: at rest every sweep repeats one board pose, and with it whatever error
repeats at each diode (a sensor position off by a fraction of a millimetre, a diode's own
delay: on the hive recording 39-58 µrad rms, as large as the noise, docs/hive.md). Such an
error does not average out over a rest's thousands of sweeps, yet counted as independent
noise those sweeps outweigh the motion and pull the stations towards what that one pose's
errors say (on the hive recording ~2 mm). Keeping a few of them keeps the pose and its
information on the stations, without the false weight.

A rest is a run of at least ``min_rest_s`` of bins of :func:`motion_rate` at or below
``threshold_rad_s`` (the thresholds of :func:`lhgraph.workflow.window.motion_start`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.angles import Angles

Array = NDArray[np.float64]
REST_WINDOW_S = 0.1
"""Thinning keeps whole windows of this length (every station's sweep period, LH1's 33 ms
per station and axis and LH2's ~20 ms, fits in one), so the kept sweeps are complete cycles."""


def motion_rate(angles: Angles, bin_s: float = 0.25, max_gap_s: float = 0.1
                ) -> tuple[Array, Array]:
    """Median angle rate (rad/s) of all hit series per time bin.

    Returns ``(bin_start_s, median_rate_rad_s)``; bins without any rate are NaN. Bins start
    at the first hit time and are ``bin_s`` long.
    """
    key = (angles.lighthouse.astype(np.int64) * 2 + angles.axis) * (
        int(angles.sensor.max(initial=0)) + 1) + angles.sensor
    order = np.lexsort((angles.time, key))
    k, t, a = key[order], angles.time[order], angles.angle[order]
    dt = np.diff(t)
    pair = (k[1:] == k[:-1]) & (dt > 0) & (dt <= max_gap_s)
    rate = np.abs(np.diff(a))[pair] / dt[pair]
    mid = 0.5 * (t[1:] + t[:-1])[pair]
    t0 = float(angles.time.min(initial=0.0))
    n_bins = max(int(np.ceil((float(angles.time.max(initial=0.0)) - t0) / bin_s)), 1)
    b = np.minimum(((mid - t0) / bin_s).astype(np.int64), n_bins - 1)
    median = np.full(n_bins, np.nan)
    order = np.lexsort((rate, b))
    b, rate = b[order], rate[order]
    bounds = np.searchsorted(b, np.arange(n_bins + 1))
    for i in np.flatnonzero(np.diff(bounds) > 0):
        median[i] = np.median(rate[bounds[i]:bounds[i + 1]])
    return t0 + bin_s * np.arange(n_bins), median


@dataclass(frozen=True)
class RestThinning:
    """What :func:`thin_rests` did: the rests found (``spans_s``, (n, 2) start and end, s),
    the hits it left out and those it kept within the rests."""

    spans_s: Array
    hits_dropped: int
    hits_kept: int

    def summary(self) -> str:
        """One line for the progress output."""
        total = float(np.sum(self.spans_s[:, 1] - self.spans_s[:, 0]))
        return (f"{len(self.spans_s)} rest(s) of the board, {total:.1f} s in all: "
                f"{self.hits_dropped} of their {self.hits_dropped + self.hits_kept} hits "
                "left out of the calibration")


def rest_spans(angles: Angles, threshold_rad_s: float = 0.01, min_rest_s: float = 1.0,
               bin_s: float = 0.25, max_gap_s: float = 0.1) -> Array:
    """``(n, 2)`` start and end times (s) of the rests: runs of at least ``min_rest_s`` of
    :func:`motion_rate` bins at or below ``threshold_rad_s`` (a bin without rates, a gap in
    the data, ends a rest)."""
    start, rate = motion_rate(angles, bin_s, max_gap_s)
    still = np.r_[False, rate <= threshold_rad_s, False]  # NaN compares False
    edges = np.flatnonzero(np.diff(still.astype(np.int8)))
    first, stop = edges[::2], edges[1::2]
    long = (stop - first) * bin_s >= min_rest_s - 1e-9
    return np.c_[start[first[long]], start[first[long]] + (stop - first)[long] * bin_s]


def thin_rests(angles: Angles, keep_every: int, **rest_options: float
               ) -> tuple[Angles, RestThinning]:
    """``angles`` with, within each rest (:func:`rest_spans`, ``rest_options`` passed on),
    only the hits of one ``REST_WINDOW_S`` window in ``keep_every`` (the first of the rest,
    then every ``keep_every``-th); ``keep_every`` 1 keeps everything."""
    spans = rest_spans(angles, **rest_options)
    t = angles.time
    keep = np.ones(len(angles), dtype=bool)
    in_rest = np.zeros(len(angles), dtype=bool)
    for t0, t1 in spans:
        m = (t >= t0) & (t < t1)
        in_rest |= m
        window = np.floor((t[m] - t0) / REST_WINDOW_S).astype(np.int64)
        keep[m] = window % keep_every == 0
    dropped = int(np.sum(~keep))
    return (angles if dropped == 0 else angles.select(keep),
            RestThinning(spans, dropped, int(np.sum(keep & in_rest))))
