"""The .lhcap edge-record format, raw dumps, and pulse <-> edge conversions."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lhgraph.errors import InputError
from lhgraph.signal.capture import (
    Capture,
    decode_capture_bytes,
    edges_from_words,
    edges_to_pulses,
    encode_capture,
    pulses_to_edges,
    read_capture,
    read_raw_dump,
    write_capture,
)
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
    (lambda d: d[:4] + struct.pack("<H", 2) + d[6:], "unknown .lhcap version"),
    (lambda d: d[:6] + struct.pack("<H", 50) + d[8:], "shorter than"),
    (lambda d: d + b"\0" * 8, "records need"),
    (lambda d: d[:60], "inside the header"),
    (lambda d: b"", "wrong magic"),
])
def test_bad_headers_raise(mutate, message):
    cap = Capture(np.array([0, 5]), np.array([0, 1]), 9)
    with pytest.raises(InputError, match=message):
        decode_capture_bytes(mutate(encode_capture(cap)), "x.lhcap")


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
