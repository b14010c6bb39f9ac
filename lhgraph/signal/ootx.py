"""OOTX: the slow data channel of a Lighthouse v1 station (one bit per sync flash).

Frame on the wire (SPEC §3): 17 zeros then a 1 (preamble); then 16-bit words, MSB first,
each followed by a stuffing bit that must be 1. The words carry the byte stream
``length (u16 LE) | payload | pad to even | CRC-32 of payload (u32 LE)``, two bytes per word
(first byte in the high half). The LH1 payload (33 bytes, little-endian) is, in order:

    u16 fw_version   (firmware version bits 15..6, protocol version bits 5..0)
    u32 id
    f16 phase0, phase1, tilt0, tilt1
    u8  unlock_count, u8 hw_version
    f16 curve0, curve1
    i8  accel_dir x, y, z
    f16 gibphase0, gibphase1, gibmag0, gibmag1
    u8  mode (0 = A, 1 = B, 2 = C), u8 faults

(f16 = IEEE half float; the layout agrees with libsurvive's decoder and nairol's
LighthouseRedox notes). Calibration values are radians as broadcast, before any model use.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.errors import InputError
from lhgraph.model.calibration import StationCalibration
from lhgraph.model.station import FactoryCalibration

PAYLOAD_LEN = 33
PREAMBLE_ZEROS = 17
_PAYLOAD = struct.Struct("<HI4e2B2e3b4e2B")
assert _PAYLOAD.size == PAYLOAD_LEN


@dataclass(frozen=True)
class OotxPayload:
    """Content of an LH1 OOTX frame; calibration fields are ``[axis0, axis1]`` (rad)."""

    id: int = 0
    fw_version: int = 0
    phase: tuple[float, float] = (0.0, 0.0)
    tilt: tuple[float, float] = (0.0, 0.0)
    curve: tuple[float, float] = (0.0, 0.0)
    gibphase: tuple[float, float] = (0.0, 0.0)
    gibmag: tuple[float, float] = (0.0, 0.0)
    accel_dir: tuple[int, int, int] = (0, 0, 0)
    unlock_count: int = 0
    hw_version: int = 0
    mode: int = 0
    faults: int = 0

    @classmethod
    def from_calibration(cls, cal: StationCalibration, **fields: int) -> OotxPayload:
        """Payload broadcasting ``cal`` (values rounded to half floats when packed)."""
        c = cal.calibration
        accel = np.clip(np.round(np.asarray(cal.accel_dir, float)), -128, 127).astype(int)
        return cls(id=int(cal.id) & 0xFFFFFFFF, phase=_pair(c.phase), tilt=_pair(c.tilt),
                   curve=_pair(c.curve), gibphase=_pair(c.gibphase), gibmag=_pair(c.gibmag),
                   accel_dir=(int(accel[0]), int(accel[1]), int(accel[2])), **fields)

    def to_calibration(self) -> StationCalibration:
        """The factory calibration, id and accelerometer vector as an ootx.toml entry."""
        cal = FactoryCalibration(phase=self.phase, tilt=self.tilt, curve=self.curve,
                                 gibphase=self.gibphase, gibmag=self.gibmag)
        return StationCalibration(cal, self.id, np.asarray(self.accel_dir, dtype=float))


def _pair(values: ArrayLike) -> tuple[float, float]:
    a = np.asarray(values, dtype=float).reshape(2)
    return float(a[0]), float(a[1])


def pack_payload(p: OotxPayload) -> bytes:
    """The 33 payload bytes (calibration values rounded to IEEE half floats)."""
    return _PAYLOAD.pack(
        p.fw_version, p.id, p.phase[0], p.phase[1], p.tilt[0], p.tilt[1], p.unlock_count,
        p.hw_version, p.curve[0], p.curve[1], *p.accel_dir, p.gibphase[0], p.gibphase[1],
        p.gibmag[0], p.gibmag[1], p.mode, p.faults,
    )


def unpack_payload(data: bytes) -> OotxPayload:
    """Parse an LH1 payload (at least 33 bytes; extra bytes of newer versions are ignored)."""
    if len(data) < PAYLOAD_LEN:
        raise InputError(f"OOTX payload has {len(data)} bytes, expected {PAYLOAD_LEN}")
    (fw, sid, ph0, ph1, ti0, ti1, unlock, hw, cu0, cu1, ax, ay, az, gp0, gp1, gm0, gm1, mode,
     faults) = _PAYLOAD.unpack_from(data)
    return OotxPayload(id=sid, fw_version=fw, phase=(ph0, ph1), tilt=(ti0, ti1),
                       curve=(cu0, cu1), gibphase=(gp0, gp1), gibmag=(gm0, gm1),
                       accel_dir=(ax, ay, az), unlock_count=unlock, hw_version=hw, mode=mode,
                       faults=faults)


def encode_frame(payload: bytes) -> NDArray[np.uint8]:
    """Bits (0/1, in transmission order) of one OOTX frame carrying ``payload``."""
    if len(payload) > 0xFFFF:
        raise ValueError("OOTX payload longer than 65535 bytes")
    body = struct.pack("<H", len(payload)) + payload + b"\0" * (len(payload) % 2)
    body += struct.pack("<I", zlib.crc32(payload))
    words = np.frombuffer(body, dtype=">u2")
    data_bits = (words[:, None] >> np.arange(15, -1, -1)) & 1
    with_stuffing = np.hstack([data_bits, np.ones((len(words), 1), dtype=data_bits.dtype)])
    preamble = np.r_[np.zeros(PREAMBLE_ZEROS), 1]
    return np.concatenate([preamble, with_stuffing.ravel()]).astype(np.uint8)


@dataclass
class OotxFrame:
    """A complete frame: payload bytes, whether its CRC matched, and the index (in the
    stream given to the decoder) of its last data bit (only a stuffing bit follows)."""

    payload: bytes
    crc_ok: bool
    end_bit: int


@dataclass
class OotxDecoder:
    """Streaming OOTX decoder: feed bits one at a time (or in arrays) and collect frames.

    A preamble (17 zeros then 1) starts a frame anywhere, even inside another one; a
    stuffing bit of 0 abandons the frame being read. Counts of what went wrong are kept.
    """

    frames: list[OotxFrame] = field(default_factory=list)
    bad_stuffing: int = 0
    bad_crc: int = 0
    bits_seen: int = 0
    _zeros: int = 0
    _active: bool = False
    _word: int = 0
    _nbits: int = 0
    _bytes: bytearray = field(default_factory=bytearray)

    def push(self, bit: int) -> OotxFrame | None:
        """Feed one bit; returns a frame when this bit completes one."""
        bit = 1 if bit else 0
        index = self.bits_seen
        self.bits_seen += 1
        if bit == 1 and self._zeros >= PREAMBLE_ZEROS:
            self._zeros = 0
            self._active, self._word, self._nbits = True, 0, 0
            self._bytes = bytearray()
            return None
        self._zeros = 0 if bit else self._zeros + 1
        if not self._active:
            return None
        if self._nbits == 16:  # stuffing bit
            self._nbits, self._word = 0, 0
            if not bit:
                self.bad_stuffing += 1
                self._active = False
            return None
        self._word = (self._word << 1) | bit
        self._nbits += 1
        if self._nbits < 16:
            return None
        self._bytes += bytes((self._word >> 8, self._word & 0xFF))
        return self._complete(index)

    def push_bits(self, bits: ArrayLike) -> list[OotxFrame]:
        """Feed many bits; returns the frames they complete."""
        found = []
        for b in np.asarray(bits).ravel().tolist():
            frame = self.push(b)
            if frame is not None:
                found.append(frame)
        return found

    def _complete(self, index: int) -> OotxFrame | None:
        if len(self._bytes) < 2:
            return None
        length = self._bytes[0] | (self._bytes[1] << 8)
        padded = length + (length % 2)
        if len(self._bytes) < 2 + padded + 4:
            return None
        payload = bytes(self._bytes[2:2 + length])
        (crc,) = struct.unpack_from("<I", self._bytes, 2 + padded)
        frame = OotxFrame(payload, zlib.crc32(payload) == crc, index)
        if not frame.crc_ok:
            self.bad_crc += 1
        self.frames.append(frame)
        self._active = False
        return frame
