"""Pick the part of a capture in which the board moves (``lhgraph solve ... --duration S``).

A calibration needs the board in motion: a still board constrains the stations' relative
pose only through one board pose. Long recordings often start and end with the board at
rest, so :func:`moving_window` cuts the first ``duration_s`` seconds from the moment the
board starts moving, judged from the angles themselves (no other sensor needed):

1. (:func:`~lhgraph.estimation.rests.motion_rate`) every hit series of one (station, axis,
   sensor) gives angle rates
``|delta angle| / delta t`` between consecutive hits (at most ``max_gap_s`` apart),
   dated at the midpoint;
2. the rates are binned in ``bin_s`` bins; a bin is *moving* when the median rate of all
   series in it exceeds ``threshold_rad_s`` (the median ignores reflections and the few
   sensors a rotation about them leaves still);
3. motion starts at the first bin that opens a run of moving bins at least ``min_moving_s``
   long (a bump of the table is not a start);
4. the window is ``[start, start + duration_s)``; it may end in still data, and is shorter
   when the capture ends first.

Why the default threshold: at rest the median rate is noise, ~1 mrad/s on the hive
recording (30 Hz sweeps, ~50 urad angle noise) and ~2 mrad/s for 2 MHz quantisation; a board
waved at 2 m gives 50-140 mrad/s. 10 mrad/s (2 cm/s at 2 m) separates them with a margin.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.estimation.rests import motion_rate
from lhgraph.io.angles import Angles

Array = NDArray[np.float64]


def motion_start(angles: Angles, threshold_rad_s: float = 0.01, min_moving_s: float = 1.0,
                 bin_s: float = 0.25, max_gap_s: float = 0.1) -> float:
    """Time (s) at which the board starts moving for at least ``min_moving_s``.

    Raises :class:`InputError` when it never does (see the module docstring).
    """
    start, rate = motion_rate(angles, bin_s, max_gap_s)
    moving = np.nan_to_num(rate, nan=0.0) > threshold_rad_s
    run = max(int(np.ceil(min_moving_s / bin_s)), 1)
    if len(moving) >= run:
        sustained = np.convolve(moving.astype(np.int64), np.ones(run, dtype=np.int64),
                                "valid") == run
        if np.any(sustained):
            return float(start[int(np.argmax(sustained))])
    peak = np.nanmax(rate) if np.any(np.isfinite(rate)) else 0.0
    raise InputError(f"the board never moves for {min_moving_s:g} s (median angle rate at most "
                     f"{peak * 1e3:.1f} mrad/s, threshold {threshold_rad_s * 1e3:.1f} mrad/s)",
                     where="angles")


def moving_window(angles: Angles, duration_s: float, threshold_rad_s: float = 0.01,
                  min_moving_s: float = 1.0, bin_s: float = 0.25, max_gap_s: float = 0.1
                  ) -> Angles:
    """The hits of the first ``duration_s`` seconds (times in s) from the moment the board
    starts moving (:func:`motion_start`), times unchanged.

    Raises :class:`InputError` for a non-positive duration, a board that never moves or a
    window without hits.
    """
    if not duration_s > 0:
        raise InputError(f"duration must be > 0 s, got {duration_s:g}", where="--duration")
    t_start = motion_start(angles, threshold_rad_s, min_moving_s, bin_s, max_gap_s)
    keep = (angles.time >= t_start) & (angles.time < t_start + duration_s)
    if not keep.any():
        raise InputError(f"no hit within {duration_s:g} s of the motion's start "
                         f"(t = {t_start:.3f} s)", where="--duration")
    return angles.select(keep)
