"""The board link's wire protocol: frames (COBS + CRC-32), commands and their answers.

Described in ``docs/protocol.md``. A frame is ``COBS(type u8, seq u8, len u16, payload,
CRC-32 of the preceding bytes)`` followed by a 0x00 delimiter; an answer has the request's
type with ``RESP_FLAG`` set and the request's sequence number, or is an ERROR frame.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

from lhgraph.errors import DeviceError

PROTOCOL_VERSION = 1
DEFAULT_BAUDRATE = 6_000_000

CMD_INFO = 0x01
CMD_ARM = 0x02
CMD_STATUS = 0x03
CMD_READ = 0x04
CMD_ABORT = 0x05
RESP_FLAG = 0x80
RESP_ERROR = 0xFF

STATE_IDLE, STATE_ARMED, STATE_CAPTURING, STATE_READY = 0, 1, 2, 3
STATE_NAMES = {0: "idle", 1: "armed", 2: "capturing", 3: "ready"}

E_CRC, E_FRAMING, E_TOO_LONG = 1, 2, 3
E_LENGTH = 4
E_UNREAD = 10
ERROR_NAMES = {
    1: "bad frame CRC",
    2: "bad framing",
    3: "frame too long",
    4: "bad length",
    5: "unknown command",
    6: "not allowed in this state",
    7: "argument out of range",
    8: "block index out of range",
    9: "hardware error",
    10: "the board holds a capture that was not downloaded",
}
ARM_DISCARD = 0x1
"""ARM flag: drop a capture the board holds that was not downloaded (docs/protocol.md)."""

SELF_TEST_PROBLEMS = {
    0x001: "HSE crystal did not start (running from the internal oscillator, timing +-1 %)",
    0x002: "HSE crystal frequency is not the configured one",
    0x004: "SDRAM data/address bus test failed",
    0x008: "SDRAM march test failed",
    0x010: "SDRAM retention test failed",
    0x020: "the board reset after a fault",
    0x040: "the board reset by its watchdog",
    0x080: "a clock-tree wait timed out",
    0x200: "SDRAM controller timed out",
    0x400: "a DMA stream or the watchdog timed out",
    0x800: "the IMU's time-stamp counter missed samples (its stamps are wrong)",
}
"""STATUS self-test bits (byte 40) that mean something went wrong; 0x100 = not run."""
TRANSIENT_ERRORS = frozenset({E_CRC, E_FRAMING, E_TOO_LONG})

FRAME_OVERHEAD = 8
MAX_BLOCK = 4096
MAX_WIRE_FRAME = 2 * (4 + MAX_BLOCK + FRAME_OVERHEAD) + 64  # generous resync limit


# --- framing ------------------------------------------------------------------------------


def cobs_encode(data: bytes) -> bytes:
    """COBS-encode ``data`` (result has no zero byte; the 0x00 delimiter is not added)."""
    out = bytearray()
    for chunk in data.split(b"\x00"):
        while len(chunk) >= 254:
            out.append(0xFF)
            out += chunk[:254]
            chunk = chunk[254:]
        out.append(len(chunk) + 1)
        out += chunk
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises ``ValueError`` on a malformed encoding."""
    if not data:
        raise ValueError("empty COBS frame")
    if 0 in data:
        raise ValueError("zero byte inside a COBS frame")
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        end = i + code
        if end > n:
            raise ValueError("truncated COBS group")
        out += data[i + 1 : end]
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)


@dataclass(frozen=True)
class Frame:
    """One decoded link frame."""

    kind: int
    seq: int
    payload: bytes


def encode_frame(kind: int, seq: int, payload: bytes = b"") -> bytes:
    """Wire form of a frame: COBS(type, seq, len, payload, CRC-32) + 0x00."""
    raw = struct.pack("<BBH", kind, seq, len(payload)) + payload
    return cobs_encode(raw + struct.pack("<I", zlib.crc32(raw))) + b"\x00"


def decode_frame(encoded: bytes) -> Frame:
    """Decode one frame (without its delimiter); ``ValueError`` if it is damaged."""
    raw = cobs_decode(encoded)
    if len(raw) < FRAME_OVERHEAD:
        raise ValueError("frame too short")
    (crc,) = struct.unpack_from("<I", raw, len(raw) - 4)
    if zlib.crc32(raw[:-4]) != crc:
        raise ValueError("frame CRC mismatch")
    kind, seq, length = struct.unpack_from("<BBH", raw)
    if length != len(raw) - FRAME_OVERHEAD:
        raise ValueError("frame length field mismatch")
    return Frame(kind, seq, raw[4:-4])


_INFO = struct.Struct("<HHIIIIII")
_STATUS = struct.Struct("<BBHIIIIIIIII")
_HEALTH = struct.Struct("<13I")
_IMU_STATUS = struct.Struct("<3I")


def _unpack_answer(name: str, layout: struct.Struct, payload: bytes) -> tuple[int, ...]:
    """The fields of an answer payload; DeviceError when its length is not the layout's."""
    if len(payload) != layout.size:
        raise DeviceError(f"{name} answer has {len(payload)} bytes, expected {layout.size}")
    return layout.unpack(payload)


@dataclass(frozen=True)
class BoardInfo:
    """Answer to INFO."""

    protocol_version: int
    block_size: int
    firmware_version: int
    board_id: int
    sample_rate: int
    max_duration_ms: int
    max_delay_ms: int
    max_records: int

    @classmethod
    def parse(cls, payload: bytes) -> BoardInfo:
        """Decode an INFO payload (28 bytes)."""
        return cls(*_unpack_answer("INFO", _INFO, payload))


@dataclass(frozen=True)
class BoardStatus:
    """Answer to STATUS (also to ARM and ABORT).

    The first 40 bytes are every firmware's; the health fields (bytes 40..91) come from
    firmware that reports them (``health_reported``) and are 0 otherwise, as are the IMU
    fields (bytes 92..103: the IMU part found at boot, 0 = none; IMU records and missed
    samples of the current capture). Cycle counts are CPU cycles at 180 MHz.
    """

    state: int
    hw_error: int
    flags: int
    duration_ms: int
    delay_left_ms: int
    samples_done: int
    samples_target: int
    records: int
    image_size: int
    image_crc: int
    block_size: int
    block_count: int
    self_test: int = 0
    hse_khz: int = 0
    fault_pc: int = 0
    fault_lr: int = 0
    fault_cfsr: int = 0
    fault_hfsr: int = 0
    dma_overruns: int = 0
    isr_cycles_max: int = 0
    isr_cycles_budget: int = 0
    frames_timed_out: int = 0
    tx_dropped: int = 0
    blocks_unread: int = 0
    reset_cause: int = 0
    health_reported: bool = False
    imu_part: int = 0
    imu_records: int = 0
    imu_missed: int = 0

    @classmethod
    def parse(cls, payload: bytes) -> BoardStatus:
        """Decode a STATUS payload: 40 bytes, or 92 or more with the health fields (and
        104 or more with the IMU fields)."""
        if len(payload) == _STATUS.size:
            return cls(*_STATUS.unpack(payload))
        health_end = _STATUS.size + _HEALTH.size
        if len(payload) < health_end:
            raise DeviceError(f"STATUS answer has {len(payload)} bytes, expected "
                              f"{_STATUS.size} or at least {health_end}")
        imu = (_IMU_STATUS.unpack_from(payload, health_end)
               if len(payload) >= health_end + _IMU_STATUS.size else (0, 0, 0))
        return cls(*_STATUS.unpack_from(payload), *_HEALTH.unpack_from(payload, _STATUS.size),
                   True, *imu)

    @property
    def state_name(self) -> str:
        """``idle``, ``armed``, ``capturing`` or ``ready``."""
        return STATE_NAMES.get(self.state, f"state {self.state}")

    def problems(self) -> tuple[str, ...]:
        """The board's self-test failures and lost data, one phrase each (empty if none)."""
        out = [text for bit, text in SELF_TEST_PROBLEMS.items() if self.self_test & bit]
        if self.dma_overruns:
            out.append(f"{self.dma_overruns} sample half-buffers lost since boot")
        return tuple(out)


def is_rejected_request(frame: Frame) -> bool:
    """An ERROR the board sends for a request it received damaged (seq unknown: 0)."""
    return (frame.kind == RESP_ERROR and frame.seq == 0 and len(frame.payload) >= 1
            and frame.payload[0] in TRANSIENT_ERRORS)


class BoardRefused(DeviceError):
    """The board answered a request with an ERROR frame."""

    def __init__(self, command: int, code: int, state: int):
        self.command, self.code, self.state = command, code, state
        name = ERROR_NAMES.get(code, f"error {code}")
        super().__init__(f"board refused command 0x{command:02x}: {name} "
                         f"(board state: {STATE_NAMES.get(state, state)})")
