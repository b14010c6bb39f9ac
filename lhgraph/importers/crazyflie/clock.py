"""The Crazyflie log's clock against the Lighthouse deck's: seconds of the deck per second of
the log (:func:`deck_clock`).

The Crazyflie stamps every event with its own clock. The deck's FPGA stamps every light
pulse it forwards (``lhUartFrame``: ``timestampFPGA``, a 24-bit counter of
:data:`FPGA_HZ` that wraps every 0.7 s), and that counter keeps the stations' time: on the
shared LH1 logs a sync-to-sync slot is 200 005.5 ticks against the 200 000 of 8.333 ms
(28 ppm). Against it the shared logs' own clock runs 1.09 % slow (1.01106-1.01108 deck
seconds per log second on all four; Qualisys, aligned by its marker events, says
1.01105-1.01108). An IMU integrated on the log's clock would turn 1.1 % too little and
travel 2.2 % too short, so the importer writes every time on the deck's clock.

The rate is the slope of the unwrapped counter against the frames' log stamps: the frames
are cut into runs at log gaps over :data:`MAX_GAP_S` (a wrap could hide in a longer one),
each run keeps its own offset, and frames stamped over :data:`JITTER_S` off the line (the
log stamps a frame when the Crazyflie reads it) are dropped, five times over.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lhgraph.importers.crazyflie.usdlog import UsdLog

FPGA_HZ = 24e6
"""Ticks per second of the deck's pulse counter."""
FPGA_WRAP = 1 << 24
MAX_GAP_S = 0.3
JITTER_S = 2e-3
MIN_FRAMES = 100
PLAUSIBLE_SCALE = (0.95, 1.05)
"""A scale outside this is not a clock's drift but a counter of another kind: not applied."""


@dataclass(frozen=True)
class DeckClock:
    """Deck seconds per log second (``scale``), from ``frames`` raw frames, with the
    median distance of their log stamps from the fit (``jitter_s``)."""

    scale: float
    frames: int
    jitter_s: float

    @property
    def plausible(self) -> bool:
        """Whether ``scale`` is a clock's drift (:data:`PLAUSIBLE_SCALE`)."""
        return PLAUSIBLE_SCALE[0] <= self.scale <= PLAUSIBLE_SCALE[1]

    def line(self) -> str:
        """One summary line."""
        if not self.plausible:
            return (f"clock: the log's own; the deck's pulse counter gives {self.scale:.6f} "
                    f"deck s per log s ({self.frames} raw frames), not a clock's drift: "
                    "not applied")
        return (f"clock: the deck's (log times x {self.scale:.6f}: the log's clock runs "
                f"{abs(1 - 1 / self.scale) * 100:.2f} % {'slow' if self.scale > 1 else 'fast'}; "
                f"{self.frames} raw frames, median jitter {self.jitter_s * 1e3:.2f} ms)")


def deck_clock(log: UsdLog) -> DeckClock | None:
    """The deck's clock against ``log``'s (its ``lhUartFrame`` events), None with fewer than
    :data:`MIN_FRAMES` of them or too short a span to fit."""
    if log.count("lhUartFrame") < MIN_FRAMES or \
            "timestampFPGA" not in log.events["lhUartFrame"].dtype.names:
        return None
    t = log.time_s("lhUartFrame") / log.clock_scale
    order = np.argsort(t, kind="stable")
    t = t[order]
    ticks = log.events["lhUartFrame"]["timestampFPGA"].astype(np.int64)[order]
    step = (np.diff(ticks) + FPGA_WRAP // 2) % FPGA_WRAP - FPGA_WRAP // 2
    run = np.r_[0, np.cumsum(np.diff(t) > MAX_GAP_S)]
    counter = np.r_[0, np.cumsum(step)].astype(float)
    keep = np.ones(len(t), dtype=bool)
    for _ in range(5):
        tc, kc = _centred(t, run, keep), _centred(counter, run, keep)
        denominator = float(tc[keep] @ tc[keep])
        if denominator <= 0 or keep.sum() < MIN_FRAMES:
            return None
        rate = float(tc[keep] @ kc[keep]) / denominator
        residual_s = np.abs(kc - rate * tc) / rate
        keep = residual_s < JITTER_S + np.median(residual_s[keep])
    return DeckClock(rate / FPGA_HZ, int(keep.sum()), float(np.median(residual_s[keep])))


def _centred(x: np.ndarray, run: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``x`` less the mean of its run's kept values."""
    n = run.max() + 1
    mean = (np.bincount(run[keep], x[keep], minlength=n)
            / np.maximum(np.bincount(run[keep], minlength=n), 1))
    return x - mean[run]
