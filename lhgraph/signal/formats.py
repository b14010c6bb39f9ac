"""Recording files by kind into the decoder, and the decoder's output files.

Kinds (:data:`FORMATS`): ``lhcap``, the board's edge-record file (docs/formats/lhcap.md);
``raw``, a raw sample dump (a u32 port word per sample, no header); ``libsurvive``, the raw
light of one device of a libsurvive recording. The kind comes from the file name unless
given. Outputs: ``angles.csv``, ``ootx.toml`` when a station's OOTX frame decoded, and
``imu.csv`` when the capture holds IMU samples (a version-2 ``.lhcap``).
"""

from __future__ import annotations

from pathlib import Path

from lhgraph.choices import FORMATS
from lhgraph.errors import InputError
from lhgraph.io.angles import save_angles
from lhgraph.io.files import check_writable
from lhgraph.io.imu import save_imu
from lhgraph.model.board import Board
from lhgraph.model.calibration import save_calibration
from lhgraph.signal.capture import read_capture, read_raw_dump
from lhgraph.signal.decode import DecodeOptions, DecodeResult, decode_capture, decode_pulses
from lhgraph.signal.libsurvive import read_libsurvive

ANGLES_FILE = "angles.csv"
OOTX_FILE = "ootx.toml"
IMU_FILE = "imu.csv"
RAW_SAMPLE_RATE_HZ = 2_000_000
"""Sample rate of a raw dump unless given (the board's)."""


def guess_format(path: str | Path) -> str:
    """Input format from the file name: ``.lhcap``, ``.raw``/``.bin``, ``.rec``/``.rec.gz``."""
    name = Path(path).name.lower()
    if name.endswith(".lhcap"):
        return "lhcap"
    if name.endswith((".raw", ".bin")):
        return "raw"
    if name.endswith((".rec", ".rec.gz")):
        return "libsurvive"
    raise InputError("cannot tell the format from the name; give --format "
                     f"({'|'.join(FORMATS)})", path)


def default_period(path: str | Path, fmt: str | None = None) -> str:
    """The rotor period the decoder uses for a recording unless told: ``"nominal"`` (1/60 s,
    as libsurvive decodes) for libsurvive recordings, ``"fit"`` for everything else.

    ``fmt`` is the recording's kind; without it the kind comes from the name
    (:func:`guess_format`).
    """
    return "nominal" if (fmt or guess_format(path)) == "libsurvive" else "fit"


def decode_file(path: str | Path, fmt: str | None = None, device: str | None = None,
                board: Board | None = None, options: DecodeOptions | None = None,
                sample_rate_hz: float | None = None) -> tuple[DecodeResult, list[str]]:
    """Read and decode a recording -> (result, reader warnings).

    ``lhcap``: the board's edge file; ``raw``: a raw sample dump (``sample_rate_hz``, default
    2 MHz; channel k = sensor k); ``libsurvive``: one ``device``'s raw light of a libsurvive
    recording (48 MHz ticks from the device's first pulse). ``options`` default to
    :class:`DecodeOptions` with the period of :func:`default_period`. A file in which the
    decoder finds no sync flash raises InputError ``no Lighthouse signal found``.
    """
    fmt = fmt or guess_format(path)
    options = options or DecodeOptions(period=default_period(path, fmt))
    warnings: list[str] = []
    if fmt == "libsurvive":
        recording = read_libsurvive(path, device)
        result = decode_pulses(recording.pulses, recording.sample_rate_hz, board, options)
    elif fmt in ("raw", "lhcap"):
        if fmt == "raw":
            capture = read_raw_dump(path, int(sample_rate_hz or RAW_SAMPLE_RATE_HZ))
        else:
            capture, warnings = read_capture(path)
        result = decode_capture(capture, board, options)
    else:
        raise InputError(f"unknown format {fmt!r} (expected {'|'.join(FORMATS)})")
    if result.report.sync_flashes == 0:
        raise InputError("no Lighthouse signal found", path)
    return result, warnings


def check_output_directory(out_dir: str | Path, overwrite: bool = False) -> None:
    """Refuse (InputError) a directory :func:`write_decoded` cannot write ``angles.csv``
    into; creates nothing (call it before decoding)."""
    check_writable(Path(out_dir) / ANGLES_FILE, overwrite, create_parents=False)


def write_decoded(result: DecodeResult, out_dir: str | Path, overwrite: bool = False
                  ) -> list[Path]:
    """Write ``angles.csv``, ``ootx.toml`` (when any station's OOTX decoded) and ``imu.csv``
    (when the recording has IMU samples); nothing is written unless all of them may be."""
    out_dir = Path(out_dir)
    ootx, imu = out_dir / OOTX_FILE, out_dir / IMU_FILE
    targets = ([out_dir / ANGLES_FILE] + ([ootx] if result.calibrations else [])
               + ([imu] if result.imu is not None else []))
    for target in targets:
        check_writable(target, overwrite)
    written = [save_angles(result.angles, targets[0], overwrite)]
    if result.calibrations:
        written.append(save_calibration(result.calibrations, ootx, overwrite))
    if result.imu is not None:
        written.append(save_imu(result.imu, imu, overwrite, time_format="{:.7f}"))
    return written
