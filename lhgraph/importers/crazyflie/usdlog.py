"""The Crazyflie uSD-card event log: reader (:func:`read_usd_log`) and writer
(:func:`encode_usd_log`, :func:`write_usd_log`).

Layout (little-endian, docs/crazyflie.md): magic byte ``0xBC``, ``u16 version`` (1: event
timestamps ``u32`` ms, 2: ``u64`` µs), ``u16 n_event_types``; per event type ``u16 id``, a
NUL-terminated name, ``u16 n_vars`` and per variable a NUL-terminated ``name(T)`` with ``T``
a :mod:`struct` type character; then events (``u16 id``, timestamp, the variables packed in
header order, no padding) up to the last 4 bytes, the CRC-32 (zlib) of everything before.

A damaged log keeps what is valid and :attr:`UsdLog.notes` says what was dropped: after
bytes that are no event (an unknown id: flipped, inserted or lost bytes) the reader
resynchronises on the next run of :data:`RESYNC_RUN` whole events of known ids; an event
out of time order with its neighbours of its type is dropped; a cut-short last event ends
the log.
"""

from __future__ import annotations

import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.files import read_input, write_atomic

MAGIC = 0xBC
TIMESTAMP_TYPE = {1: "<u4", 2: "<u8"}
"""Event timestamp dtype per log version."""
TIMESTAMP_UNIT_S = {1: 1e-3, 2: 1e-6}
"""Seconds per timestamp tick per log version."""
_VARIABLE = re.compile(r"^(.+)\(([bBhHiIqQefd?])\)$")


@dataclass(frozen=True)
class EventType:
    """One event type of the header: ``id``, ``name`` and its variables as
    ``(name, struct type character)`` pairs, in packing order."""

    id: int
    name: str
    variables: tuple[tuple[str, str], ...]

    def dtype(self, version: int) -> np.dtype:
        """Packed numpy dtype of one event record (id, timestamp, variables)."""
        return np.dtype([("id", "<u2"), ("timestamp", TIMESTAMP_TYPE[version])]
                        + [(name, "<" + t) for name, t in self.variables])


@dataclass(frozen=True)
class UsdLog:
    """A decoded log: ``events[name]`` is a structured array (fields ``timestamp`` in ticks
    and the variables), ``order`` the type id of every kept event in file order, ``notes``
    what the reader dropped (empty for an intact log), ``clock_scale`` the seconds of a
    reference clock per second of the log's (1: the log's own;
    :func:`lhgraph.importers.crazyflie.clock.deck_clock` measures it)."""

    version: int
    types: tuple[EventType, ...]
    events: dict[str, NDArray]
    order: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    notes: tuple[str, ...] = ()
    clock_scale: float = 1.0

    def time_s(self, name: str) -> NDArray[np.float64]:
        """Timestamps (s, the log's clock times ``clock_scale``) of the events called
        ``name``."""
        return (self.events[name]["timestamp"].astype(float)
                * (TIMESTAMP_UNIT_S[self.version] * self.clock_scale))

    def count(self, name: str) -> int:
        """Number of events called ``name`` (0 if the type is absent)."""
        return len(self.events[name]) if name in self.events else 0

    def require(self, name: str, variables: tuple[str, ...], source: str | Path | None = None
                ) -> None:
        """InputError naming ``source`` when the events called ``name`` lack any of
        ``variables`` (nothing to check when the log has no such events)."""
        if name not in self.events:
            return
        missing = [v for v in variables if v not in self.events[name].dtype.names]
        if missing:
            raise InputError(f"{name} events lack {', '.join(missing)}", source)


RESERVED = ("id", "timestamp")
"""Field names every event record has: no variable may take them."""


RESYNC_RUN = 8
"""Whole events of known ids in a row that resynchronise the reader after damage (random
bytes pass as one with odds of about n_types / 65536 per event)."""


def _cstring(data: bytes, pos: int, source: Path) -> tuple[str, int]:
    end = data.find(b"\0", pos)
    if end < 0:
        raise InputError(f"header cut short at byte {pos}", source)
    try:
        return data[pos:end].decode("ascii"), end + 1
    except UnicodeDecodeError:
        raise InputError(f"header string at byte {pos} is not ASCII", source) from None


def _u16(data: bytes, pos: int, source: Path) -> int:
    if pos + 2 > len(data):
        raise InputError(f"header cut short at byte {pos}", source)
    return int.from_bytes(data[pos:pos + 2], "little")


def _read_header(data: bytes, source: Path) -> tuple[int, tuple[EventType, ...], int]:
    if len(data) < 5 or data[0] != MAGIC:
        first = f"0x{data[0]:02X}" if data else "nothing"
        raise InputError(f"not a Crazyflie uSD log (starts with {first}, expected 0xBC)", source)
    version, n_types = _u16(data, 1, source), _u16(data, 3, source)
    if version not in TIMESTAMP_TYPE:
        raise InputError(f"uSD log version {version} is not supported (1 or 2)", source)
    pos, types = 5, []
    for _ in range(n_types):
        type_id = _u16(data, pos, source)
        name, pos = _cstring(data, pos + 2, source)
        n_vars = _u16(data, pos, source)
        pos += 2
        variables = []
        for _ in range(n_vars):
            spec, pos = _cstring(data, pos, source)
            m = _VARIABLE.match(spec)
            if m is None:
                raise InputError(f"event {name!r}: variable {spec!r} is not 'name(T)'", source)
            variables.append((m.group(1), m.group(2)))
        names = [v for v, _ in variables]
        clash = sorted({v for v in names if names.count(v) > 1 or v in RESERVED})
        if clash:
            raise InputError(f"event {name!r}: variable name(s) {', '.join(clash)} repeated "
                             "or reserved (id, timestamp)", source)
        types.append(EventType(type_id, name, tuple(variables)))
    if len({t.id for t in types}) != len(types):
        raise InputError("header lists an event id twice", source)
    return version, tuple(types), pos


def _event_run(data: bytes, pos: int, end: int, sizes: dict[int, int], limit: int) -> int:
    """How many whole events of known ids follow one another from ``pos`` (at most
    ``limit``)."""
    n = 0
    while n < limit and pos + 2 <= end:
        size = sizes.get(data[pos] | (data[pos + 1] << 8))
        if size is None or pos + size > end:
            break
        pos += size
        n += 1
    return n


def _scan(data: bytes, start: int, end: int, sizes: dict[int, int]
          ) -> tuple[list[int], list[int], list[tuple[int, int, str]]]:
    """Offsets and ids of the whole events in ``data[start:end]``, and the damaged stretches
    skipped, ``(first byte, first byte after, why)``: after an unknown event id the reading
    resumes at the first byte from which :data:`RESYNC_RUN` events of known ids follow one
    another (or the events left reach ``end`` exactly); a cut-short last event ends it."""
    offsets, ids, gaps, pos = [], [], [], start
    while pos < end:
        if pos + 2 > end:
            gaps.append((pos, end, "a cut-short last event"))
            break
        type_id = data[pos] | (data[pos + 1] << 8)
        size = sizes.get(type_id)
        if size is None:
            resume = next((p for p in range(pos + 1, end - 1)
                           if _event_run(data, p, end, sizes, RESYNC_RUN) == RESYNC_RUN
                           or _reaches_end(data, p, end, sizes)), end)
            gaps.append((pos, resume, f"unknown event id {type_id}"))
            pos = resume
            continue
        if pos + size > end:
            gaps.append((pos, end, "a cut-short last event"))
            break
        offsets.append(pos)
        ids.append(type_id)
        pos += size
    return offsets, ids, gaps


def _reaches_end(data: bytes, pos: int, end: int, sizes: dict[int, int]) -> bool:
    """True when whole events of known ids run from ``pos`` exactly to ``end``."""
    while pos + 2 <= end:
        size = sizes.get(data[pos] | (data[pos + 1] << 8))
        if size is None or pos + size > end:
            return False
        pos += size
    return pos == end


def read_usd_log(path: str | Path) -> UsdLog:
    """Read a uSD event log (see module); InputError if the file is not one."""
    source = Path(path)
    data = read_input(source, "a uSD log")
    version, types, start = _read_header(data, source)
    by_id = {t.id: t for t in types}
    sizes = {t.id: t.dtype(version).itemsize for t in types}
    crc_ok = len(data) >= start + 4 and (
        zlib.crc32(data[:-4]) == int.from_bytes(data[-4:], "little"))
    end = len(data) - 4 if crc_ok else len(data)
    offsets, ids, gaps = _scan(data, start, end, sizes)
    notes = []
    if not crc_ok:
        notes.append("CRC mismatch (log truncated or corrupted)")
    for a, b, why in gaps:
        what = "the CRC is missing" if not crc_ok and b == end else f"resumed at byte {b}"
        notes.append(f"dropped bytes {a}-{b} ({b - a} bytes: {why}; {what})")
    # The timestamps of one event type never go back (types interleave slightly out of
    # order): an event later than the next of its type, or earlier than the one before, is
    # damaged (a spike or a dip drops it and at most one neighbour) and dropped.
    ts_dtype = np.dtype(TIMESTAMP_TYPE[version])
    buf = np.frombuffer(data, dtype=np.uint8)
    off = np.asarray(offsets, dtype=np.int64)
    ids_arr = np.asarray(ids, dtype=np.int64)
    ts = buf[(off[:, None] + 2 + np.arange(ts_dtype.itemsize)).ravel()].copy().view(ts_dtype)
    back = np.zeros(len(off), dtype=bool)
    for type_id in by_id:
        at = np.flatnonzero(ids_arr == type_id)
        step_back = np.diff(ts[at].astype(np.int64)) < 0
        back[at[1:]] |= step_back
        back[at[:-1]] |= step_back
    if back.any():
        first = int(off[np.flatnonzero(back)[0]])
        notes.append(f"dropped {int(back.sum())} event(s) going back in time, the first at "
                     f"byte {first}")
        off, ids_arr = off[~back], ids_arr[~back]
    if gaps or back.any():
        notes.append(f"kept {len(off)} events")
    elif not crc_ok:
        # Read to the very end without a CRC: the last 4 bytes were event data, unless they
        # are exactly a damaged CRC; events parse cleanly, so the damage is inside values.
        notes.append(f"kept all {len(off)} events (their values are not verified)")
    events = {}
    for type_id, t in by_id.items():
        rows = off[ids_arr == type_id]
        dt = t.dtype(version)
        raw = buf[(rows[:, None] + np.arange(dt.itemsize)).ravel()].copy()
        events[t.name] = raw.view(dt)
    return UsdLog(version, types, events, ids_arr, tuple(notes))


def encode_usd_log(log: UsdLog) -> bytes:
    """The bytes of a uSD log (header, events, CRC-32). Events are written in ``log.order``
    when it lists every event, else merged by timestamp (stable, header order on ties)."""
    if log.version not in TIMESTAMP_TYPE:
        raise InputError(f"uSD log version {log.version} is not supported (1 or 2)")
    head = [struct.pack("<BHH", MAGIC, log.version, len(log.types))]
    for t in log.types:
        head.append(struct.pack("<H", t.id) + t.name.encode("ascii") + b"\0"
                    + struct.pack("<H", len(t.variables)))
        head += [f"{name}({code})".encode("ascii") + b"\0" for name, code in t.variables]
    records, type_ids, times = [], [], []
    for t in log.types:
        ev = log.events.get(t.name)
        n = 0 if ev is None else len(ev)
        packed = np.zeros(n, dtype=t.dtype(log.version))
        for name in packed.dtype.names:
            if name != "id":
                packed[name] = ev[name]
        packed["id"] = t.id
        records.append(packed)
        type_ids.append(np.full(n, t.id))
        times.append(packed["timestamp"].astype(np.int64))
    ids = np.concatenate(type_ids) if type_ids else np.zeros(0, dtype=np.int64)
    if len(log.order) == len(ids):
        sequence = [np.flatnonzero(np.asarray(log.order) == t.id) for t in log.types]
        order = np.argsort(np.concatenate(sequence), kind="stable")
    else:
        order = np.argsort(np.concatenate(times), kind="stable")
    blobs = [r.tobytes() for r in records]
    sizes = np.concatenate([np.full(len(r), r.dtype.itemsize) for r in records])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    flat = b"".join(blobs)
    body = b"".join(flat[s:s + n] for s, n in zip(starts[order], sizes[order], strict=True))
    data = b"".join(head) + body
    return data + struct.pack("<I", zlib.crc32(data))


def write_usd_log(log: UsdLog, path: str | Path, overwrite: bool = False) -> Path:
    """Write ``log`` as a uSD event log file (:func:`encode_usd_log`), atomically."""
    return write_atomic(path, encode_usd_log(log), overwrite)
