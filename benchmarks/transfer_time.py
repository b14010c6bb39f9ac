"""Transfer time of a capture from the board to the PC (docs/protocol.md, "Transfer time").

Computes the wire time of an 8 s capture sent as edge records (~1.3 MB) and as a raw
64 MB sample dump over the link protocol (COBS frames of 4 KiB blocks, 8N1 = 10 bits per
byte), and, with ``--measure``, times a real download of a synthetic 1.3 MB capture from
``virtual_board`` paced at the link's baud rate (the firmware core on a pty, the Python
client of ``lhgraph capture``).

    python -m benchmarks transfer_time [--measure] [--baud 6000000]
"""

from __future__ import annotations

import argparse
import random
import struct
import subprocess
import tempfile
import time
import zlib
from pathlib import Path

from benchmarks import prog
from lhgraph.device.download import download_capture

REPO = Path(__file__).resolve().parents[1]

BLOCK = 4096
HEADER_LEN, TRAILER_LEN, RECORD_LEN = 108, 4, 8
FRAME_OVERHEAD = 8 + 4  # type, seq, len, CRC-32 + the block index of a READ answer
BITS_PER_BYTE = 10  # 8N1
# Board time to prepare one READ answer (copy from SDRAM, CRC-32 with the 16-entry table,
# COBS encoding, copy into the UART ring): ~40 cycles/byte at 180 MHz, an estimate. The
# UART sends from its interrupt while the next answer is prepared, so only the first
# block's preparation adds to the wire time (the pipeline is never starved: 0.9 ms < 6.9 ms).
BOARD_BLOCK_S = 4108 * 40 / 180e6
# USB latency of an FT232H (latency timer 1-16 ms) and the host: paid once per exchange
# that stalls the pipeline; the client keeps 4 READs in flight, so only at the start and
# end of the download.
LINK_RTT_S = 0.016


def cobs_len(n: int) -> int:
    """Worst-case COBS size of n bytes (no zero bytes in the data) plus the delimiter."""
    return n + n // 254 + 1 + 1


def wire_bytes(payload: int, block: int = BLOCK) -> int:
    """Bytes on the wire to send ``payload`` bytes as READ answers of ``block`` bytes."""
    full, rest = divmod(payload, block)
    total = full * cobs_len(block + FRAME_OVERHEAD)
    if rest:
        total += cobs_len(rest + FRAME_OVERHEAD)
    return total


def estimate(payload: int, baud: float, block: int = BLOCK) -> dict[str, float]:
    """Wire time, board overhead and the total for one download."""
    n_blocks = -(-payload // block)
    wire = wire_bytes(payload, block)
    wire_s = wire * BITS_PER_BYTE / baud
    block_wire_s = cobs_len(block + FRAME_OVERHEAD) * BITS_PER_BYTE / baud
    # hidden behind the wire while the board prepares faster than it sends
    board_s = BOARD_BLOCK_S + n_blocks * max(0.0, BOARD_BLOCK_S - block_wire_s)
    return {"payload": payload, "blocks": n_blocks, "wire_bytes": wire, "wire_s": wire_s,
            "board_s": board_s, "total_s": wire_s + board_s + 2 * LINK_RTT_S,
            "efficiency": payload / wire}


def synthetic_capture(path: Path, n_records: int, samples: int, seed: int = 3) -> bytes:
    """Write a valid .lhcap of ``n_records`` edges spread over ``samples`` samples."""
    rnd = random.Random(seed)
    idx = sorted(rnd.sample(range(1, samples - 1), n_records - 1))
    word = 0
    recs = bytearray(struct.pack("<II", 0, word))
    for i in idx:
        word ^= 1 << rnd.randrange(32)
        recs += struct.pack("<II", i, word)
    header = b"LHCP" + struct.pack("<HHIIIIQQI", 1, 108, 2_000_000, 0, 1, 0x100, 0, samples,
                                   n_records) + struct.pack("<32h", *range(32))
    body = header + bytes(recs)
    data = body + struct.pack("<I", zlib.crc32(body))
    path.write_bytes(data)
    return data


def build_virtual_board() -> Path:
    """Build (or reuse) build/firmware-host/virtual_board."""
    build = REPO / "build" / "firmware-host"
    if not (build / "CMakeCache.txt").exists():
        subprocess.run(["cmake", "-S", str(REPO / "firmware"), "-B", str(build)], check=True,
                       stdout=subprocess.DEVNULL)
    subprocess.run(["cmake", "--build", str(build), "--target", "virtual_board", "-j2"],
                   check=True, stdout=subprocess.DEVNULL)
    return build / "virtual_board"


def measure(baud: float, n_records: int, capture: Path | None = None) -> dict[str, float]:
    """Download a capture (default: a synthetic 8 s one) from virtual_board paced at ``baud``."""
    exe = build_virtual_board()
    with tempfile.TemporaryDirectory() as tmp:
        if capture is None:
            src = Path(tmp) / "src.lhcap"
            data = synthetic_capture(src, n_records, 16_000_000)
        else:
            src, data = capture, capture.read_bytes()
        proc = subprocess.Popen([str(exe), "--capture", str(src), "--baud", str(baud),
                                 "--time-scale", "0"], stdout=subprocess.PIPE)
        try:
            assert proc.stdout is not None
            port = proc.stdout.readline().decode().strip()
            t0 = time.monotonic()
            result = download_capture(port, Path(tmp) / "out.lhcap", duration_s=8.0)
            total = time.monotonic() - t0
            same = (Path(tmp) / "out.lhcap").read_bytes() == data
        finally:
            proc.terminate()
            proc.wait()
    return {"payload": len(data), "download_s": result.download_s, "total_s": total,
            "rate_kBps": len(data) / result.download_s / 1e3, "identical": float(same)}


def main(argv: list[str] | None = None) -> int:
    """Print the estimate table (and the measurement with --measure)."""
    ap = argparse.ArgumentParser(prog=prog(__file__), description=__doc__.splitlines()[0])
    ap.add_argument("--baud", type=float, default=6e6)
    ap.add_argument("--edges-bytes", type=int, default=1_300_000,
                    help="size of the edge-record capture (default 1.3 MB)")
    ap.add_argument("--measure", action="store_true",
                    help="also time a paced download from virtual_board")
    ap.add_argument("--capture", type=Path,
                    help="also estimate (and with --measure, time) this .lhcap file, e.g. "
                    "the capture.lhcap of `lhgraph simulate --capture`")
    args = ap.parse_args(argv)

    raw = 64 * 1024 * 1024
    edges = args.edges_bytes
    print(f"link: {args.baud / 1e6:g} Mbaud 8N1 = {args.baud / BITS_PER_BYTE / 1e3:.0f} kB/s "
          f"payload-free; blocks of {BLOCK} B in COBS frames; board prepares a block in "
          f"{BOARD_BLOCK_S * 1e3:.2f} ms (estimate, overlapped with sending)")
    print()
    print("| capture | payload (bytes) | blocks | wire bytes | efficiency | wire time | "
          "board time not hidden | total |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    rows = [("8 s edge records", edges), ("8 s raw dump (64 MiB)", raw)]
    if args.capture is not None:
        rows.append((f"{args.capture.name} (given)", args.capture.stat().st_size))
    for name, size in rows:
        e = estimate(size, args.baud)
        print(f"| {name} | {size:,} | {e['blocks']:,} | {e['wire_bytes']:,} | "
              f"{e['efficiency'] * 100:.1f}% | {e['wire_s']:.2f} s | {e['board_s']:.2f} s | "
              f"**{e['total_s']:.1f} s** |")
    print()
    for baud in (3e6, 6e6, 12e6):
        e1, e2 = estimate(edges, baud), estimate(raw, baud)
        print(f"at {baud / 1e6:g} Mbaud: edges {e1['total_s']:.1f} s, raw {e2['total_s']:.0f} s")
    if args.measure:
        n_records = (edges - HEADER_LEN - TRAILER_LEN) // RECORD_LEN
        m = measure(args.baud, n_records)
        print()
        runs = [("synthetic 8 s", m)]
        if args.capture is not None:
            runs.append((args.capture.name, measure(args.baud, 0, args.capture)))
        for name, m in runs:
            print(f"measured, {name} (virtual_board paced at {args.baud / 1e6:g} Mbaud, pty, "
                  f"Python client): {m['payload']:,} bytes downloaded in "
                  f"{m['download_s']:.2f} s ({m['rate_kBps']:.0f} kB/s), {m['total_s']:.2f} s "
                  f"with INFO/ARM/STATUS, byte-identical: {bool(m['identical'])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
