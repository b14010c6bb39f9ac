"""The photodiode board: sensor ids, positions and normals in the board frame (m)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.errors import InputError
from lhgraph.io.files import as_int, as_vector, get_key, read_toml, write_toml


@dataclass(frozen=True)
class Board:
    """Sensors of a board: ``ids`` (N,), ``positions`` and unit ``normals`` (N, 3), board frame."""

    ids: NDArray[np.int64]
    positions: NDArray[np.float64]
    normals: NDArray[np.float64]
    name: str = ""

    def index_of(self, sensor_ids: ArrayLike, source: str | Path | None = None) -> NDArray:
        """Row index of each sensor id; unknown ids raise InputError naming ``source``."""
        sensor_ids = np.asarray(sensor_ids, dtype=np.int64)
        order = np.argsort(self.ids)
        pos = np.searchsorted(self.ids[order], sensor_ids)
        pos = np.clip(pos, 0, len(order) - 1)
        idx = order[pos]
        bad = self.ids[idx] != sensor_ids
        if np.any(bad):
            unknown = sorted(set(sensor_ids[bad].tolist()))
            raise InputError(
                f"sensor id(s) {unknown[:5]} not on the board ({len(self.ids)} sensors)", source
            )
        return idx

    def is_planar(self, tol_m: float = 1e-3) -> bool:
        """True when all sensors lie within ``tol_m`` of one plane."""
        centred = self.positions - self.positions.mean(axis=0)
        return bool(np.linalg.svd(centred, compute_uv=False)[-1] < tol_m * np.sqrt(len(centred)))


MAX_EXTENT_M = 10.0
"""A board file's sensors lie within this distance of its origin on every axis (m)."""
MIN_SPAN_M = 1e-3
"""A board file's sensors span at least this much on some axis (m)."""
MIN_SEPARATION_M = 1e-3
"""Two sensors of a board file are at least this far apart (m; real diodes: 8.8 mm and
more): nearer, one diode is listed twice."""


def coincident_sensors(ids: list[int], positions: list[NDArray[np.float64]]
                       ) -> list[tuple[int, int]]:
    """Pairs of sensor ids whose positions are less than :data:`MIN_SEPARATION_M` apart."""
    p = np.asarray(positions, dtype=float).reshape(-1, 3)
    i, j = np.nonzero(np.triu(np.linalg.norm(p[:, None] - p[None], axis=2)
                              < MIN_SEPARATION_M, k=1))
    return [(ids[a], ids[b]) for a, b in zip(i.tolist(), j.tolist(), strict=True)]


def make_board(positions: ArrayLike, normals: ArrayLike, ids: ArrayLike | None = None,
               name: str = "") -> Board:
    """Board from arrays; normals are normalised, ids default to 0..N-1."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    ids = np.arange(len(positions)) if ids is None else np.asarray(ids, dtype=np.int64)
    return Board(ids.astype(np.int64), positions, normals, name)


def with_sensor_offsets(board: Board, offsets_m: ArrayLike) -> Board:
    """``board`` with every sensor moved by ``offsets_m`` (N, 3) (m, board frame, by board
    row; e.g. what a graph solve with sensor offsets found); normals and ids kept."""
    offsets_m = np.asarray(offsets_m, dtype=float).reshape(board.positions.shape)
    return Board(board.ids.copy(), board.positions + offsets_m, board.normals.copy(),
                 board.name)


def load_board(path: str | Path) -> Board:
    """Read a board TOML (``[[sensors]]`` with ``id``, ``position``, ``normal``)."""
    data = read_toml(path)
    sensors = data.get("sensors")
    if not isinstance(sensors, list) or not sensors:
        raise InputError("expected at least one [[sensors]] table", path)
    ids, pos, nrm = [], [], []
    for i, s in enumerate(sensors):
        where = f"sensors[{i}]"
        if not isinstance(s, dict):
            raise InputError("expected a table", path, where)
        ids.append(as_int(get_key(s, "id", path, where), path, where + ".id"))
        pos.append(as_vector(get_key(s, "position", path, where), 3, path, where + ".position"))
        n = as_vector(get_key(s, "normal", path, where), 3, path, where + ".normal")
        if np.linalg.norm(n) < 1e-9:
            raise InputError("normal has zero length", path, where + ".normal")
        nrm.append(n)
    if len(set(ids)) != len(ids):
        raise InputError("duplicate sensor id", path, "sensors")
    far = [i for i, p in enumerate(pos) if np.max(np.abs(p)) > MAX_EXTENT_M]
    if far:
        raise InputError(f"position more than {MAX_EXTENT_M:g} m from the board origin", path,
                         f"sensors[{far[0]}].position")
    if len(pos) > 1 and np.ptp(np.array(pos), axis=0).max() < MIN_SPAN_M:
        raise InputError(f"the sensors' positions span less than {MIN_SPAN_M * 1e3:g} mm: "
                         "not a board a pose can be solved from", path, "sensors")
    if pairs := coincident_sensors(ids, pos):
        shown = ", ".join(f"{a} and {b}" for a, b in pairs[:5])
        more = f" (and {len(pairs) - 5} more pairs)" if len(pairs) > 5 else ""
        raise InputError(f"duplicate sensor positions: sensors {shown}{more} are less than "
                         f"{MIN_SEPARATION_M * 1e3:g} mm apart (one diode listed twice?)",
                         path, "sensors")
    return make_board(pos, nrm, ids, name=str(data.get("name", Path(path).stem)))


def save_board(board: Board, path: str | Path, overwrite: bool = False) -> Path:
    """Write a board TOML."""
    data = {
        "name": board.name,
        "sensors": [
            {"id": int(i), "position": [float(x) for x in p], "normal": [float(x) for x in n]}
            for i, p, n in zip(board.ids, board.positions, board.normals, strict=True)
        ],
    }
    return write_toml(path, data, overwrite)
