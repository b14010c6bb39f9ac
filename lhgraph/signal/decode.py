"""Lighthouse v1 signal decoding: light pulses -> sync flashes -> sweep angles + OOTX.

Pipeline (docs/decoding.md): edges -> per-sensor pulses (carrier gaps merged) -> sync
flashes (sync-length pulses on one or more sensors at once, clustered) -> slot grid (which
8.333 ms slot each flash belongs to and whether its station flashes first or second) ->
classification of each flash (skip / data / axis bits, from its width and the LH1 slot
pattern) -> rotor period per station (least-squares fit over the whole capture) -> sweep hits
(the longest short pulse of a sensor in a slot) -> angle (SPEC §3) -> OOTX frames per station.
The sync-flash stages are in ``lhgraph.signal.sync``; reading files of each kind into the
decoder is ``lhgraph.signal.formats``.

Station numbering: station 0 is the station whose sync flash comes *first* in each slot,
station 1 the one flashing ~416.7 us later; this is read from the signal and stable for a
capture. Times are in samples of the capture clock (``sample_rate_hz``) inside, seconds in
the output; angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from lhgraph.choices import PERIODS, SYNCS
from lhgraph.errors import InputError
from lhgraph.io.angles import Angles
from lhgraph.io.imu import ImuStream
from lhgraph.model.board import Board
from lhgraph.model.calibration import StationCalibration
from lhgraph.signal.capture import Capture, edges_to_pulses, toggles_per_channel
from lhgraph.signal.decode_report import DecodeReport
from lhgraph.signal.ootx import OotxDecoder, unpack_payload
from lhgraph.signal.pulses import LightPulses
from lhgraph.signal.sync import (
    STATION_OFFSET_SLOTS,
    SlotPattern,
    SyncFlashes,
    classify_flashes,
    cluster_syncs,
    fit_periods,
    slot_grid,
)

SWEEP_WINDOW_SLOTS = (0.1, 1.0)  # laser hits accepted this far into a slot (after 1st flash)
NOISE_SAMPLES_PER_EDGE = 16
"""A photodiode channel with more than one edge per this many samples, on average over the
capture, carries no Lighthouse signal: sync flashes and sweeps light a sensor for a few
percent of each 8.333 ms slot, so even a flash chopped by a visible carrier averages less
than one edge per 50 samples (random bits: one per 2)."""


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
        if self.period not in PERIODS:
            raise InputError(f"period must be 'fit' or 'nominal', got {self.period!r}")
        if self.sync_reference not in SYNCS:
            raise InputError("sync_reference must be 'measured' or 'fitted', got "
                             f"{self.sync_reference!r}")


@dataclass
class DecodeResult:
    """Decoded sweep angles (with an int column ``sweep`` = slot counter), the factory
    calibration of every station whose OOTX frame decoded, the report, and the capture's
    IMU samples in ``imu.csv``'s units on the angles' clock (None: the recording has none)."""

    angles: Angles
    calibrations: dict[int, StationCalibration]
    report: DecodeReport
    imu: ImuStream | None = None


def decode_capture(capture: Capture, board: Board | None = None,
                   options: DecodeOptions | None = None) -> DecodeResult:
    """Decode a board capture (edge records) into angles, OOTX calibration and a report;
    a version-2 capture's IMU samples become ``result.imu`` (time = sample index / rate, the
    angles' clock).

    Channels with more edges than one per :data:`NOISE_SAMPLES_PER_EDGE` samples are left
    out before pulses are built (reported), which also bounds the work on input that is not
    a capture at all.
    """
    edges = toggles_per_channel(capture)
    noisy = (edges * NOISE_SAMPLES_PER_EDGE > capture.length_samples) & (capture.channel_map >= 0)
    if np.any(noisy):
        capture = replace(capture, channel_map=np.where(noisy, -1, capture.channel_map))
    result = decode_pulses(edges_to_pulses(capture), capture.sample_rate_hz, board, options)
    result.report.drop(f"edges of channels with more than one edge per {NOISE_SAMPLES_PER_EDGE} "
                       f"samples (noise; channels {np.flatnonzero(noisy)[:8].tolist()})",
                       int(edges[noisy].sum()))
    imu = capture.imu
    if imu is not None and len(imu):
        result.imu = imu.stream(capture.sample_rate_hz)
        result.report.notes.append(
            f"IMU: {len(imu)} samples of the {imu.part_name} at {imu.odr_hz} Hz"
            + (f" ({imu.missed} missed by the board)" if imu.missed else ""))
    elif imu is not None:
        result.report.notes.append("IMU: none in the capture"
                                   + (" (the board found no IMU)" if imu.part == 0 else ""))
    return result


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
    syncs = cluster_syncs(pulses, is_sync, opt.cluster_gap_s * rate)
    empty = DecodeResult(_empty_angles(), {}, report)
    if len(syncs.start) < 2:
        report.notes.append("fewer than two sync flashes: nothing to decode")
        return empty
    grid = slot_grid(syncs, rate, opt.grid_tolerance_s, report)
    if grid is None:
        return empty
    slot, role, keep = grid
    if not np.any(keep):
        report.notes.append("no sync flash on the slot grid: nothing to decode")
        return empty
    syncs = SyncFlashes(syncs.start[keep], syncs.width[keep], syncs.n_sensors[keep])
    report.sync_flashes = len(syncs.start)
    pattern, data = classify_flashes(slot, role, syncs.width / rate, report)
    fits = fit_periods(slot, role, syncs.start, rate, opt.period, report)
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


def _sweep_angles(pulses: LightPulses, is_sweep: NDArray, pattern: SlotPattern, slot: NDArray,
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
