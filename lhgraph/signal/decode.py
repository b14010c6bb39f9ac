"""Lighthouse v1 signal decoding: light pulses -> sync flashes -> sweep angles + OOTX.

Pipeline (docs/decoding.md): edges -> per-sensor pulses (carrier gaps merged) -> sync
flashes (sync-length pulses on one or more sensors at once, clustered) -> slot grid (which
8.333 ms slot each flash belongs to and whether its station flashes first or second) ->
classification of each flash (skip / data / axis bits, from its width and the LH1 slot
pattern) -> rotor period per station (least-squares fit over the whole capture) -> sweep hits
(the longest short pulse of a sensor in a slot) -> angle (SPEC §3) -> OOTX frames per station.

Station numbering: station 0 is the station whose sync flash comes *first* in each slot,
station 1 the one flashing ~416.7 us later; this is read from the signal and stable for a
capture. Times are in samples of the capture clock (``sample_rate_hz``) inside, seconds in
the output; angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.angles import Angles, save_angles
from lhgraph.io.files import check_writable
from lhgraph.model.board import Board
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.signal.capture import Capture, edges_to_pulses, read_capture, read_raw_dump
from lhgraph.signal.libsurvive import read_libsurvive
from lhgraph.signal.ootx import OotxDecoder, unpack_payload
from lhgraph.signal.pulses import LightPulses

ROTOR_HZ = 60.0
SYNC_BASE_S = 62.5e-6  # width of a sync flash with skip = data = axis = 0
SYNC_STEP_S = 10.0 / 960.0 * 1e-3  # 10.4167 us per unit of (4 skip + 2 data + axis)
STATION_OFFSET_SLOTS = 0.05  # second station flashes 20 000 / 400 000 of a slot later
# LH1 pattern over 4 slots (libsurvive's ordering): does the first-flashing station skip?
FIRST_SKIPS = np.array([1, 1, 0, 0])
PATTERN_AXIS = np.array([0, 1, 0, 1])
SWEEP_WINDOW_SLOTS = (0.1, 1.0)  # laser hits accepted this far into a slot (after 1st flash)


@dataclass(frozen=True)
class DecodeOptions:
    """Tuning of the decoder (times in seconds).

    ``period``: ``"fit"`` measures each rotor's period from its sync train (least squares
    over the capture), ``"nominal"`` uses 1/60 s (as libsurvive does).
    ``sync_reference``: ``"measured"`` times each sweep from its own sync flash's first rising
    edge, ``"fitted"`` from the fitted sync train (removes the per-sweep sampling error of
    the sync edge; a sweep whose flash was missed is still decoded).
    """

    period: str = "fit"
    sync_reference: str = "measured"
    merge_gap_s: float = 1.6e-6
    sync_width_s: tuple[float, float] = (45e-6, 145e-6)
    max_sweep_width_s: float = 45e-6
    stuck_width_s: float = 1e-3
    cluster_gap_s: float = 30e-6
    grid_tolerance_s: float = 20e-6
    max_pulses_per_sweep: int = 4

    def __post_init__(self) -> None:
        if self.period not in ("fit", "nominal"):
            raise InputError(f"period must be 'fit' or 'nominal', got {self.period!r}")
        if self.sync_reference not in ("measured", "fitted"):
            raise InputError("sync_reference must be 'measured' or 'fitted', got "
                             f"{self.sync_reference!r}")


@dataclass
class StationTiming:
    """What the sync train says about one station (times in seconds of the capture)."""

    index: int
    flashes: int
    period_s: float
    offset_s: float
    residual_rms_s: float
    ootx_frames: int = 0
    ootx_bad_crc: int = 0
    ootx_bad_stuffing: int = 0


@dataclass
class DecodeReport:
    """What the decoder kept, dropped and why."""

    pulses: int = 0
    merged_gaps: int = 0
    sync_flashes: int = 0
    sweep_hits: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    stations: list[StationTiming] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def drop(self, reason: str, count: int) -> None:
        """Count ``count`` items dropped for ``reason`` (zero counts are not recorded)."""
        if count:
            self.dropped[reason] = self.dropped.get(reason, 0) + int(count)

    def lines(self) -> list[str]:
        """Human-readable summary."""
        out = [f"{self.pulses} pulses ({self.merged_gaps} carrier gaps merged), "
               f"{self.sync_flashes} sync flashes, {self.sweep_hits} sweep hits"]
        for s in self.stations:
            out.append(f"station {s.index}: {s.flashes} flashes, period {s.period_s * 1e3:.6f} ms,"
                       f" sync residual {s.residual_rms_s * 1e6:.2f} us rms, OOTX "
                       f"{s.ootx_frames} frames ok, {s.ootx_bad_crc} bad CRC, "
                       f"{s.ootx_bad_stuffing} bad stuffing")
        out += [f"dropped {n}: {reason}" for reason, n in self.dropped.items()]
        return out + self.notes


@dataclass
class DecodeResult:
    """Decoded sweep angles (with an int column ``sweep`` = slot counter), the factory
    calibration of every station whose OOTX frame decoded, and the report."""

    angles: Angles
    calibrations: dict[int, StationCalibration]
    report: DecodeReport


@dataclass
class _Syncs:
    """Sync flashes (one per cluster): first rising edge, widest width, sensor count."""

    start: NDArray[np.float64]
    width: NDArray[np.float64]
    n_sensors: NDArray[np.int64]


def decode_capture(capture: Capture, board: Board | None = None,
                   options: DecodeOptions | None = None) -> DecodeResult:
    """Decode a board capture (edge records) into angles, OOTX calibration and a report."""
    pulses = edges_to_pulses(capture)
    return decode_pulses(pulses, capture.sample_rate_hz, board, options)


def decode_pulses(pulses: LightPulses, sample_rate_hz: float, board: Board | None = None,
                  options: DecodeOptions | None = None) -> DecodeResult:
    """Decode light pulses (sensor ids, start/end in samples at ``sample_rate_hz``)."""
    opt = options or DecodeOptions()
    rate = float(sample_rate_hz)
    report = DecodeReport()
    pulses = pulses.sorted()
    if board is not None and len(pulses):
        known = np.isin(pulses.sensor, board.ids)
        report.drop("pulses of sensors not on the board", np.count_nonzero(~known))
        pulses = _select(pulses, known)
    pulses, report.merged_gaps = merge_carrier_gaps(pulses, int(opt.merge_gap_s * rate + 1e-9))
    report.pulses = len(pulses)
    width = (pulses.end - pulses.start).astype(float)
    stuck = width > opt.stuck_width_s * rate
    if np.any(stuck):
        sensors = sorted(set(pulses.sensor[stuck].tolist()))
        report.drop(f"pulses longer than {opt.stuck_width_s * 1e3:g} ms (sensor stuck high? "
                    f"sensors {sensors[:8]})", np.count_nonzero(stuck))
    is_sync = (width >= opt.sync_width_s[0] * rate) & (width <= opt.sync_width_s[1] * rate)
    is_sweep = width <= opt.max_sweep_width_s * rate
    report.drop("pulses too long for a sweep, too short or long for a sync",
                np.count_nonzero(~is_sync & ~is_sweep & ~stuck))
    syncs = _cluster_syncs(pulses, is_sync, opt.cluster_gap_s * rate)
    empty = DecodeResult(_empty_angles(), {}, report)
    if len(syncs.start) < 2:
        report.notes.append("fewer than two sync flashes: nothing to decode")
        return empty
    grid = _slot_grid(syncs, rate, opt, report)
    if grid is None:
        return empty
    slot, role, keep = grid
    if not np.any(keep):
        report.notes.append("no sync flash on the slot grid: nothing to decode")
        return empty
    syncs = _Syncs(syncs.start[keep], syncs.width[keep], syncs.n_sensors[keep])
    report.sync_flashes = len(syncs.start)
    pattern, data = _classify(slot, role, syncs.width / rate, report)
    fits = _fit_periods(slot, role, syncs.start, rate, opt, report)
    angles = _sweep_angles(pulses, is_sweep, pattern, slot, role, syncs.start, fits, rate, opt,
                           report)
    calibrations = _ootx(slot, role, data, report)
    report.sweep_hits = len(angles)
    return DecodeResult(angles, calibrations, report)


def merge_carrier_gaps(pulses: LightPulses, max_gap: int) -> tuple[LightPulses, int]:
    """Join pulses of one sensor separated by at most ``max_gap`` dark samples.

    Returns (pulses sorted by start, number of gaps merged).
    """
    if len(pulses) < 2 or max_gap <= 0:
        return pulses, 0
    order = np.lexsort((pulses.start, pulses.sensor))
    s, a, b, k = (pulses.sensor[order], pulses.start[order], pulses.end[order],
                  pulses.kind[order])
    same = s[1:] == s[:-1]
    # running end per sensor: shift each sensor's ends above the previous sensors' ones
    group = np.cumsum(np.r_[0, ~same])
    lift = (int(b.max()) - int(a.min()) + 1) * group
    run_end = np.maximum.accumulate(b + lift) - lift
    new = np.r_[True, ~same | (a[1:] - run_end[:-1] > max_gap)]
    first = np.flatnonzero(new)
    merged = LightPulses(s[first], a[first], np.maximum.reduceat(b, first), k[first])
    return merged.sorted(), len(s) - len(first)


def _select(p: LightPulses, mask: NDArray) -> LightPulses:
    return LightPulses(p.sensor[mask], p.start[mask], p.end[mask], p.kind[mask])


def _empty_angles() -> Angles:
    z = np.zeros(0)
    zi = np.zeros(0, np.int64)
    return Angles(z, zi, zi, zi, z, {"sweep": zi})


def _cluster_syncs(pulses: LightPulses, is_sync: NDArray, gap: float) -> _Syncs:
    """Group sync-length pulses whose starts follow each other within ``gap`` samples."""
    start = pulses.start[is_sync].astype(float)
    end = pulses.end[is_sync].astype(float)
    if len(start) == 0:
        return _Syncs(np.zeros(0), np.zeros(0), np.zeros(0, np.int64))
    first = np.flatnonzero(np.r_[True, np.diff(start) > gap])
    return _Syncs(np.minimum.reduceat(start, first), np.maximum.reduceat(end - start, first),
                  np.diff(np.r_[first, len(start)]))


def _slot_grid(syncs: _Syncs, rate: float, opt: DecodeOptions, report: DecodeReport
               ) -> tuple[NDArray, NDArray, NDArray] | None:
    """Slot index and role (0 first, 1 second flasher) of each sync flash.

    Returns (slot, role, kept mask) for the flashes on the grid; off-grid and duplicate
    flashes are dropped (reported).
    """
    t = syncs.start - syncs.start[0]
    slot_nom = rate / (2 * ROTOR_HZ)
    slot_len = _estimate_slot(t, slot_nom)
    if slot_len is None:
        report.notes.append("no two sync flashes a whole slot apart: cannot find the rotor "
                            "period")
        return None
    tol = opt.grid_tolerance_s * rate / slot_len
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
class _Pattern:
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


def _classify(slot: NDArray, role: NDArray, width_s: NDArray, report: DecodeReport
              ) -> tuple[_Pattern, NDArray]:
    """The slot pattern that best explains the flash widths, and each flash's data bit.

    Skip and axis add 4 and 1 width steps, data 2; widths fall short of nominal by up to
    ~10 us, so data 0 is expected near -2.6 us and data 1 near +18.2 us of the nominal
    data-0 width.
    """
    hypotheses = [_Pattern(False, k) for k in range(4)] + [_Pattern(True, k) for k in range(2)]
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


def _fit_periods(slot: NDArray, role: NDArray, start: NDArray, rate: float,
                 opt: DecodeOptions, report: DecodeReport) -> dict[int, tuple[float, float]]:
    """Per station: (slot length, offset) in samples, sync start = offset + slot * length."""
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
        if opt.period == "nominal":
            length = nominal
            offset = float(np.median(t - n * length))
            resid = t - (offset + n * length)
        fits[r] = (float(length), float(offset))
        report.stations.append(StationTiming(
            r, int(np.count_nonzero(m)), 2 * length / rate, offset / rate,
            float(np.sqrt(np.mean(resid ** 2))) / rate))
    return fits


def _sweep_angles(pulses: LightPulses, is_sweep: NDArray, pattern: _Pattern, slot: NDArray,
                  role: NDArray, sync_start: NDArray, fits: dict[int, tuple[float, float]],
                  rate: float, opt: DecodeOptions, report: DecodeReport) -> Angles:
    """Angles of the sweep pulses, each timed from its sweeping station's sync flash."""
    # the first flasher's grid (or the only station's) locates the slots
    ref = 0 if 0 in fits else 1
    ref_len, ref_off = fits[ref]
    ref_off -= ref * STATION_OFFSET_SLOTS * ref_len
    p = _select(pulses, is_sweep)
    centre = 0.5 * (p.start + p.end).astype(float)
    u = (centre - ref_off) / ref_len
    n = np.floor(u).astype(np.int64)
    inside = (u - n >= SWEEP_WINDOW_SLOTS[0]) & (n >= slot.min()) & (n <= slot.max())
    report.drop("short pulses during sync flashes or outside the capture's slots",
                np.count_nonzero(~inside))
    p, centre, n = _select(p, inside), centre[inside], n[inside]
    st, axis = pattern.sweeping(n)
    if opt.sync_reference == "fitted":
        known = np.isin(st, list(fits))
        length = np.array([fits.get(r, (np.nan, 0))[0] for r in (0, 1)])[st]
        offset = np.array([fits.get(r, (0, np.nan))[1] for r in (0, 1)])[st]
        t_sync = offset + n * length
        report.drop("sweep pulses of a station without a sync train", np.count_nonzero(~known))
    else:
        known, t_sync, extrapolated = _own_sync(n, st, slot, role, sync_start, fits)
        report.drop("sweep pulses before their sweeping station's first sync flash",
                    np.count_nonzero(~known))
        if np.any(extrapolated & known):
            report.notes.append(f"{np.count_nonzero(extrapolated & known)} sweep pulses timed "
                                "from an earlier flash of their station (sync flash missed)")
    p, centre, n, st, axis, t_sync = (_select(p, known), centre[known], n[known], st[known],
                                      axis[known], t_sync[known])
    if len(p) == 0:
        return _empty_angles()
    # one hit per (sensor, slot): the longest pulse; too many pulses = noise
    width = (p.end - p.start).astype(float)
    order = np.lexsort((-width, p.sensor, n))
    first = np.r_[True, (n[order][1:] != n[order][:-1])
                  | (p.sensor[order][1:] != p.sensor[order][:-1])]
    group = np.cumsum(first) - 1
    noisy = np.bincount(group)[group] > opt.max_pulses_per_sweep
    report.drop(f"sweep pulses of sensors with more than {opt.max_pulses_per_sweep} pulses "
                "in one sweep (noise)", np.count_nonzero(noisy))
    report.drop("extra pulses of a sensor in one sweep (reflections; kept the longest)",
                np.count_nonzero(~first & ~noisy))
    chosen = order[first & ~noisy]
    chosen = chosen[np.argsort(centre[chosen], kind="stable")]
    period = 2 * np.array([fits.get(r, (np.nan, 0))[0] for r in (0, 1)])[st[chosen]]
    angle = (centre[chosen] - t_sync[chosen] - period / 4) * 2 * np.pi / period
    return Angles(centre[chosen] / rate, st[chosen].astype(np.int64),
                  axis[chosen].astype(np.int64), p.sensor[chosen].astype(np.int64), angle,
                  {"sweep": n[chosen].astype(np.int64)})


def _own_sync(n: NDArray, st: NDArray, slot: NDArray, role: NDArray, sync_start: NDArray,
              fits: dict[int, tuple[float, float]]) -> tuple[NDArray, NDArray, NDArray]:
    """Sync start of station ``st`` in slot ``n``: its own flash there, else its latest
    earlier flash plus whole slots. Returns (found, start in samples, extrapolated)."""
    found = np.zeros(len(n), bool)
    t_sync = np.zeros(len(n))
    extrapolated = np.zeros(len(n), bool)
    for r, (length, _) in fits.items():
        mine = np.flatnonzero(st == r)
        order = np.argsort(slot[role == r])
        slots_r, starts_r = slot[role == r][order], sync_start[role == r][order]
        idx = np.searchsorted(slots_r, n[mine], side="right") - 1
        ok = idx >= 0
        idx = np.maximum(idx, 0)
        found[mine] = ok
        t_sync[mine] = starts_r[idx] + (n[mine] - slots_r[idx]) * length
        extrapolated[mine] = slots_r[idx] != n[mine]
    return found, t_sync, extrapolated


def _ootx(slot: NDArray, role: NDArray, data: NDArray, report: DecodeReport
          ) -> dict[int, StationCalibration]:
    """Decode each station's OOTX bit stream (restarting after missed flashes)."""
    out: dict[int, StationCalibration] = {}
    timing = {s.index: s for s in report.stations}
    for r in (0, 1):
        m = role == r
        if not np.any(m):
            continue
        n, bits = slot[m], data[m]
        order = np.argsort(n)
        n, bits = n[order], bits[order]
        breaks = np.flatnonzero(np.diff(n) != 1) + 1
        good = []
        bad_crc = bad_stuffing = 0
        for segment in np.split(bits, breaks):
            dec = OotxDecoder()
            good += [f.payload for f in dec.push_bits(segment) if f.crc_ok]
            bad_crc += dec.bad_crc
            bad_stuffing += dec.bad_stuffing
        if r in timing:
            timing[r].ootx_frames = len(good)
            timing[r].ootx_bad_crc = bad_crc
            timing[r].ootx_bad_stuffing = bad_stuffing
        payloads = [g for g in good if len(g) >= 33]
        if len(payloads) < len(good):
            report.notes.append(f"station {r}: {len(good) - len(payloads)} OOTX frames too short "
                                "for an LH1 payload")
        if payloads:
            if len(set(payloads)) > 1:
                report.notes.append(f"station {r}: OOTX frames disagree; used the last one")
            out[r] = unpack_payload(payloads[-1]).to_calibration()
        else:
            report.notes.append(f"station {r}: no complete OOTX frame (needs ~3 s of flashes)")
    return out


FORMATS = ("lhcap", "raw", "libsurvive")
ANGLES_FILE = "angles.csv"
OOTX_FILE = "ootx.toml"


def guess_format(path: str | Path) -> str:
    """Input format from the file name: ``.lhcap``, ``.raw``/``.bin``, ``.rec``/``.rec.gz``."""
    name = Path(path).name.lower()
    if name.endswith(".lhcap"):
        return "lhcap"
    if name.endswith((".raw", ".bin")):
        return "raw"
    if name.endswith((".rec", ".rec.gz")):
        return "libsurvive"
    raise InputError("cannot tell the format from the name; give --format "
                     f"({'|'.join(FORMATS)})", path)


def decode_file(path: str | Path, fmt: str | None = None, device: str | None = None,
                board: Board | None = None, options: DecodeOptions | None = None,
                sample_rate_hz: float | None = None) -> tuple[DecodeResult, list[str]]:
    """Read and decode a capture file -> (result, reader warnings).

    ``lhcap``: the board's edge file; ``raw``: a raw sample dump (``sample_rate_hz``, default
    2 MHz; channel k = sensor k); ``libsurvive``: one ``device``'s raw light of a libsurvive
    recording (48 MHz ticks from the device's first pulse; default period ``nominal``, as
    libsurvive decodes).
    """
    fmt = fmt or guess_format(path)
    if fmt == "libsurvive":
        recording = read_libsurvive(path, device)
        options = options or DecodeOptions(period="nominal")
        return decode_pulses(recording.pulses, recording.sample_rate_hz, board, options), []
    if fmt == "raw":
        capture = read_raw_dump(path, int(sample_rate_hz or 2_000_000))
        warnings: list[str] = []
    elif fmt == "lhcap":
        capture, warnings = read_capture(path)
    else:
        raise InputError(f"unknown format {fmt!r} (expected {'|'.join(FORMATS)})")
    return decode_capture(capture, board, options), warnings


def write_decoded(result: DecodeResult, out_dir: str | Path, overwrite: bool = False
                  ) -> list[Path]:
    """Write ``angles.csv`` and (when any station's OOTX decoded) ``ootx.toml``."""
    out_dir = Path(out_dir)
    targets = [out_dir / ANGLES_FILE] + ([out_dir / OOTX_FILE] if result.calibrations else [])
    for target in targets:
        check_writable(target, overwrite)
    written = [save_angles(result.angles, targets[0], overwrite)]
    if result.calibrations:
        written.append(save_calibration(result.calibrations, targets[1], overwrite))
    return written
