"""Raw-signal synthesis: turn a simulated capture into the edge records a real board records.

The simulator (:mod:`lhgraph.sim.simulate`) gives the slot schedule (each station's sync start
sample per slot, who sweeps which axis) and the laser sweep pulses. This adds what the
photodiodes also see: every station's sync flash in every slot, on every sensor facing that
station, with its width encoding ``skip``, ``data`` (the station's OOTX bit stream: CRC-valid
LH1 frames of its factory calibration, back to back) and ``axis`` (SPEC §3); optionally
carrier chatter, echo pulses, missed flashes and a station vanishing. A capture simulated
with an IMU also gets its samples as the board's ICM-42688-P records them (a version-2
capture: counts at +-2000 deg/s and +-16 g, stamped with the board sample at or after each
sample's time). Times in samples of the board clock.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.gravity import accel_dir_from_up
from lhgraph.geometry.transforms import inverse, transform_points
from lhgraph.model.calibration import StationCalibration
from lhgraph.signal.capture import Capture, pulses_to_edges, write_capture
from lhgraph.signal.capture_imu import CaptureImu
from lhgraph.signal.ootx import OotxPayload, encode_frame, pack_payload
from lhgraph.signal.pulses import LightPulses
from lhgraph.signal.sync import SYNC_BASE_S, SYNC_STEP_S
from lhgraph.sim.common import SimulatedCapture


@dataclass(frozen=True)
class CaptureOptions:
    """Imperfections of the synthesised signal (fractions are per pulse / per flash).

    ``sync_shortfall_s``: each sensor's flash is shorter than nominal by U(0, this);
    ``chatter_fraction``: pulses split by 1-3 dark samples (laser carrier);
    ``echo_fraction``: sweep pulses followed by a weaker (shorter) echo in the same sweep;
    ``missing_sync_fraction``: flashes no sensor sees; ``vanish``: (station, time s) after
    which that station is gone (no flashes, no sweeps); ``max_incidence_deg``: sensors
    further off-axis do not see a flash.
    """

    sync_shortfall_s: float = 3e-6
    chatter_fraction: float = 0.0
    echo_fraction: float = 0.0
    missing_sync_fraction: float = 0.0
    vanish: tuple[int, float] | None = None
    max_incidence_deg: float = 80.0
    board_id: int = 0
    firmware_version: int = 0


def default_calibrations(sim: SimulatedCapture) -> dict[int, StationCalibration]:
    """Each station's factory calibration from the simulator's truth; id ``0x1000 + index``,
    ``accel_dir`` from the scene's up vector (as an upright station would measure it)."""
    up = np.asarray(sim.truth.extra["simulation"]["up"], dtype=float)
    return {i: StationCalibration(s.model.calibration, 0x1000 + i,
                                  accel_dir_from_up(s.T_world_lh[:3, :3].T @ up))
            for i, s in sim.truth.stations.items()}


def ootx_bits(calibration: StationCalibration, n_bits: int, start: int) -> NDArray[np.uint8]:
    """``n_bits`` of a station's endless OOTX stream, from bit ``start`` of its frame."""
    frame = encode_frame(pack_payload(OotxPayload.from_calibration(calibration)))
    return frame[(start + np.arange(n_bits)) % len(frame)]


def synthesize_capture(sim: SimulatedCapture,
                       calibrations: dict[int, StationCalibration] | None = None,
                       rng: np.random.Generator | None = None,
                       options: CaptureOptions | None = None) -> Capture:
    """The capture (edge records, channel k = k-th board sensor) a board would record."""
    rng = rng if rng is not None else np.random.default_rng(0)
    opt = options or CaptureOptions()
    calibrations = calibrations or default_calibrations(sim)
    fs = float(sim.config.sample_rate_hz)
    slots = sim.slots
    K, n = slots.sync_start_sample.shape
    board = sim.board

    # sync flashes: width from (skip, data, axis); every facing sensor sees them
    k = np.repeat(np.arange(K), n)
    st = np.tile(np.arange(n), K)
    start = slots.sync_start_sample.reshape(-1)
    skip = (slots.sweeping[k] != st).astype(int)
    axis = slots.axis[k]
    data = np.zeros(len(k), dtype=int)
    for s in range(n):
        sel = st == s
        cal = calibrations.get(s)
        if cal is not None:
            data[sel] = ootx_bits(cal, int(np.count_nonzero(sel)), int(rng.integers(1000)))
    width_s = SYNC_BASE_S + SYNC_STEP_S * (4 * skip + 2 * data + axis)
    flash = rng.random(len(k)) >= opt.missing_sync_fraction
    flash &= (start >= 0) & (start < sim.n_samples)
    if opt.vanish is not None:
        flash &= ~((st == opt.vanish[0]) & (start / fs >= opt.vanish[1]))
    k, st, start, width_s = k[flash], st[flash], start[flash], width_s[flash]

    T_world_board = sim.motion.pose(start / fs)
    T_world_lh = np.stack([sim.truth.pose(i) for i in range(n)])
    T_lh_world = inverse(T_world_lh)[st]
    S = len(board.ids)
    p_world = transform_points(np.repeat(T_world_board, S, axis=0),
                               np.tile(board.positions, (len(st), 1)))
    n_world = np.einsum("nij,nj->ni", np.repeat(T_world_board[:, :3, :3], S, axis=0),
                        np.tile(board.normals, (len(st), 1)))
    st_rep = np.repeat(st, S)
    to_station = T_world_lh[st_rep, :3, 3] - p_world
    cos_inc = np.sum(n_world * to_station, axis=1) / np.linalg.norm(to_station, axis=1)
    in_front = transform_points(np.repeat(T_lh_world, S, axis=0), p_world)[:, 0] > 0
    sees = (cos_inc > np.cos(np.radians(opt.max_incidence_deg))) & in_front
    sensor = np.tile(board.ids, len(st))[sees]
    f_start = np.repeat(start, S)[sees]
    f_width = np.repeat(width_s, S)[sees] - rng.uniform(0, opt.sync_shortfall_s, sees.sum())
    f_end = f_start + np.maximum(np.round(f_width * fs).astype(np.int64), 1)

    # sweep pulses (minus a vanished station's), echoes and carrier chatter
    sweeps = sim.pulses
    keep = np.ones(len(sweeps), dtype=bool)
    if opt.vanish is not None:
        keep = ~((sim.angles.lighthouse == opt.vanish[0]) & (sweeps.start / fs >= opt.vanish[1]))
    s_sensor, s_start, s_end = sweeps.sensor[keep], sweeps.start[keep], sweeps.end[keep]
    s_kind = sweeps.kind[keep]
    echo = rng.random(len(s_sensor)) < opt.echo_fraction
    echo_delay = rng.integers(40, 400, echo.sum())  # 20-200 us later, 1 sample+ shorter
    echo_len = np.maximum((s_end - s_start)[echo] // 2, 1)
    e_start = s_end[echo] + echo_delay
    pulses = LightPulses(
        np.concatenate([sensor, s_sensor, s_sensor[echo]]),
        np.concatenate([f_start, s_start, e_start]),
        np.concatenate([f_end, s_end, e_start + echo_len]),
        np.concatenate([np.full(len(sensor), LightPulses.SYNC), s_kind,
                        np.full(echo.sum(), LightPulses.REFLECTION)]).astype(np.int64),
    )
    pulses = _chatter(pulses, opt.chatter_fraction, rng)
    channel_map = np.full(32, -1, dtype=np.int16)
    channel_map[:S] = board.ids
    capture = pulses_to_edges(pulses, sim.n_samples, channel_map, int(round(fs)))
    capture.board_id, capture.firmware_version = opt.board_id, opt.firmware_version
    if sim.imu is not None:
        imu = CaptureImu.from_stream(sim.imu.stream, fs,
                                     odr_hz=int(round(sim.config.imu.rate_hz)))
        inside = imu.sample_index < sim.n_samples
        imu.sample_index, imu.raw = imu.sample_index[inside], imu.raw[inside]
        capture.imu = imu
    return capture


def _chatter(p: LightPulses, fraction: float, rng: np.random.Generator) -> LightPulses:
    """Split a ``fraction`` of the pulses (those >= 4 samples) by a 1-3-sample dark gap."""
    length = p.end - p.start
    split = (rng.random(len(p)) < fraction) & (length >= 5)
    if not np.any(split):
        return p
    gap = rng.integers(1, 4, split.sum())
    cut = p.start[split] + 1 + (rng.random(split.sum()) * (length[split] - gap - 1)).astype(int)
    return _split(p, split, cut, gap)


def _split(p: LightPulses, split: NDArray, cut: NDArray, gap: NDArray) -> LightPulses:
    """Pulses with ``split`` ones ending at ``cut`` and resuming at ``cut + gap``."""
    end = p.end.copy()
    end[split] = cut
    return LightPulses(np.concatenate([p.sensor, p.sensor[split]]),
                       np.concatenate([p.start, cut + gap]),
                       np.concatenate([end, p.end[split]]),
                       np.concatenate([p.kind, p.kind[split]]))


CAPTURE_FILE = "capture.lhcap"


def write_simulated_capture(sim: SimulatedCapture, out_dir: str | Path, overwrite: bool = False,
                            options: CaptureOptions | None = None) -> Path:
    """Synthesise ``sim``'s raw signal (seeded by its config's seed) into
    ``out_dir/capture.lhcap``."""
    rng = np.random.default_rng([int(sim.config.seed), 0x1CA9])
    capture = synthesize_capture(sim, None, rng, options)
    return write_capture(capture, Path(out_dir) / CAPTURE_FILE, overwrite)
