"""OOTX payload packing and frame coding."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lhgraph.errors import InputError
from lhgraph.model.calibration import StationCalibration
from lhgraph.model.station import FactoryCalibration
from lhgraph.signal.ootx import (
    PAYLOAD_LEN,
    OotxDecoder,
    OotxPayload,
    encode_frame,
    pack_payload,
    unpack_payload,
)


def _example() -> OotxPayload:
    return OotxPayload(id=0xDEADBEEF, fw_version=0x1234, phase=(0.0586, -0.0621),
                       tilt=(0.0013, -0.0079), curve=(-0.0019, 0.0036),
                       gibphase=(2.89, 0.024), gibmag=(0.0047, -0.004), accel_dir=(0, 127, -1),
                       unlock_count=3, hw_version=9, mode=1, faults=0)


def test_payload_layout_known_bytes():
    data = pack_payload(_example())
    assert len(data) == PAYLOAD_LEN
    assert data[:2] == b"\x34\x12" and data[2:6] == b"\xef\xbe\xad\xde"
    assert np.frombuffer(data[6:14], "<f2").tolist() == pytest.approx(
        [0.0586, -0.0621, 0.0013, -0.0079], rel=1e-3)
    assert data[14:16] == b"\x03\x09"
    assert np.frombuffer(data[16:20], "<f2").tolist() == pytest.approx([-0.0019, 0.0036],
                                                                      rel=1e-3)
    assert struct.unpack("<3b", data[20:23]) == (0, 127, -1)
    assert np.frombuffer(data[23:31], "<f2").tolist() == pytest.approx(
        [2.89, 0.024, 0.0047, -0.004], rel=1e-3)
    assert data[31:] == b"\x01\x00"


def test_payload_round_trip_is_half_float_exact():
    p = _example()
    back = unpack_payload(pack_payload(p))
    assert back.id == p.id and back.accel_dir == p.accel_dir and back.mode == 1
    for key in ("phase", "tilt", "curve", "gibphase", "gibmag"):
        assert np.array_equal(getattr(back, key), np.float16(getattr(p, key)).astype(float))
    assert unpack_payload(pack_payload(back)) == back
    with pytest.raises(InputError):
        unpack_payload(b"\0" * 10)


def test_calibration_conversion():
    cal = StationCalibration(FactoryCalibration(phase=[0.05, 0.06], tilt=[0.001, -0.002],
                                                curve=[0.003, 0.004], gibphase=[1.0, 2.0],
                                                gibmag=[0.01, -0.02]), 42, np.array([0, 127, 0]))
    back = unpack_payload(pack_payload(OotxPayload.from_calibration(cal))).to_calibration()
    assert back.id == 42 and back.accel_dir.tolist() == [0, 127, 0]
    np.testing.assert_allclose(back.calibration.gibphase, [1.0, 2.0], rtol=1e-3)
    np.testing.assert_allclose(back.calibration.tilt, [0.001, -0.002], rtol=1e-3)


def test_frame_structure():
    payload = bytes(range(33))
    bits = encode_frame(payload)
    assert bits[:18].tolist() == [0] * 17 + [1]
    words = bits[18:].reshape(-1, 17)
    assert len(words) == 1 + 17 + 2
    assert np.all(words[:, 16] == 1)
    values = (words[:, :16] * (1 << np.arange(15, -1, -1))).sum(axis=1)
    stream = b"".join(struct.pack(">H", int(v)) for v in values)
    assert stream[:2] == struct.pack("<H", 33)
    assert stream[2:35] == payload and stream[35] == 0
    assert stream[36:40] == struct.pack("<I", zlib.crc32(payload))


def test_decoder_finds_frames_in_a_noisy_stream():
    rng = np.random.default_rng(0)
    payload = pack_payload(_example())
    frame = encode_frame(payload)
    junk = rng.integers(0, 2, 100)
    stream = np.concatenate([junk, frame, frame, frame[:200], frame])
    dec = OotxDecoder()
    frames = dec.push_bits(stream)
    assert [f.payload for f in frames] == [payload] * 3
    assert all(f.crc_ok for f in frames)
    assert frames[0].end_bit == 100 + len(frame) - 2  # the last stuffing bit follows


def test_decoder_rejects_bad_crc_and_bad_stuffing():
    payload = pack_payload(_example())
    frame = encode_frame(payload)
    flipped = frame.copy()
    flipped[18 + 17 * 3 + 4] ^= 1  # a data bit of the third word
    dec = OotxDecoder()
    frames = dec.push_bits(flipped)
    assert len(frames) == 1 and not frames[0].crc_ok and dec.bad_crc == 1
    stuffed = frame.copy()
    stuffed[18 + 17 * 2 + 16] = 0  # a stuffing bit
    dec = OotxDecoder()
    assert dec.push_bits(stuffed) == [] and dec.bad_stuffing == 1


@settings(max_examples=50, deadline=None)
@given(st.binary(min_size=0, max_size=80), st.lists(st.integers(0, 1), max_size=40))
def test_random_frames_round_trip(payload, prefix):
    dec = OotxDecoder()
    frames = dec.push_bits(np.r_[np.array(prefix, dtype=np.uint8), encode_frame(payload)])
    assert frames[-1].payload == payload and frames[-1].crc_ok


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(0, 1), max_size=2000))
def test_random_bits_never_crash(bits):
    dec = OotxDecoder()
    dec.push_bits(bits)
    assert dec.bits_seen == len(bits)
