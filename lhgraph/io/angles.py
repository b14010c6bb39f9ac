"""Sweep-angle tables (``*.csv``: ``time,lighthouse,axis,sensor,angle``; SPEC §4).

One row per sweep hit: hit time (s), station index, axis (0 azimuth, 1 elevation), sensor
id, and the angle (rad) as decoded from timing, before factory-calibration correction.
Extra columns are kept in :attr:`Angles.extra` and written back.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.files import TEXT_ENCODING, read_csv_columns, write_csv_columns
from lhgraph.model.board import Board

SWEEP_GAP_S = 4e-3
"""Hits of one station and axis further apart than this belong to different sweeps."""

COLUMNS: tuple[tuple[str, type], ...] = (
    ("time", float), ("lighthouse", int), ("axis", int), ("sensor", int), ("angle", float),
)


@dataclass
class Angles:
    """Columns of an angles table, all of length N, sorted by time."""

    time: NDArray[np.float64]
    lighthouse: NDArray[np.int64]
    axis: NDArray[np.int64]
    sensor: NDArray[np.int64]
    angle: NDArray[np.float64]
    extra: dict[str, NDArray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.time)

    def select(self, mask: NDArray) -> Angles:
        """Rows where ``mask`` (bool or index array) holds."""
        return Angles(self.time[mask], self.lighthouse[mask], self.axis[mask], self.sensor[mask],
                      self.angle[mask], {k: v[mask] for k, v in self.extra.items()})

    def stations(self) -> list[int]:
        """Sorted station indices present."""
        return sorted(set(self.lighthouse.tolist()))

    def sweep_ids(self, max_gap_s: float = SWEEP_GAP_S) -> NDArray[np.int64]:
        """Sweep index of every hit, numbered 0.. in time order.

        A sweep is one pass of one station's laser (one 8.333 ms slot). Uses the extra
        ``sweep`` column when present; otherwise hits of the same station and axis belong to
        one sweep while they are less than ``max_gap_s`` after the sweep's first hit.
        """
        if "sweep" in self.extra:
            _, sweep = np.unique(np.asarray(self.extra["sweep"], dtype=np.int64),
                                 return_inverse=True)
            stations, station = np.unique(self.lighthouse, return_inverse=True)
            _, ids = np.unique(sweep * len(stations) + station, return_inverse=True)
            return ids.astype(np.int64)
        ids = np.empty(len(self), dtype=np.int64)
        open_sweeps: dict[tuple[int, int], tuple[int, float]] = {}
        count = 0
        for i, (t, lh, ax) in enumerate(zip(self.time, self.lighthouse, self.axis, strict=True)):
            current = open_sweeps.get((lh, ax))
            if current is None or t - current[1] > max_gap_s:
                current = (count, t)
                open_sweeps[(lh, ax)] = current
                count += 1
            ids[i] = current[0]
        return ids

    def check_board(self, board: Board, source: str | Path | None = None) -> NDArray:
        """Board row index of each hit; unknown sensor ids raise InputError."""
        return board.index_of(self.sensor, source)


def validate(a: Angles, source: str | Path | None = None) -> Angles:
    """Check value ranges and ordering; errors name the (1-based, header = 1) line."""
    def fail(mask: NDArray, problem: str) -> None:
        row = int(np.flatnonzero(mask)[0])
        raise InputError(problem, source, str(row + 2))

    if np.any(bad := ~np.isin(a.axis, (0, 1))):
        fail(bad, f"axis must be 0 or 1, got {a.axis[bad][0]}")
    if np.any(bad := a.lighthouse < 0):
        fail(bad, "lighthouse index must be >= 0")
    if np.any(bad := a.sensor < 0):
        fail(bad, "sensor id must be >= 0")
    if np.any(bad := np.abs(a.angle) > np.pi):
        fail(bad, f"angle {a.angle[bad][0]:.6g} rad is outside [-pi, pi]")
    if len(a) > 1 and np.any(back := np.diff(a.time) < 0):
        fail(np.r_[False, back], "time goes backwards")
    repeats = duplicate_rows(a)
    if len(repeats):
        first = int(repeats[0])
        raise InputError(f"repeats an earlier row exactly: a hit counted twice ({len(repeats)} "
                         "such rows in the file; remove them)", source, str(first + 2))
    return a


def duplicate_rows(a: Angles) -> NDArray[np.int64]:
    """Rows (sorted indices) identical in every column to an earlier row; ``a`` sorted by
    time, so only rows sharing a time are compared."""
    if len(a) < 2:
        return np.zeros(0, np.int64)
    tied = np.flatnonzero(np.diff(a.time) == 0)
    rows = np.unique(np.r_[tied, tied + 1])
    if len(rows) == 0:
        return rows.astype(np.int64)
    columns = [a.time, a.lighthouse, a.axis, a.sensor, a.angle, *a.extra.values()]
    keys = [np.asarray(c)[rows] for c in columns]
    order = np.lexsort((rows, *keys[::-1]))  # equal rows together, earliest first
    same = np.ones(len(rows) - 1, bool)
    for k in keys:
        same &= k[order][1:] == k[order][:-1]
    return np.sort(rows[order][1:][same]).astype(np.int64)


def load_angles(path: str | Path) -> Angles:
    """Read and validate an angles CSV."""
    extras = _extra_names(path)
    cols = read_csv_columns(path, COLUMNS, optional=extras)
    a = Angles(cols["time"], cols["lighthouse"], cols["axis"], cols["sensor"], cols["angle"],
               {k: cols[k] for k in extras if k in cols})
    if len(a) == 0:
        raise InputError("no rows after the header", path)
    return validate(a, path)


def _extra_names(path: str | Path) -> list[str]:
    try:
        with Path(path).open(encoding=TEXT_ENCODING) as f:
            header = [h.strip() for h in f.readline().split(",")]
    except (OSError, UnicodeDecodeError):
        return []  # read_csv_columns says what is wrong with the file
    return [h for h in header if h not in dict(COLUMNS)]


def save_angles(a: Angles, path: str | Path, overwrite: bool = False) -> Path:
    """Write an angles CSV (contract columns, then extras)."""
    cols = {"time": a.time, "lighthouse": a.lighthouse, "axis": a.axis, "sensor": a.sensor,
            "angle": a.angle, **a.extra}
    fmts = {"time": "{:.9f}", "lighthouse": "{:d}", "axis": "{:d}", "sensor": "{:d}",
            "angle": "{:.12g}"}
    for k, v in a.extra.items():
        if np.issubdtype(np.asarray(v).dtype, np.integer):
            fmts[k] = "{:d}"
    return write_csv_columns(path, cols, fmts, overwrite)
