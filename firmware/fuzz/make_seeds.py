#!/usr/bin/env python3
"""Write seed inputs for the protocol fuzzer: byte 0 picks the start state, then frames."""

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
    }
    for name, data in seeds.items():
        (d / f"seed_{name}").write_bytes(data)


if __name__ == "__main__":
    main(sys.argv[1])
