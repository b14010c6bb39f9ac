"""Board captures: the ``.lhcap`` edge-record file, raw sample dumps, and edge <-> pulse.

A capture is the 32 photodiode lines sampled together (2 MHz on the board), stored as
*edges*: the sample index at which the 32-bit port word changed and the new word
(docs/formats/lhcap.md). Bit ``k`` of a word is 1 while the sensor on channel ``k`` sees light;
``channel_map[k]`` is that sensor's id (-1 = unused bit). A version-2 file adds the board
IMU's samples (:class:`CaptureImu`), each stamped with the sample index of its data-ready.
Times are in samples of the board's clock throughout.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.errors import InputError
from lhgraph.io.files import read_input, unreadable, write_atomic
from lhgraph.signal.capture_imu import IMU_PARTS, IMU_RECORD, CaptureImu, read_imu_records
from lhgraph.signal.pulses import LightPulses

MAGIC = b"LHCP"
VERSION = 1
VERSION_IMU = 2
HEADER_LEN = 108
HEADER_LEN_IMU = 128
N_CHANNELS = 32
FLAG_OVERFLOW = 1
_HEADER = struct.Struct("<4sHHIIIIQQI32h")
_HEADER_IMU = struct.Struct("<IIHHHHI")  # bytes 108..127 of a version-2 header
_RECORD = np.dtype([("sample_index", "<u4"), ("port_word", "<u4")])
assert _HEADER.size == HEADER_LEN and HEADER_LEN + _HEADER_IMU.size == HEADER_LEN_IMU


def identity_channel_map() -> NDArray[np.int16]:
    """Channel ``k`` = sensor ``k`` for all 32 channels."""
    return np.arange(N_CHANNELS, dtype=np.int16)


@dataclass
class Capture:
    """One board capture as edge records.

    ``sample_index`` (N,) strictly increasing, the first 0; ``port_word`` (N,) u32, the port
    state from that sample on; ``length_samples`` > last index; ``channel_map`` (32,) sensor
    id per port bit (-1 unused).
    """

    sample_index: NDArray[np.int64]
    port_word: NDArray[np.uint32]
    length_samples: int
    sample_rate_hz: int = 2_000_000
    channel_map: NDArray[np.int16] = field(default_factory=identity_channel_map)
    flags: int = 0
    board_id: int = 0
    firmware_version: int = 0
    start_time_us: int = 0
    imu: CaptureImu | None = None
    """The board IMU's samples (a version-2 file); None: a version-1 file."""

    def __post_init__(self) -> None:
        self.sample_index = np.asarray(self.sample_index, dtype=np.int64)
        self.port_word = np.asarray(self.port_word, dtype=np.uint32)
        self.channel_map = np.asarray(self.channel_map, dtype=np.int16).reshape(N_CHANNELS)

    def __len__(self) -> int:
        return len(self.sample_index)

    @property
    def overflowed(self) -> bool:
        """True when the board ran out of memory and stopped early."""
        return bool(self.flags & FLAG_OVERFLOW)

    @property
    def duration_s(self) -> float:
        """Capture length in seconds."""
        return self.length_samples / self.sample_rate_hz


def encode_capture(capture: Capture) -> bytes:
    """The ``.lhcap`` bytes of a capture (header, records, [IMU records,] CRC-32): version 1
    without ``capture.imu``, version 2 with it."""
    n = len(capture)
    imu = capture.imu
    header = _HEADER.pack(
        MAGIC, VERSION if imu is None else VERSION_IMU,
        HEADER_LEN if imu is None else HEADER_LEN_IMU, int(capture.sample_rate_hz),
        int(capture.flags), int(capture.board_id), int(capture.firmware_version),
        int(capture.start_time_us), int(capture.length_samples), n,
        *[int(c) for c in capture.channel_map],
    )
    records = np.empty(n, dtype=_RECORD)
    records["sample_index"] = capture.sample_index
    records["port_word"] = capture.port_word
    body = header + records.tobytes()
    if imu is not None:
        imu_records = np.empty(len(imu), dtype=IMU_RECORD)
        imu_records["sample_index"] = imu.sample_index
        imu_records["raw"] = imu.raw
        body = (header + _HEADER_IMU.pack(len(imu), imu.missed, imu.part, imu.odr_hz,
                                          imu.gyro_full_scale_dps, imu.accel_full_scale_g, 0)
                + records.tobytes() + imu_records.tobytes())
    return body + struct.pack("<I", zlib.crc32(body))


def file_layout(data: bytes) -> tuple[int, int, int, int] | None:
    """``(version, edge records, IMU records, file size they need)`` from the start of
    ``.lhcap`` bytes (its header), or None when that is no known header."""
    if len(data) < HEADER_LEN or data[:4] != MAGIC:
        return None
    version, header_len = struct.unpack_from("<HH", data, 4)
    (n,) = struct.unpack_from("<I", data, 40)
    if version == VERSION and header_len >= HEADER_LEN:
        return version, n, 0, header_len + 8 * n + 4
    if version == VERSION_IMU and header_len >= HEADER_LEN_IMU and len(data) >= HEADER_LEN_IMU:
        m = imu_header(data)[0]
        return version, n, m, header_len + 8 * n + 16 * m + 4
    return None


def imu_header(data: bytes) -> tuple[int, int, int, int, int, int]:
    """``(IMU records, missed, part, output data rate Hz, gyro full scale deg/s, accelerometer
    full scale g)`` of the bytes of a version-2 ``.lhcap`` header, zeros for version 1."""
    version, header_len = struct.unpack_from("<HH", data, 4)
    if version != VERSION_IMU or header_len < HEADER_LEN_IMU or len(data) < HEADER_LEN_IMU:
        return (0,) * 6
    return _HEADER_IMU.unpack_from(data, HEADER_LEN)[:6]


def write_capture(capture: Capture, path: str | Path, overwrite: bool = False) -> Path:
    """Write a ``.lhcap`` file atomically; refuses to replace a file unless ``overwrite``."""
    check_capture(capture)
    return write_atomic(path, encode_capture(capture), overwrite)


def check_capture(capture: Capture, source: str | Path | None = None) -> None:
    """Raise InputError unless the records follow the format's rules."""
    idx, words = capture.sample_index, capture.port_word
    if len(idx) == 0 or idx[0] != 0:
        raise InputError("the first edge record must have sample_index 0", source)
    if np.any(np.diff(idx) <= 0):
        raise InputError("edge sample indices must strictly increase", source)
    if np.any(words[1:] == words[:-1]):
        raise InputError("consecutive edge records must differ in their port word", source)
    if capture.length_samples <= idx[-1]:
        raise InputError("capture length must exceed the last edge's sample index", source)
    if idx[-1] >= 2**32:
        raise InputError("sample index does not fit in u32", source)
    imu = capture.imu
    if imu is not None:
        if len(imu) and (np.any(np.diff(imu.sample_index) <= 0) or imu.sample_index[0] < 0
                         or imu.sample_index[-1] >= capture.length_samples):
            raise InputError("IMU sample indices must strictly increase within the capture",
                             source)
        if imu.part not in IMU_PARTS and (imu.part != 0 or len(imu)):
            raise InputError(f"unknown IMU part {imu.part}", source)


def read_capture(path: str | Path) -> tuple[Capture, list[str]]:
    """Read a ``.lhcap`` file (version 1, or 2 with IMU records) -> (capture, warnings).

    A wrong magic, unknown version, short header, unknown IMU part or a file longer than its
    record counts say raise InputError. A truncated record list, a CRC mismatch, records
    that break the ordering rules, or IMU samples the board missed are reported in
    ``warnings``; the valid records (the longest valid prefix of each list) are kept.
    """
    path = Path(path)
    return decode_capture_bytes(read_input(path, "a .lhcap file"), path)


def decode_capture_bytes(data: bytes, source: str | Path | None = None
                         ) -> tuple[Capture, list[str]]:
    """Parse ``.lhcap`` bytes of version 1 or 2 (see :func:`read_capture`)."""
    if len(data) < 8 or data[:4] != MAGIC:
        raise InputError("not an .lhcap file (wrong magic)", source)
    version, header_len = struct.unpack_from("<HH", data, 4)
    if version not in (VERSION, VERSION_IMU):
        raise InputError(f"unknown .lhcap version {version}", source)
    need = HEADER_LEN if version == VERSION else HEADER_LEN_IMU
    if header_len < need:
        raise InputError(f"header length {header_len} is shorter than {need} "
                         f"(version {version})", source)
    if len(data) < header_len:
        raise InputError("file ends inside the header", source)
    fields = _HEADER.unpack_from(data, 0)
    rate, flags, board_id, fw, start_us, length, n = fields[3:10]
    channel_map = np.array(fields[10:], dtype=np.int16)
    if rate == 0:
        raise InputError("sample rate is 0", source)
    m, missed, part, odr, gyro_fs, accel_fs = imu_header(data)
    if part not in IMU_PARTS and (part != 0 or m):
        raise InputError(f"unknown IMU part {part}", source)
    if m and (gyro_fs == 0 or accel_fs == 0):
        raise InputError("IMU full scale is 0", source)
    warnings: list[str] = []
    imu_bytes = 16 * m
    expected = header_len + 8 * n + imu_bytes + 4
    if len(data) > expected:
        need_what = f"{n} records" + (f" and {m} IMU records" if m else "")
        raise InputError(f"file has {len(data)} bytes but {need_what} need {expected}", source)
    n_kept, m_kept = n, m
    if len(data) < expected:
        n_kept = min(n, (len(data) - header_len) // 8)
        m_kept = min(m, max(len(data) - header_len - 8 * n, 0) // 16)
        imu_note = f", {m_kept} of {m} IMU records" if m else ""
        warnings.append(f"truncated: {n_kept} of {n} edge records{imu_note} present, CRC "
                        "missing; kept the complete records")
    else:
        (crc,) = struct.unpack_from("<I", data, expected - 4)
        if zlib.crc32(data[:expected - 4]) != crc:
            warnings.append("CRC-32 mismatch: the file is corrupted; kept the records that "
                            "follow the ordering rules")
    records = np.frombuffer(data, dtype=_RECORD, count=n_kept, offset=header_len)
    idx = records["sample_index"].astype(np.int64)
    words = records["port_word"].astype(np.uint32)
    valid = _valid_prefix(idx, words)
    if valid < n_kept:
        warnings.append(f"edge record {valid} breaks the ordering rules; dropped it and the "
                        f"{n_kept - valid - 1} after it")
    idx, words = idx[:valid], words[:valid]
    if valid == 0:
        idx, words = np.zeros(1, np.int64), np.zeros(1, np.uint32)
        warnings.append("no valid edge records; the capture is empty")
    if length <= idx[-1]:
        warnings.append(f"capture length {length} does not exceed the last edge "
                        f"{idx[-1]}; set to last edge + 1")
        length = int(idx[-1]) + 1
    imu = None
    if version == VERSION_IMU:
        imu = read_imu_records(data, header_len + 8 * n, m_kept, int(length), warnings)
        imu.part, imu.odr_hz, imu.missed = int(part), int(odr), int(missed)
        imu.gyro_full_scale_dps, imu.accel_full_scale_g = int(gyro_fs), int(accel_fs)
        if missed:
            warnings.append(f"the board missed {missed} IMU samples while capturing")
    capture = Capture(idx, words, int(length), int(rate), channel_map, int(flags),
                      int(board_id), int(fw), int(start_us), imu)
    if capture.overflowed:
        warnings.append("the board's memory overflowed: the capture stopped early")
    return capture, warnings


def _valid_prefix(idx: NDArray[np.int64], words: NDArray[np.uint32]) -> int:
    """Length of the longest prefix that follows the record rules."""
    if len(idx) == 0 or idx[0] != 0:
        return 0
    bad = np.flatnonzero((np.diff(idx) <= 0) | (words[1:] == words[:-1]))
    return int(bad[0]) + 1 if len(bad) else len(idx)


def edges_from_words(words: NDArray[np.uint32], sample_rate_hz: int = 2_000_000,
                     channel_map: ArrayLike | None = None) -> Capture:
    """Edge records of a sequence of port words (one per sample)."""
    words = np.asarray(words)
    if len(words) == 0:
        raise InputError("no samples")
    change = np.flatnonzero(words[1:] != words[:-1]) + 1
    idx = np.concatenate([[0], change]).astype(np.int64)
    cmap = identity_channel_map() if channel_map is None else channel_map
    return Capture(idx, np.asarray(words[idx], dtype=np.uint32), len(words), int(sample_rate_hz),
                   np.asarray(cmap))


def read_raw_dump(path: str | Path, sample_rate_hz: int = 2_000_000,
                  channel_map: ArrayLike | None = None) -> Capture:
    """Read a raw dump (u32 little-endian port word per sample, no header) as edges."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise unreadable(exc, path, "a raw dump") from None
    if path.is_dir():
        raise InputError("is a directory, expected a raw dump", path)
    if size < 4:
        raise InputError("raw dump holds no sample", path)
    if size % 4:
        raise InputError(f"raw dump size {size} is not a multiple of 4 bytes", path)
    words = np.memmap(path, dtype="<u4", mode="r")
    capture = edges_from_words(words, sample_rate_hz, channel_map)
    del words
    return capture


def pulses_to_edges(pulses: LightPulses, length_samples: int,
                    channel_map: ArrayLike | None = None, sample_rate_hz: int = 2_000_000
                    ) -> Capture:
    """Edge records of light pulses (sensor ids mapped to port bits by ``channel_map``).

    Overlapping pulses on one sensor are OR-ed (light seen by either). Pulses are clipped
    to ``[0, length_samples)``; pulses of sensors not in the map raise InputError.
    """
    cmap = identity_channel_map() if channel_map is None else np.asarray(channel_map, np.int16)
    bit = _bits_of_sensors(pulses.sensor, cmap)
    start = np.clip(pulses.start, 0, length_samples)
    end = np.clip(pulses.end, 0, length_samples)
    keep = end > start
    bit, start, end = bit[keep], start[keep], end[keep]
    # Per-bit coverage counter: +1 at start, -1 at end; a bit is lit while its count > 0.
    times = np.concatenate([start, end])
    delta = np.concatenate([np.ones(len(start), np.int64), -np.ones(len(end), np.int64)])
    bits = np.concatenate([bit, bit])
    order = np.lexsort((delta, times, bits))  # per bit by time, ends before starts at a tie
    times, delta, bits = times[order], delta[order], bits[order]
    count = _segmented_cumsum(delta, bits)
    lit = count > 0
    # Sum the per-bit changes at each time: word change = XOR of toggled bits.
    prev_lit = np.r_[False, lit[:-1]]
    prev_lit[np.r_[True, bits[1:] != bits[:-1]]] = False
    toggles = lit != prev_lit
    t_toggle, b_toggle = times[toggles], bits[toggles]
    # A bit may toggle twice at one time (end then start): those cancel in the XOR.
    mask = (np.uint64(1) << b_toggle.astype(np.uint64)).astype(np.uint64)
    uniq, inv = np.unique(t_toggle, return_inverse=True)
    xor = np.zeros(len(uniq), np.uint64)
    np.bitwise_xor.at(xor, inv, mask)
    keep = (xor != 0) & (uniq < length_samples)  # a line going dark at the end is no edge
    uniq, xor = uniq[keep], xor[keep]
    words = np.bitwise_xor.accumulate(xor) if len(xor) else xor
    idx = np.concatenate([[0], uniq]).astype(np.int64)
    words = np.concatenate([[0], words]).astype(np.uint32)
    if len(idx) > 1 and idx[1] == 0:
        idx, words = idx[1:], words[1:]
    return Capture(idx, words, int(length_samples), int(sample_rate_hz), cmap)


def changed_bits(capture: Capture) -> NDArray[np.uint32]:
    """Per edge record, the port bits that changed there (the first record: its lit bits)."""
    words = capture.port_word.astype(np.uint32)
    return words ^ np.r_[np.uint32(0), words[:-1]]


def toggles_per_channel(capture: Capture) -> NDArray[np.int64]:
    """Number of edges (rising and falling) of each of the 32 port bits."""
    changed = changed_bits(capture)
    return np.array([np.count_nonzero(changed & np.uint32(1 << k)) for k in range(N_CHANNELS)],
                    dtype=np.int64)


def edges_to_pulses(capture: Capture) -> LightPulses:
    """Light pulses (per port bit, between a rising and the next falling edge) of a capture.

    Pulses of unused channels (map -1) are left out; a line still lit at the end of the
    capture ends at ``length_samples``; ``kind`` is -1 (unknown).
    """
    idx, words = capture.sample_index, capture.port_word.astype(np.uint32)
    changed = changed_bits(capture)
    sensors, starts, ends = [], [], []
    for k in range(N_CHANNELS):
        if capture.channel_map[k] < 0:
            continue
        bitk = np.uint32(1 << k)
        rows = np.flatnonzero(changed & bitk)
        if len(rows) == 0:
            continue
        level = (words[rows] & bitk) != 0
        t = idx[rows]
        rise = t[level]
        fall = t[~level]
        if len(fall) < len(rise):
            fall = np.r_[fall, capture.length_samples]
        sensors.append(np.full(len(rise), capture.channel_map[k], np.int64))
        starts.append(rise)
        ends.append(fall)
    if not sensors:
        empty = np.zeros(0, np.int64)
        return LightPulses(empty, empty, empty, empty)
    sensor = np.concatenate(sensors)
    pulses = LightPulses(sensor, np.concatenate(starts), np.concatenate(ends),
                         np.full(len(sensor), -1, np.int64))
    return pulses.sorted()


def _bits_of_sensors(sensor: NDArray, channel_map: NDArray[np.int16]) -> NDArray[np.int64]:
    """Port bit of each sensor id."""
    lookup = {int(s): k for k, s in enumerate(channel_map) if s >= 0}
    sensor = np.asarray(sensor, dtype=np.int64)
    ids, inv = np.unique(sensor, return_inverse=True)
    missing = [int(s) for s in ids if int(s) not in lookup]
    if missing:
        raise InputError(f"sensor id(s) {missing[:5]} have no channel in the capture's map")
    return np.array([lookup[int(s)] for s in ids], dtype=np.int64)[inv].reshape(sensor.shape)


def _segmented_cumsum(values: NDArray[np.int64], groups: NDArray[np.int64]) -> NDArray:
    """Cumulative sum restarting where ``groups`` (sorted) changes."""
    total = np.cumsum(values)
    starts = np.flatnonzero(np.r_[True, groups[1:] != groups[:-1]])
    offset = np.r_[0, total[starts[1:] - 1]] if len(starts) else np.zeros(0, np.int64)
    lengths = np.diff(np.r_[starts, len(values)])
    return total - np.repeat(offset, lengths)
