#!/usr/bin/env python3
"""Write seed inputs for the protocol fuzzer: byte 0 picks the start state and the mode.

Raw mode (byte 0 bit 2 clear): wire bytes. Frame mode (bit 2 set): records
``ctl type seq n payload[n]`` that the harness wraps into frames with valid CRCs
(tests/fuzz_proto.c).
"""

from __future__ import annotations

import struct
import sys
import zlib
from pathlib import Path


def cobs(data: bytes) -> bytes:
    """COBS-encode ``data`` (no delimiter)."""
    out = bytearray()
    for chunk in data.split(b"\x00"):
        while len(chunk) >= 254:
            out += b"\xff" + chunk[:254]
            chunk = chunk[254:]
        out += bytes([len(chunk) + 1]) + chunk
    return bytes(out)


def frame(kind: int, seq: int, payload: bytes = b"") -> bytes:
    """One wire frame."""
    raw = struct.pack("<BBH", kind, seq, len(payload)) + payload
    return cobs(raw + struct.pack("<I", zlib.crc32(raw))) + b"\x00"


def record(kind: int, seq: int, payload: bytes = b"", ctl: int = 0) -> bytes:
    """One frame-mode record (the harness computes the CRC)."""
    return bytes([ctl, kind, seq, len(payload)]) + payload


def main(out_dir: str) -> None:
    """Write the seeds."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    arm = struct.pack("<IIQ", 1, 0, 1_700_000_000_000_000)
    seeds = {
        "info": b"\x00" + frame(1, 1),
        "status": b"\x00" + frame(3, 2),
        "arm": b"\x00" + frame(2, 3, arm) + frame(3, 4),
        "read_ready": (b"\x01" + frame(4, 5, struct.pack("<I", 0))
                       + frame(4, 6, struct.pack("<I", 3))),
        "capturing": b"\x02" + frame(3, 7) + b"\x5a" + frame(5, 8),
        "abort": b"\x01" + frame(5, 9) + frame(4, 10, struct.pack("<I", 0)),
        "garbage": b"\x00" + bytes(range(1, 60)) + b"\x00" + frame(1, 11),
        "f_arm_ready": (b"\x05" + record(3, 1) + record(2, 2, arm)
                        + record(2, 3, arm + struct.pack("<I", 1)) + record(4, 4, bytes(4))),
        "f_download": (b"\x05" + b"".join(record(4, i + 1, struct.pack("<I", i)) for i in range(6))
                       + record(2, 9, arm)),
        "f_capturing": b"\x06" + record(3, 1, ctl=32) + record(3, 2, ctl=32) + record(5, 3),
        "f_timeout": b"\x04" + record(1, 1, ctl=16) + record(1, 2, ctl=3) + record(3, 3, ctl=2),
        "f_bad": b"\x04" + record(1, 1, ctl=4) + record(3, 2, ctl=8) + record(0x77, 3),
    }
    for name, data in seeds.items():
        (d / f"seed_{name}").write_bytes(data)


if __name__ == "__main__":
    main(sys.argv[1])
