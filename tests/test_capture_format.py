"""The .lhcap edge-record format, raw dumps, and pulse <-> edge conversions."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lhgraph.errors import InputError
from lhgraph.io.imu import STANDARD_GRAVITY_MPS2, ImuStream
from lhgraph.signal.capture import (
    Capture,
    decode_capture_bytes,
    edges_from_words,
    edges_to_pulses,
    encode_capture,
    file_layout,
    pulses_to_edges,
    read_capture,
    read_raw_dump,
    write_capture,
)
from lhgraph.signal.capture_imu import CaptureImu
from lhgraph.signal.pulses import LightPulses


def _dense(sensor, start, end, length, channel_map=None):
    """Port words per sample, by brute force (the reference for the vectorised code)."""
    bit_of = {s: k for k, s in enumerate(range(32) if channel_map is None else channel_map)}
    words = np.zeros(length, np.uint32)
    for s, a, b in zip(sensor, start, end, strict=True):
        words[max(a, 0):max(min(b, length), 0)] |= np.uint32(1 << bit_of[int(s)])
    return words


def _random_pulses(rng, n=500, length=50_000, n_sensors=32):
    sensor = rng.integers(0, n_sensors, n)
    start = rng.integers(0, length, n)
    end = start + rng.integers(1, 60, n)
    return LightPulses(sensor, start, end, np.zeros(n, np.int64))


def test_known_bytes_of_a_tiny_capture():
    cap = Capture(np.array([0, 5]), np.array([0, 0b101]), 9, channel_map=np.arange(32))
    data = encode_capture(cap)
    assert data[:4] == b"LHCP"
    assert struct.unpack_from("<HHIIIIQQI", data, 4) == (1, 108, 2_000_000, 0, 0, 0, 0, 9, 2)
    assert struct.unpack_from("<4I", data, 108) == (0, 0, 5, 5)
    assert len(data) == 108 + 16 + 4
    assert struct.unpack_from("<I", data, 124)[0] == zlib.crc32(data[:124])


def test_write_read_round_trip_and_refuses_overwrite(tmp_path):
    rng = np.random.default_rng(1)
    cmap = np.r_[np.arange(100, 130), -1, -1]
    pulses = _random_pulses(rng, n_sensors=30)
    pulses.sensor += 100
    cap = pulses_to_edges(pulses, 60_000, cmap)
    cap.board_id, cap.firmware_version, cap.start_time_us = 7, 0x010203, 1_700_000_000_000_000
    path = write_capture(cap, tmp_path / "a.lhcap")
    back, warnings = read_capture(path)
    assert warnings == []
    assert np.array_equal(back.sample_index, cap.sample_index)
    assert np.array_equal(back.port_word, cap.port_word)
    assert np.array_equal(back.channel_map, cmap)
    assert (back.length_samples, back.board_id, back.firmware_version, back.start_time_us) == (
        60_000, 7, 0x010203, 1_700_000_000_000_000)
    with pytest.raises(InputError, match="exists already"):
        write_capture(cap, path)
    write_capture(cap, path, overwrite=True)


def test_pulses_to_edges_matches_brute_force_and_back():
    rng = np.random.default_rng(2)
    pulses = _random_pulses(rng, n=3000)
    length = 50_100
    cap = pulses_to_edges(pulses, length)
    dense = _dense(pulses.sensor, pulses.start, pulses.end, length)
    ref = edges_from_words(dense)
    assert np.array_equal(cap.sample_index, ref.sample_index)
    assert np.array_equal(cap.port_word, ref.port_word)
    back = edges_to_pulses(cap)
    assert np.array_equal(_dense(back.sensor, back.start, back.end, length), dense)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 31), st.integers(-5, 300), st.integers(0, 40)),
                max_size=40))
def test_pulses_to_edges_property(items):
    length = 320
    sensor = np.array([i[0] for i in items], np.int64)
    start = np.array([i[1] for i in items], np.int64)
    end = start + np.array([i[2] for i in items], np.int64)
    cap = pulses_to_edges(LightPulses(sensor, start, end, np.zeros(len(items), np.int64)), length)
    dense = _dense(sensor, start, end, length)
    ref = edges_from_words(dense)
    assert np.array_equal(cap.sample_index, ref.sample_index)
    assert np.array_equal(cap.port_word, ref.port_word)


def test_truncated_file_keeps_complete_records(tmp_path):
    cap = pulses_to_edges(_random_pulses(np.random.default_rng(3)), 60_000)
    data = encode_capture(cap)
    back, warnings = decode_capture_bytes(data[:108 + 8 * 10 + 3])
    assert len(back) == 10 and "truncated" in warnings[0]
    assert np.array_equal(back.port_word, cap.port_word[:10])


def test_crc_mismatch_reported_and_bad_records_dropped():
    cap = pulses_to_edges(_random_pulses(np.random.default_rng(4)), 60_000)
    data = bytearray(encode_capture(cap))
    struct.pack_into("<I", data, 108 + 8 * 20, 0)  # record 20's index goes backwards
    back, warnings = decode_capture_bytes(bytes(data))
    assert any("CRC" in w for w in warnings)
    assert any("record 20" in w for w in warnings)
    assert len(back) == 20


@pytest.mark.parametrize("mutate, message", [
    (lambda d: b"XXXX" + d[4:], "wrong magic"),
    (lambda d: d[:4] + struct.pack("<H", 3) + d[6:], "unknown .lhcap version"),
    (lambda d: d[:6] + struct.pack("<H", 50) + d[8:], "shorter than"),
    (lambda d: d + b"\0" * 8, "records need"),
    (lambda d: d[:60], "inside the header"),
    (lambda d: b"", "wrong magic"),
])
def test_bad_headers_raise(mutate, message):
    cap = Capture(np.array([0, 5]), np.array([0, 1]), 9)
    with pytest.raises(InputError, match=message):
        decode_capture_bytes(mutate(encode_capture(cap)), "x.lhcap")


def _imu_capture(m: int = 50, seed: int = 6) -> Capture:
    """A random capture with ``m`` IMU samples (version 2)."""
    rng = np.random.default_rng(seed)
    cap = pulses_to_edges(_random_pulses(rng), 60_000)
    index = np.sort(rng.choice(60_000, m, replace=False))
    cap.imu = CaptureImu(index, rng.integers(-32768, 32768, (m, 6)), odr_hz=1000, missed=0)
    return cap


def test_version_2_layout_and_round_trip(tmp_path):
    cap = Capture(np.array([0, 5]), np.array([0, 0b101]), 9, channel_map=np.arange(32),
                  imu=CaptureImu([3, 7], [[1, -2, 3, -4, 5, -6], [7, 8, 9, 10, 11, 12]],
                                 odr_hz=500, missed=4))
    data = encode_capture(cap)
    # docs/formats/lhcap.md: version 2, 128-byte header, the IMU fields at 108
    assert struct.unpack_from("<HH", data, 4) == (2, 128)
    assert struct.unpack_from("<IIHHHHI", data, 108) == (2, 4, 1, 500, 2000, 16, 0)
    assert struct.unpack_from("<4I", data, 128) == (0, 0, 5, 5)
    assert struct.unpack_from("<I6h", data, 144) == (3, 1, -2, 3, -4, 5, -6)
    assert struct.unpack_from("<I6h", data, 160) == (7, 7, 8, 9, 10, 11, 12)
    assert len(data) == 128 + 16 + 32 + 4
    assert struct.unpack_from("<I", data, len(data) - 4)[0] == zlib.crc32(data[:-4])
    assert file_layout(data) == (2, 2, 2, len(data))
    back, warnings = decode_capture_bytes(data)
    assert warnings == ["the board missed 4 IMU samples while capturing"]
    assert back.imu is not None and np.array_equal(back.imu.raw, cap.imu.raw)
    assert (back.imu.part_name, back.imu.odr_hz, back.imu.missed) == ("ICM-42688-P", 500, 4)
    big = _imu_capture()
    back, warnings = read_capture(write_capture(big, tmp_path / "imu.lhcap"))
    assert warnings == []
    assert np.array_equal(back.sample_index, big.sample_index)
    assert np.array_equal(back.imu.sample_index, big.imu.sample_index)
    assert np.array_equal(back.imu.raw, big.imu.raw)
    # without an IMU the file stays version 1, byte for byte as before
    big.imu = None
    assert encode_capture(big)[4:8] == struct.pack("<HH", 1, 108)


def test_version_2_truncated_or_corrupted_keeps_what_is_valid():
    cap = _imu_capture()
    data = encode_capture(cap)
    n = len(cap)
    back, warnings = decode_capture_bytes(data[:-4 - 16 * 20 - 5])  # 20.3 IMU records short
    assert len(back) == n and len(back.imu) == 29
    assert warnings[0].startswith(f"truncated: {n} of {n} edge records, 29 of 50 IMU records")
    assert np.array_equal(back.imu.raw, cap.imu.raw[:29])
    back, warnings = decode_capture_bytes(data[:128 + 8 * 10 + 3])  # inside the edge records
    assert len(back) == 10 and len(back.imu) == 0
    assert "10 of" in warnings[0] and "0 of 50 IMU records" in warnings[0]
    broken = bytearray(data)
    struct.pack_into("<I", broken, 128 + 8 * n + 16 * 30, 0)  # IMU record 30 goes back
    back, warnings = decode_capture_bytes(bytes(broken))
    assert any("CRC" in w for w in warnings)
    assert any(w.startswith("IMU record 30 breaks the ordering rules") and "the 19 after" in w
               for w in warnings)
    assert len(back.imu) == 30 and len(back) == n
    struct.pack_into("<I", broken, 128 + 8 * n + 16 * 30, 60_000)  # past the capture's end
    back, warnings = decode_capture_bytes(bytes(broken))
    assert len(back.imu) == 30


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d[:6] + struct.pack("<H", 108) + d[8:], "shorter than 128 .version 2"),
    (lambda d: d[:116] + struct.pack("<H", 9) + d[118:], "unknown IMU part 9"),
    (lambda d: d[:120] + struct.pack("<H", 0) + d[122:], "IMU full scale is 0"),
    (lambda d: d + b"\0" * 16, "and 50 IMU records need"),
])
def test_version_2_bad_headers_raise(mutate, message):
    with pytest.raises(InputError, match=message):
        decode_capture_bytes(mutate(encode_capture(_imu_capture())))


def test_imu_counts_and_si_units():
    t = np.array([0.0, 0.001, 0.0015, 0.002])
    accel = np.array([[0, 0, STANDARD_GRAVITY_MPS2], [1, -1, 0], [200, 0, 0], [0, 0, 0]])
    gyro = np.array([[0, 0, 0], [0.5, -0.5, 1], [0, 0, 0], [0, 0, -50.0]])
    imu = CaptureImu.from_stream(ImuStream(t, accel, gyro), 2_000_000)
    assert imu.sample_index.tolist() == [0, 2000, 3000, 4000]
    assert imu.raw[0].tolist() == [0, 0, 2048, 0, 0, 0]  # 1 g = 32768 / 16 counts
    assert imu.raw[2, 0] == 32767 and imu.raw[3, 5] == -32768  # saturated at the full scale
    back = imu.stream(2_000_000)
    assert np.allclose(back.time, t)
    ok = slice(0, 2)
    assert np.abs(back.accel_mps2[ok] - accel[ok]).max() <= 16 * STANDARD_GRAVITY_MPS2 / 65536
    assert np.abs(back.gyro_rad_s[ok] - gyro[ok]).max() <= np.radians(2000) / 65536


def test_read_capture_missing_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_capture(tmp_path / "nope.lhcap")


def test_raw_dump(tmp_path):
    rng = np.random.default_rng(5)
    pulses = _random_pulses(rng, n=200, length=20_000)
    dense = _dense(pulses.sensor, pulses.start, pulses.end, 20_100)
    dense[0] = 3  # lines lit at sample 0 are part of the first record
    path = tmp_path / "d.raw"
    dense.astype("<u4").tofile(path)
    cap = read_raw_dump(path, sample_rate_hz=1_000_000)
    assert cap.sample_rate_hz == 1_000_000 and cap.length_samples == 20_100
    assert cap.sample_index[0] == 0 and cap.port_word[0] == 3
    rebuilt = np.repeat(cap.port_word, np.diff(np.r_[cap.sample_index, cap.length_samples]))
    assert np.array_equal(rebuilt, dense)
    (tmp_path / "odd.raw").write_bytes(b"\0" * 7)
    with pytest.raises(InputError, match="multiple of 4"):
        read_raw_dump(tmp_path / "odd.raw")
