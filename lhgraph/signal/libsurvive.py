"""Reader of libsurvive recordings (``.rec`` / ``.rec.gz``) and their ``.json`` config.

A recording is text, one event per line: ``<host time s> <device> <type> ...``. Used here:

- ``C channel timecode length`` — a raw light pulse as the device reported it (48 MHz
  ticks of the device clock, 32-bit wrapping timecode of the rising edge; ``length`` ticks);
  the channel is the sensor index unless the device's ``CONFIG`` line has a ``channelMap``
  (sensor index -> channel), which is applied here;
- ``A sensor acode timecode length_s angle lh`` — libsurvive's own decoded sweep angle
  (rad, ``(t_centre - t_sync - 200000) * 2 pi / 800000`` with ``t_centre`` = timecode +
  length // 2; ``acode & 1`` is the axis).

Timecodes are unwrapped to int64 ticks counted from the device's first ``C`` line.
The ``.json`` beside a recording is libsurvive's ``config.json`` (its factory calibration
and solved poses per lighthouse), read by :mod:`lhgraph.io.libsurvive_config`.
"""

from __future__ import annotations

import gzip
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import make_pose
from lhgraph.io.libsurvive_config import R_SURVIVE_LH, read_survive_config
from lhgraph.model.board import Board, make_board
from lhgraph.model.calibration import StationCalibration
from lhgraph.signal.pulses import LightPulses

TICK_HZ = 48_000_000
MAX_CHANNEL = 255
"""The largest raw light channel a libsurvive device's ``channelMap`` may name."""


@dataclass
class LibsurviveAngles:
    """libsurvive's decoded angles of one device (``A`` lines); times in unwrapped ticks."""

    sensor: NDArray[np.int64]
    acode: NDArray[np.int64]
    timecode: NDArray[np.int64]
    length_s: NDArray[np.float64]
    angle: NDArray[np.float64]
    lighthouse: NDArray[np.int64]


@dataclass
class LibsurviveRecording:
    """Raw light pulses (``C`` lines, ticks) and libsurvive's angles of one device."""

    device: str
    pulses: LightPulses
    angles: LibsurviveAngles
    first_timecode: int
    sample_rate_hz: int = TICK_HZ


def _open_text(path: Path):
    if path.suffix == ".gz":
        return gzip.open(path, "rt", errors="replace")
    return path.open("r", errors="replace")


def read_libsurvive(path: str | Path, device: str | None = None) -> LibsurviveRecording:
    """Read one device's light pulses and angles from a libsurvive recording.

    ``device`` (e.g. ``"HMD"``) may be omitted when only one device has light data.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path)
    c_rows: dict[str, list[list[str]]] = {}
    a_rows: dict[str, list[list[str]]] = {}
    configs: dict[str, str] = {}
    try:
        with _open_text(path) as f:
            for line in f:
                parts = line.split()
                if len(parts) < 3:
                    continue
                if parts[2] == "C" and len(parts) >= 6:
                    c_rows.setdefault(parts[1], []).append(parts[3:6])
                elif parts[2] == "A" and len(parts) >= 9:
                    a_rows.setdefault(parts[1], []).append(parts[3:9])
                elif parts[2] == "CONFIG":
                    configs[parts[1]] = line.split("CONFIG", 1)[1]
    except (OSError, EOFError, UnicodeDecodeError) as exc:
        if not c_rows:
            raise InputError(f"unreadable recording ({exc})", path) from None
        # a truncated gzip keeps the lines read so far
    found = ", ".join(sorted(c_rows)) or "none"
    if device is None:
        if len(c_rows) != 1:
            raise InputError(f"give the device (devices with light data: {found})", path)
        device = next(iter(c_rows))
    if device not in c_rows:
        raise InputError(f"no raw light ('C') lines for device {device!r} (devices with light "
                         f"data: {found})", path)
    recording = _recording(path, device, c_rows[device], a_rows.get(device, []))
    channel_map = _channel_map(configs.get(device, ""))
    if channel_map is not None and (min(channel_map) < 0 or max(channel_map) > MAX_CHANNEL
                                    or len(set(channel_map)) != len(channel_map)):
        raise InputError(f"device {device!r}: its channelMap must list distinct channels in "
                         f"0..{MAX_CHANNEL}", path)
    if channel_map is not None:  # C lines carry raw channels; A lines sensor indices
        lookup = np.full(max(max(channel_map), int(recording.pulses.sensor.max())) + 1, -1)
        lookup[channel_map] = np.arange(len(channel_map))
        p = recording.pulses
        sensor = lookup[p.sensor]
        keep = sensor >= 0
        recording.pulses = LightPulses(sensor[keep], p.start[keep], p.end[keep], p.kind[keep])
    return recording


def _channel_map(config_text: str) -> list[int] | None:
    """The device config's ``channelMap`` (sensor index -> raw channel), if any."""
    found = re.search(r'"channelMap"\s*:\s*\[([^\]]*)\]', config_text)
    if not found:
        return None
    try:
        channels = [int(v) for v in found.group(1).split(",")]
    except ValueError:
        return None
    return channels or None


def _recording(path: Path, device: str, c_rows: list[list[str]], a_rows: list[list[str]]
               ) -> LibsurviveRecording:
    try:
        c = np.array(c_rows, dtype=np.int64)
        a = np.array(a_rows, dtype=float).reshape(-1, 6)
    except ValueError:
        raise InputError("malformed C or A line", path) from None
    first = int(c[0, 1])
    start = _unwrap32(c[:, 1]) - first
    pulses = LightPulses(c[:, 0], start, start + c[:, 2], np.full(len(c), -1, np.int64))
    a_ticks = _unwrap_near(a[:, 2].astype(np.int64) - first, start)
    angles = LibsurviveAngles(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a_ticks,
                              a[:, 3], a[:, 4], a[:, 5].astype(np.int64))
    return LibsurviveRecording(device, pulses, angles, first)


def _unwrap32(raw: NDArray[np.int64]) -> NDArray[np.int64]:
    """Unwrap 32-bit timecodes listed in (roughly) time order."""
    step = np.diff(raw) % (1 << 32)
    step = np.where(step >= (1 << 31), step - (1 << 32), step)
    return raw[0] + np.r_[0, np.cumsum(step)]


def _unwrap_near(values: NDArray[np.int64], reference: NDArray[np.int64]) -> NDArray[np.int64]:
    """Shift each value by a multiple of 2^32 to lie nearest to the reference timeline."""
    if len(values) == 0:
        return values
    lo, hi = reference.min(), reference.max()
    wrapped = (values - lo) % (1 << 32) + lo
    return np.where(wrapped > hi + (1 << 31), wrapped - (1 << 32), wrapped)


def read_libsurvive_calibration(path: str | Path) -> dict[int, StationCalibration]:
    """Factory calibration per libsurvive lighthouse index from a recording's ``.json`` (its
    ``config.json``: :func:`lhgraph.io.libsurvive_config.read_survive_config`)."""
    config = read_survive_config(path)
    out = {k: lh.calibration for k, lh in config.lighthouses.items()
           if lh.calibration is not None}
    if not out:
        raise InputError("no lighthouse with its factory calibration (OOTXSet 1)", path)
    return out


def read_libsurvive_board(path: str | Path, device: str) -> Board:
    """The device's photodiodes (``modelPoints``/``modelNormals`` of its ``CONFIG`` line, m,
    device frame) as a board; sensor ids are the indices used by its ``A`` lines."""
    path = Path(path)
    with _open_text(path) as f:
        for line in f:
            parts = line.split(maxsplit=3)
            if len(parts) == 4 and parts[1] == device and parts[2] == "CONFIG":
                try:
                    config = json.loads(line.split("CONFIG", 1)[1])
                    lc = config["lighthouse_config"]
                    return make_board(lc["modelPoints"], lc["modelNormals"], name=device)
                except (ValueError, KeyError, TypeError) as exc:
                    raise InputError(f"{device} CONFIG has no usable sensor geometry ({exc})",
                                     path) from None
    raise InputError(f"no CONFIG line for device {device!r}", path)


def read_libsurvive_poses(path: str | Path) -> dict[int, NDArray[np.float64]]:
    """libsurvive's own solved ``T_world_lh`` per lighthouse index from a recording's
    ``.json``, in libsurvive's frames (its lighthouse frame: x right, y up, looking along
    -z; :data:`lhgraph.io.libsurvive_config.R_SURVIVE_LH` turns it into ours)."""
    config = read_survive_config(path)
    return {k: make_pose(lh.T_world_lh[:3, :3] @ R_SURVIVE_LH.T, lh.T_world_lh[:3, 3])
            for k, lh in config.lighthouses.items() if lh.T_world_lh is not None}


def match_angles(recording: LibsurviveRecording, times_s: NDArray, sensors: NDArray
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pair libsurvive's ``A`` rows with decoded hits (time = pulse centre, s from the
    device's first pulse) of the same pulse: returns (A row indices, hit indices)."""
    p, a = recording.pulses, recording.angles
    rate = recording.sample_rate_hz
    pulse_key = p.start * 64 + p.sensor
    order = np.argsort(pulse_key)
    pos = np.clip(np.searchsorted(pulse_key[order], a.timecode * 64 + a.sensor), 0,
                  len(order) - 1)
    has_pulse = pulse_key[order][pos] == a.timecode * 64 + a.sensor
    length = (p.end - p.start)[order][pos]
    a_key = (2 * a.timecode + length) * 64 + a.sensor  # twice the centre, in ticks
    hit_key = np.round(2 * np.asarray(times_s) * rate).astype(np.int64) * 64 + sensors
    hit_order = np.argsort(hit_key)
    hpos = np.clip(np.searchsorted(hit_key[hit_order], a_key), 0, max(len(hit_key) - 1, 0))
    found = has_pulse & (len(hit_key) > 0)
    found &= hit_key[hit_order][hpos] == a_key if len(hit_key) else found
    return np.flatnonzero(found), hit_order[hpos[found]]
