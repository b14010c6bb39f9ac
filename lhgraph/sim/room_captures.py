"""A room larger than one capture: :func:`room_captures` cuts one simulated walk round a
many-station room (configs/simulation/lh2_room16.toml) into captures that each see a few
stations, as a lab calibrates a big room wave by wave (issue #41 item 3).

Capture ``c`` is the stretch ``[c segment_s, (c + 1) segment_s)`` of the walk with the hits
of at most ``max_stations`` of the stations that saw the board in it, only: a wave in one
corner, seen by the stations there. So that every capture hangs from the others, each keeps
the station it saw most among those the previous capture kept; the rest are the stations no
capture kept yet (most hits first), then the others by hits: every station the walk shows
well enough ends in some capture.
"""

from __future__ import annotations

import numpy as np

from lhgraph.errors import InputError
from lhgraph.io.angles import Angles


def room_captures(angles: Angles, segment_s: float, max_stations: int = 4,
                  min_hits: int = 500) -> list[Angles]:
    """``angles`` (one walk, times in s) cut into captures of ``segment_s`` seconds, each
    with the hits of at most ``max_stations`` stations (those with ``min_hits`` hits or
    more in it), every capture sharing a station with the one before it."""
    if segment_s <= 0 or max_stations < 2:
        raise InputError("needs segment_s > 0 and max_stations >= 2", where="room_captures")
    t0, t1 = float(angles.time[0]), float(angles.time[-1])
    out: list[Angles] = []
    previous: set[int] = set()
    covered: set[int] = set()
    for start in np.arange(t0, t1, segment_s):
        part = angles.select((angles.time >= start) & (angles.time < start + segment_s))
        seen, counts = np.unique(part.lighthouse, return_counts=True)
        hits = {int(k): int(n) for k, n in zip(seen, counts, strict=True) if n >= min_hits}
        by_hits = sorted(hits, key=lambda k: -hits[k])
        shared = [k for k in by_hits if k in previous]
        if previous and not shared:
            continue
        keep = shared[:1]
        for k in sorted(by_hits, key=lambda k: k in covered):  # stable: by hits within
            if len(keep) < max_stations and k not in keep:
                keep.append(k)
        if len(keep) < 2:
            continue
        out.append(part.select(np.isin(part.lighthouse, keep)))
        previous = set(keep)
        covered |= previous
    return out
