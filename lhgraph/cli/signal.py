"""Commands on recordings and the board: ``decode``, ``capture``."""

from __future__ import annotations

import argparse
import sys

from lhgraph.choices import FORMATS, PERIODS, SYNCS
from lhgraph.cli.common import COMMANDS, add_common_output, at_least, mark_inputs

# --- decode ---


def add_decode(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("decode", help="decode a capture into angles and OOTX calibration",
                       description="Decode a board capture (.lhcap), a raw sample dump or a "
                       "libsurvive recording into DIR/angles.csv, DIR/ootx.toml and (a "
                       "capture with IMU records) DIR/imu.csv (docs/decoding.md).")
    p.add_argument("capture", help="capture file")
    p.add_argument("--output", "-o", required=True, help="output directory")
    p.add_argument("--format", choices=FORMATS,
                   help="input format (docs/decoding.md; default: from the file name)")
    p.add_argument("--device", help="libsurvive device name (e.g. HMD)")
    p.add_argument("--board", help="board TOML: drop pulses of sensors not on it")
    p.add_argument("--sample-rate", type=at_least(0, float, strict=True),
                   help="raw dump sample rate in Hz (default: 2e6)")
    p.add_argument("--period", choices=PERIODS,
                   help="rotor period: fitted to the sync train or 1/60 s (default: fit; "
                   "nominal for libsurvive recordings)")
    p.add_argument("--sync", choices=SYNCS, default="measured",
                   help="time sweeps from each measured sync flash (a real station's flash "
                   "and sweep jitter together) or from the fitted train")
    add_common_output(p)
    mark_inputs(p, "capture", "board")
    return p


def run_decode(args: argparse.Namespace) -> int:
    from lhgraph.model.board import load_board
    from lhgraph.signal.decode import DecodeOptions
    from lhgraph.signal.formats import (
        check_output_directory,
        decode_file,
        default_period,
        write_decoded,
    )

    check_output_directory(args.output, args.force)
    board = load_board(args.board) if args.board else None
    options = DecodeOptions(period=args.period or default_period(args.capture, args.format),
                            sync_reference=args.sync)
    result, warnings = decode_file(args.capture, args.format, args.device, board, options,
                                   args.sample_rate)
    written = write_decoded(result, args.output, overwrite=args.force)
    for line in warnings if args.quiet else [*warnings, *result.report.lines()]:
        print(f"  {line}", file=sys.stderr)  # --quiet never hides what the reader dropped
    if not args.quiet:
        print(f"{len(result.angles)} sweep hits, OOTX of station(s) "
              f"{sorted(result.calibrations) or 'none'}; wrote "
              f"{', '.join(str(p) for p in written)}")
    return 0


COMMANDS.append(("decode", add_decode, run_decode))


# --- capture ---


def add_capture(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("capture", help="record a capture with the board and download it",
                       description="Arm the photodiode board, wait for the capture and download "
                       "it as a .lhcap file (docs/protocol.md). Exit code 1 for device or link "
                       "failures, 2 for bad arguments or an existing output.")
    p.add_argument("--port", required=True, help="serial port of the board (e.g. /dev/ttyUSB0)")
    p.add_argument("--output", "-o", required=True, help=".lhcap file to write")
    p.add_argument("--duration", type=float, default=8.0, help="capture length in s")
    p.add_argument("--delay", type=float, default=0.0, help="start delay in s")
    p.add_argument("--baud", type=int, default=6_000_000, help="baud rate")
    p.add_argument("--no-arm", action="store_true",
                   help="download the capture the board already holds; do not record")
    p.add_argument("--discard-previous", action="store_true",
                   help="record even if the board holds a capture that was not downloaded "
                   "(it is lost); without this the board refuses")
    add_common_output(p)
    mark_inputs(p, "port")
    return p


def run_capture(args: argparse.Namespace) -> int:
    from lhgraph.device.download import download_capture
    from lhgraph.device.progress import ProgressBar

    bar = None if args.quiet else ProgressBar(sys.stderr)
    try:
        result = download_capture(args.port, args.output, duration_s=args.duration,
                                  overwrite=args.force, progress=bar, baudrate=args.baud,
                                  start_delay_s=args.delay, arm=not args.no_arm,
                                  discard_previous=args.discard_previous)
    finally:
        if bar is not None:
            bar.close()
    if not args.quiet:
        print(result.summary())
    return 0


COMMANDS.append(("capture", add_capture, run_capture))
