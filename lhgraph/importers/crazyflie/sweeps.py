"""The log's ``lhAngle`` events as an angles table (:func:`lh1_angles`, :func:`lh2_angles`),
and the system type they come from (:func:`sweep_interval_s`).

What the log holds (measured on the real LH1 log, docs/crazyflie.md): the deck firmware logs
the latest angle pair (both sweeps) of every base station each time one station's pair
completes, so a station's pair is often logged twice, the second time as an exact copy
(``angle`` and ``correctedAngle`` bit-identical) next to the other station's fresh pair.
These repeats are the "extra" sweeps of station 0; they are dropped, the first logging of
each measurement is kept. After that every station and sweep arrives every 33.3 ms (30 Hz),
as LH1 with two stations must.

Hit time: the firmware logs a station's pair :data:`LOG_DELAY_S` after the sync flash that
ends the slot of the pair's last sweep (axis 1; measured against the deck's raw
``lhUartFrame`` pulses); within a slot the laser crosses a diode at ``T/4 + angle T/(2 pi)``
after the slot's sync (SPEC §3, ``T`` = 1/60 s), and axis 0 was swept one slot
(:data:`SLOT_S`) before axis 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.importers.crazyflie.usdlog import UsdLog
from lhgraph.io.angles import Angles
from lhgraph.model.boards import crazyflie_deck

Array = NDArray[np.float64]

ROTOR_PERIOD_S = 1.0 / 60.0
SLOT_S = ROTOR_PERIOD_S / 2
"""One LH1 sweep slot (half a rotor turn), s."""
LOG_DELAY_S = 0.18e-3
"""Delay from the sync flash after a pair's last sweep to its ``lhAngle`` events (median on
the real log, benchmarks/crazyflie_log_evidence.py)."""
LH2_MAX_INTERVAL_S = 0.025
"""LH1 sweeps a station's axis every 33.3 ms; LH2 rotors turn every 18.5-20 ms."""
LH2_PERIOD_RANGE_S = (0.0184, 0.0201)
"""The 16 LH2 channels' rotor periods (SPEC §8), s."""
BURST_GAP_S = 1e-3
"""The deck logs a measurement's events within a burst of < 1 ms; bursts are >= 6 ms apart."""


@dataclass(frozen=True)
class SweepSummary:
    """What :func:`lh1_angles` kept and dropped: per station, hits kept, exact repeats
    dropped, invalid hits dropped (:func:`valid_hits`)."""

    kept: dict[int, int]
    repeats: dict[int, int]
    invalid: int

    def lines(self) -> list[str]:
        """Human-readable lines for the import summary."""
        st = sorted(set(self.kept) | set(self.repeats))
        return [
            "hits kept: " + ", ".join(f"station {s}: {self.kept.get(s, 0)}" for s in st),
            "dropped repeated hits (an earlier pair logged again, bit-identical): "
            + ", ".join(f"station {s}: {self.repeats.get(s, 0)}" for s in st),
            f"dropped invalid hits (an angle not finite or beyond pi, a sweep not 0 or 1, a "
            f"sensor not on the deck): {self.invalid}",
        ]


def _angle_events(log: UsdLog) -> tuple[NDArray, NDArray[np.float64]]:
    return log.events["lhAngle"], log.time_s("lhAngle")


def repeated_hits(log: UsdLog) -> NDArray[np.bool_]:
    """Per ``lhAngle`` event: True when it repeats the previous event of the same
    (base station, sweep, sensor) bit for bit (angle and correctedAngle)."""
    a, t = _angle_events(log)
    order = np.lexsort((t, a["sensor"], a["sweep"], a["basestation"]))
    s = a[order]
    same = np.r_[False, (s["basestation"][1:] == s["basestation"][:-1])
                 & (s["sweep"][1:] == s["sweep"][:-1]) & (s["sensor"][1:] == s["sensor"][:-1])
                 & (s["angle"][1:] == s["angle"][:-1])
                 & (s["correctedAngle"][1:] == s["correctedAngle"][:-1])]
    out = np.zeros(len(a), dtype=bool)
    out[order] = same
    return out


def sweep_interval_s(log: UsdLog) -> float:
    """Median time (s) between new measurements of one station, sweep and sensor: ~0.033 on
    LH1, ~0.019 on LH2 (nan without angles)."""
    a, t = _angle_events(log)
    new = ~repeated_hits(log)
    key = (a["basestation"].astype(np.int64) * 2 + a["sweep"]) * 256 + a["sensor"]
    key, t = key[new], t[new]
    order = np.lexsort((t, key))
    dt = np.diff(t[order])[np.diff(key[order]) == 0]
    return float(np.median(dt)) if len(dt) else float("nan")


def valid_hits(a: NDArray) -> NDArray[np.bool_]:
    """Per ``lhAngle`` event: both angles finite and within [-pi, pi] (rad), the sweep 0 or
    1 and the sensor one of the deck's four."""
    ok = np.ones(len(a), dtype=bool)
    for name in ("angle", "correctedAngle"):
        value = a[name].astype(float)
        ok &= np.isfinite(value) & (np.abs(value) <= np.pi)
    return ok & np.isin(a["sweep"], (0, 1)) & np.isin(a["sensor"], crazyflie_deck().ids)


def _summary(a: NDArray, station: NDArray, repeat: NDArray, valid: NDArray) -> SweepSummary:
    stations = np.unique(a["basestation"]).astype(int)
    kept = {int(s): int(np.sum(station == s)) for s in stations}
    repeats = {int(s): int(np.sum(repeat & (a["basestation"] == s))) for s in stations}
    return SweepSummary(kept, repeats, int(np.sum(~valid & ~repeat)))


def lh1_angles(log: UsdLog) -> tuple[Angles, SweepSummary]:
    """The angles table of an LH1 log: station = the log's base-station index, axis = its
    sweep (0 horizontal = azimuth, 1 vertical = elevation), ``angle`` as measured; extra
    columns ``corrected_angle`` (the firmware's) and ``log_time`` (s, the event's stamp on
    ``log``'s clock). Repeats and invalid hits (:func:`valid_hits`) are dropped and counted."""
    a, t = _angle_events(log)
    repeat = repeated_hits(log)
    valid = valid_hits(a)
    keep = ~repeat & valid
    k = a[keep]
    axis = k["sweep"].astype(np.int64)
    angle = k["angle"].astype(float)
    in_slot = ROTOR_PERIOD_S / 4 + angle * ROTOR_PERIOD_S / (2 * np.pi)
    time = t[keep] - LOG_DELAY_S - SLOT_S + in_slot - (1 - axis) * SLOT_S
    order = np.argsort(time, kind="stable")
    station = k["basestation"].astype(np.int64)
    angles = Angles(time[order], station[order], axis[order], k["sensor"].astype(np.int64)[order],
                    angle[order],
                    {"corrected_angle": k["correctedAngle"].astype(float)[order],
                     "log_time": t[keep][order]})
    return angles, _summary(a, station, repeat, valid)


def lh2_angles(log: UsdLog) -> tuple[Angles, SweepSummary]:
    """The angles table of an LH2 log: station = the log's base-station index, axis = its
    sweep (0 = the first light plane, tilted -30°; 1 = the second, +30°), ``angle`` as
    measured; extra columns ``corrected_angle`` and ``log_time`` as :func:`lh1_angles`.
    Repeats (a station's last measurement logged again with another station's: measured on
    the real log, docs/crazyflie.md) and invalid hits (:func:`valid_hits`) are dropped and
    counted.

    Hit time: the deck logs a diode's two planes when the second has passed; within one
    revolution of period ``T`` (each station's median spacing of measurements) plane i
    crosses at rotor time ``(angle_i + 2 pi (i + 1) / 3) T / 2 pi`` (the deck's angle
    offsets of the two planes), so a plane-0 hit is moved back from the stamp by
    ``(angle_1 - angle_0 + 2 pi / 3) T / 2 pi`` (~6.7 ms) with the same diode's plane-1 angle
    of the burst (its own angle when that is missing); a plane-1 hit keeps its stamp (a
    common logging delay stays: it shifts every state alike)."""
    a, t = _angle_events(log)
    repeat = repeated_hits(log)
    valid = valid_hits(a)
    keep = ~repeat & valid
    k, t = a[keep], t[keep]
    station = k["basestation"].astype(np.int64)
    axis = k["sweep"].astype(np.int64)
    sensor = k["sensor"].astype(np.int64)
    angle = k["angle"].astype(float)
    burst = np.r_[0, np.cumsum(np.diff(t) > BURST_GAP_S)]
    # the plane-1 angle of each hit's diode in its burst
    key = (burst * 256 + station) * 256 + sensor
    plane1 = dict(zip(key[axis == 1].tolist(), angle[axis == 1].tolist(), strict=True))
    a1 = np.array([plane1.get(kk, aa) for kk, aa in zip(key.tolist(), angle.tolist(),
                                                       strict=True)])
    period = np.array([_rotor_period(t[station == s], burst[station == s])
                       for s in range(int(station.max(initial=-1)) + 1)])
    behind = np.where(axis == 0, a1 - angle + 2 * np.pi / 3, a1 - angle)
    time = t - behind * period[station] / (2 * np.pi) if len(t) else t
    order = np.argsort(time, kind="stable")
    angles = Angles(time[order], station[order], axis[order], sensor[order], angle[order],
                    {"corrected_angle": k["correctedAngle"].astype(float)[order],
                     "log_time": t[order]})
    return angles, _summary(a, station, repeat, valid)


def _rotor_period(t: Array, burst: NDArray[np.int64]) -> float:
    """A station's LH2 rotor period (s): the median spacing of its logged measurements
    within the channels' range (the slowest channel's period when none is)."""
    starts = t[np.r_[True, np.diff(burst) > 0]] if len(t) else t
    gap = np.diff(starts)
    near = gap[(gap > LH2_PERIOD_RANGE_S[0] * 0.98) & (gap < LH2_PERIOD_RANGE_S[1] * 1.02)]
    return float(np.median(near)) if len(near) else LH2_PERIOD_RANGE_S[1]
