"""Lighthouse v1 sync flashes: clustering, slot grid, flash codes and rotor periods.

Sync-length pulses seen by one or more sensors at once are clustered into flashes; each
flash is placed on the grid of 8.333 ms slots with its role (0: the station that flashes
first in a slot, 1: the one ~416.7 us later); the flash widths select the LH1 slot pattern
(which station skips and which axis is swept) and give each flash's OOTX data bit; a
least-squares line through each station's flashes gives its rotor period. Times are in
samples of the capture clock unless named ``_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.signal.decode_report import DecodeReport, StationTiming
from lhgraph.signal.pulses import LightPulses

ROTOR_HZ = 60.0
SYNC_BASE_S = 62.5e-6  # width of a sync flash with skip = data = axis = 0
SYNC_STEP_S = 10.0 / 960.0 * 1e-3  # 10.4167 us per unit of (4 skip + 2 data + axis)
STATION_OFFSET_SLOTS = 0.05  # second station flashes 20 000 / 400 000 of a slot later
# LH1 pattern over 4 slots (libsurvive's ordering): does the first-flashing station skip?
FIRST_SKIPS = np.array([1, 1, 0, 0])
PATTERN_AXIS = np.array([0, 1, 0, 1])


@dataclass
class SyncFlashes:
    """Sync flashes (one per cluster): first rising edge, widest width, sensor count."""

    start: NDArray[np.float64]
    width: NDArray[np.float64]
    n_sensors: NDArray[np.int64]


def cluster_syncs(pulses: LightPulses, is_sync: NDArray, gap: float) -> SyncFlashes:
    """Group sync-length pulses whose starts follow each other within ``gap`` samples."""
    start = pulses.start[is_sync].astype(float)
    end = pulses.end[is_sync].astype(float)
    if len(start) == 0:
        return SyncFlashes(np.zeros(0), np.zeros(0), np.zeros(0, np.int64))
    first = np.flatnonzero(np.r_[True, np.diff(start) > gap])
    return SyncFlashes(np.minimum.reduceat(start, first),
                       np.maximum.reduceat(end - start, first), np.diff(np.r_[first, len(start)]))


def slot_grid(syncs: SyncFlashes, rate: float, tolerance_s: float, report: DecodeReport
              ) -> tuple[NDArray, NDArray, NDArray] | None:
    """Slot index and role (0 first, 1 second flasher) of each sync flash.

    A flash is on the grid within ``tolerance_s``. Returns (slot, role, kept mask) for the
    flashes on the grid; off-grid and duplicate flashes are dropped (reported).
    """
    t = syncs.start - syncs.start[0]
    slot_nom = rate / (2 * ROTOR_HZ)
    slot_len = _estimate_slot(t, slot_nom)
    if slot_len is None:
        report.notes.append("no two sync flashes a whole slot apart: cannot find the rotor "
                            "period")
        return None
    tol = tolerance_s * rate / slot_len
    # Phase of the first flasher: maximise the flashes at c or c + 0.05 (a few candidates).
    phase = np.mod(t / slot_len, 1.0)
    candidates = phase[:: max(1, len(phase) // 256)]

    def near(x: NDArray, c: NDArray, width: float) -> NDArray:
        return np.abs(np.mod(x[:, None] - c[None, :] + 0.5, 1.0) - 0.5) < width

    wide = 3 * tol
    score = (near(phase, candidates, wide).sum(axis=0)
             + near(phase, candidates + STATION_OFFSET_SLOTS, wide).sum(axis=0))
    c = candidates[int(np.argmax(score))]
    role = np.full(len(t), -1)
    for width in (wide, tol, tol):
        role[:] = -1
        for r in (0, 1):
            role[near(phase, np.array([c + r * STATION_OFFSET_SLOTS]), width)[:, 0]] = r
        on = role >= 0
        u = t / slot_len - c - role * STATION_OFFSET_SLOTS
        n = np.round(u)
        if np.count_nonzero(on) < 2 or np.ptp(n[on]) == 0:
            break  # fewer than two slots to refine the period and phase on
        # refine period and phase on the flashes assigned so far (both roles share them)
        A = np.stack([np.ones(np.count_nonzero(on)), n[on]], axis=1)
        offset, slot_len = np.linalg.lstsq(A, t[on] - (c + role[on] * STATION_OFFSET_SLOTS)
                                           * slot_len, rcond=None)[0]
        c = c + offset / slot_len
        phase = np.mod(t / slot_len, 1.0)
    role[:] = -1
    for r in (0, 1):
        role[near(phase, np.array([c + r * STATION_OFFSET_SLOTS]), tol)[:, 0]] = r
    keep = role >= 0
    report.drop("sync flashes off the slot grid", np.count_nonzero(~keep))
    slot = np.round(t / slot_len - c - role * STATION_OFFSET_SLOTS).astype(np.int64)
    # duplicates of (slot, role): keep the flash seen by most sensors
    idx = np.flatnonzero(keep)
    order = np.lexsort((-syncs.n_sensors[idx], role[idx], slot[idx]))
    idx = idx[order]
    dup = np.zeros(len(idx), dtype=bool)  # no flash on the grid: nothing to deduplicate
    dup[1:] = (slot[idx][1:] == slot[idx][:-1]) & (role[idx][1:] == role[idx][:-1])
    keep[idx[dup]] = False
    report.drop("duplicate sync flashes in one slot", np.count_nonzero(dup))
    slot = slot - slot[keep].min() if np.any(keep) else slot
    return slot[keep], role[keep], keep


def _estimate_slot(t: NDArray, slot_nom: float) -> float | None:
    """Slot length (samples) from flash pairs a whole number of slots apart."""
    estimates = []
    for lag in (1, 2, 4, 8, 16):
        if len(t) <= lag:
            break
        d = t[lag:] - t[:-lag]
        ratio = d / slot_nom
        k = np.round(ratio)
        ok = (k >= 1) & (np.abs(ratio - k) < 0.002 * np.maximum(k, 1))
        estimates.append(d[ok] / k[ok])
    est = np.concatenate(estimates) if estimates else np.zeros(0)
    return float(np.median(est)) if len(est) else None


@dataclass(frozen=True)
class SlotPattern:
    """Which station sweeps which axis in slot n: the standard two-station LH1 cycle at
    phase ``phase`` (slot n is cycle step (n + phase) % 4), or one station sweeping every
    slot with axes alternating."""

    single: bool
    phase: int

    def bits(self, slot: NDArray, role: NDArray) -> tuple[NDArray, NDArray]:
        """Expected (skip, axis) of the flash of ``role`` in ``slot``."""
        if self.single:
            return np.zeros_like(slot), (slot + self.phase) % 2
        cyc = (slot + self.phase) % 4
        return np.where(role == 0, FIRST_SKIPS[cyc], 1 - FIRST_SKIPS[cyc]), PATTERN_AXIS[cyc]

    def sweeping(self, slot: NDArray) -> tuple[NDArray, NDArray]:
        """(station, axis) swept in ``slot``."""
        if self.single:
            return np.zeros_like(slot), (slot + self.phase) % 2
        cyc = (slot + self.phase) % 4
        return FIRST_SKIPS[cyc], PATTERN_AXIS[cyc]


def classify_flashes(slot: NDArray, role: NDArray, width_s: NDArray, report: DecodeReport
                     ) -> tuple[SlotPattern, NDArray]:
    """The slot pattern that best explains the flash widths, and each flash's data bit.

    Skip and axis add 4 and 1 width steps, data 2; widths fall short of nominal by up to
    ~10 us, so data 0 is expected near -2.6 us and data 1 near +18.2 us of the nominal
    data-0 width.
    """
    hypotheses = ([SlotPattern(False, k) for k in range(4)]
                  + [SlotPattern(True, k) for k in range(2)])
    best, best_cost, best_residual = hypotheses[0], np.inf, width_s
    for h in hypotheses:
        skip, axis = h.bits(slot, role)
        residual = width_s - (SYNC_BASE_S + SYNC_STEP_S * (axis + 4 * skip))
        cost = np.minimum(np.abs(residual + 0.25 * SYNC_STEP_S),
                          np.abs(residual - 1.75 * SYNC_STEP_S))
        total = np.minimum(cost, SYNC_STEP_S).sum()
        if total < best_cost:
            best, best_cost, best_residual = h, total, residual
    data = (best_residual > 0.75 * SYNC_STEP_S).astype(np.int64)
    odd = (best_residual < -1.2 * SYNC_STEP_S) | (best_residual > 2.3 * SYNC_STEP_S)
    if np.any(odd):
        report.notes.append(f"{np.count_nonzero(odd)} sync flashes have widths that fit no "
                            "code (their OOTX bits are unreliable)")
    if best.single:
        report.notes.append("one station only (it sweeps every slot)")
    return best, data


def fit_periods(slot: NDArray, role: NDArray, start: NDArray, rate: float, period: str,
                report: DecodeReport) -> dict[int, tuple[float, float]]:
    """Per station: (slot length, offset) in samples, sync start = offset + slot * length.

    ``period``: ``"fit"`` (least squares) or ``"nominal"`` (1/60 s, offset from the median).
    """
    fits = {}
    nominal = rate / (2 * ROTOR_HZ)
    for r in (0, 1):
        m = role == r
        if not np.any(m):
            continue
        n, t = slot[m].astype(float), start[m]
        if np.count_nonzero(m) >= 2 and np.ptp(n) > 0:
            length, offset = np.polyfit(n, t, 1)
        else:
            length, offset = nominal, float(t[0] - n[0] * nominal)
        resid = t - (offset + n * length)
        if period == "nominal":
            length = nominal
            offset = float(np.median(t - n * length))
            resid = t - (offset + n * length)
        fits[r] = (float(length), float(offset))
        report.stations.append(StationTiming(
            r, int(np.count_nonzero(m)), 2 * length / rate, offset / rate,
            float(np.sqrt(np.mean(resid ** 2))) / rate))
    return fits
