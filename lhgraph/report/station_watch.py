"""The moved-station watch's per-window tests as CSV (``lhgraph track --watch-csv``,
docs/track.md): one row per station and window tested, in time order."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lhgraph.estimation.station_watch import WatchResult
from lhgraph.io.files import write_atomic

WATCH_COLUMNS = ("station", "t0_s", "t1_s", "z_sigma", "position_mm", "rotation_deg", "out")
"""The columns: the window ``[t0_s, t1_s)``, the distance from the station's history in
sigmas, the difference from the history's median (mm, degrees) and whether the window is
out (1) or not (0)."""


def save_watch_tests(result: WatchResult, path: str | Path, overwrite: bool = False) -> Path:
    """Write ``result``'s station tests to the CSV ``path`` (atomically; an existing file
    only with ``overwrite``)."""
    rows = [",".join(WATCH_COLUMNS)]
    for t in sorted(result.tests, key=lambda t: (t.t0_s, t.station)):
        rows.append(f"{t.station},{t.t0_s:.3f},{t.t1_s:.3f},{t.z:.3f},"
                    f"{t.position_m * 1e3:.3f},{np.degrees(t.rotation_rad):.4f},{int(t.out)}")
    return write_atomic(path, ("\n".join(rows) + "\n").encode(), overwrite)
