"""The dataset's Qualisys recording (``mocapNN.npy``) on the log's clock (its stamps as the
log gives them: scaled to the deck's clock by the importer).

``mocapNN.npy``: ``float64 (N, 4)``, Qualisys time (ms), x, y, z (m) of the marker body, NaN
where unseen; its first and last rows are the moments the active markers were switched on
and off, which the log records as ``activeMarkerModeChanged`` events (mode 1, mode 0).
Matching the two pairs fixes the offset and the relative clock rate (:func:`align_mocap`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.importers.crazyflie.usdlog import UsdLog
from lhgraph.io.files import unreadable

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Mocap:
    """Marker-body positions on the log's clock: ``time`` (s), ``position`` (N, 3, m,
    Qualisys frame) for the seen samples; ``n_unseen`` rows left out; ``rate`` = log seconds
    per Qualisys second."""

    time: Array
    position: Array
    n_unseen: int
    rate: float


def marker_events_s(log: UsdLog, source: str | Path | None = None) -> tuple[float, float]:
    """Log times (s) of the markers' on (mode 1) and off (mode 0) events."""
    if log.count("activeMarkerModeChanged") == 0:
        raise InputError("no activeMarkerModeChanged events: cannot align the mocap", source)
    log.require("activeMarkerModeChanged", ("mode",), source)
    mode = log.events["activeMarkerModeChanged"]["mode"]
    t = log.time_s("activeMarkerModeChanged")
    on, off = t[mode == 1], t[mode == 0]
    if len(on) == 0 or len(off) == 0 or off[-1] <= on[0]:
        raise InputError("needs a marker-on event followed by a marker-off event", source)
    return float(on[0]), float(off[-1])


def read_mocap_npy(path: str | Path) -> Array:
    """The raw ``(N, 4)`` array of a ``mocapNN.npy``; InputError if it is not one."""
    try:
        m = np.load(Path(path), allow_pickle=False)
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError, PermissionError) as exc:
        raise unreadable(exc, path, "a numpy .npy array") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"not a numpy .npy array ({exc})", path) from None
    if not isinstance(m, np.ndarray):  # an .npz archive
        raise InputError("not a numpy .npy array (an .npz archive?)", path)
    if m.ndim != 2 or m.shape[1] != 4 or len(m) < 2 or not np.all(np.isfinite(m[:, 0])):
        raise InputError(f"expected an (N, 4) array of time (ms), x, y, z; got {m.shape}", path)
    if not np.all(np.diff(m[:, 0]) > 0):
        row = int(np.flatnonzero(np.diff(m[:, 0]) <= 0)[0]) + 1
        raise InputError(f"times (column 0) must increase: row {row} is not after row {row - 1}",
                         path)
    return m.astype(float)


def align_mocap(mocap_ms: Array, marker_on_s: float, marker_off_s: float) -> Mocap:
    """Qualisys rows onto the log clock: first row -> ``marker_on_s``, last row ->
    ``marker_off_s``, linear in between."""
    t_q = (mocap_ms[:, 0] - mocap_ms[0, 0]) * 1e-3
    rate = (marker_off_s - marker_on_s) / t_q[-1]
    seen = np.all(np.isfinite(mocap_ms[:, 1:]), axis=1)
    return Mocap(marker_on_s + t_q[seen] * rate, mocap_ms[seen, 1:], int(np.sum(~seen)), rate)
