"""Which stations see the board together: the co-visibility graph of a capture (or of several
joined, :func:`lhgraph.io.captures.join_captures`), what links every station's pose to the
reference's (issue #41 item 3; drawn in the run report, docs/workflow.md).

A station's pose is fixed relative to another's by the board states both see within a short
time of each other (the initialiser joins them over the same pairs,
:func:`lhgraph.estimation.init.pnp_kabsch.overlap_tree`); two stations never seen together are
linked only through others. :func:`co_visibility` counts, for every pair of stations, the
sweeps of one within ``max_gap_s`` of a sweep of the other (``links``), notes the captures
each station is seen in, and :meth:`Visibility.hops` gives each station's distance from the
reference in links: the chain its pose hangs from (unreachable: not in the result).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from lhgraph.io.angles import Angles

LINK_GAP_S = 0.05
"""Two sweeps this close in time (s) see the board at one pose, as the initialiser pairs
them."""


@dataclass(frozen=True)
class Visibility:
    """The co-visibility of a capture: ``hits`` per station, the ``captures`` (0-based, one
    capture: ``[0]``) each station is seen in, and ``links[(a, b)]`` (a < b) the sweeps of
    either within ``max_gap_s`` of one of the other (pairs never seen together absent)."""

    hits: dict[int, int]
    captures: dict[int, list[int]]
    links: dict[tuple[int, int], int]

    def stations(self) -> list[int]:
        """Sorted station indices."""
        return sorted(self.hits)

    def neighbours(self, k: int) -> list[int]:
        """The stations linked to ``k``."""
        return sorted({b if a == k else a for a, b in self.links if k in (a, b)})

    def hops(self, reference: int) -> dict[int, int]:
        """Each station's distance in links from ``reference`` (breadth first); stations
        not linked to it are absent."""
        out = {reference: 0}
        queue = deque([reference])
        while queue:
            k = queue.popleft()
            for n in self.neighbours(k):
                if n not in out:
                    out[n] = out[k] + 1
                    queue.append(n)
        return out


def co_visibility(angles: Angles, max_gap_s: float = LINK_GAP_S) -> Visibility:
    """The co-visibility graph of ``angles`` (times in s; an ``extra["capture"]`` column
    names each hit's capture, else one capture): each sweep is dated at its first hit."""
    sweep = angles.sweep_ids()
    first = np.unique(sweep, return_index=True)[1]
    t, lh = angles.time[first], angles.lighthouse[first]
    capture = np.asarray(angles.extra.get("capture", np.zeros(len(angles), dtype=np.int64)))
    stations = np.unique(angles.lighthouse).tolist()
    hits = {k: int(np.sum(angles.lighthouse == k)) for k in stations}
    captures = {k: np.unique(capture[angles.lighthouse == k]).tolist() for k in stations}
    times = {k: np.sort(t[lh == k]) for k in stations}
    links = {}
    for i, a in enumerate(stations):
        for b in stations[i + 1:]:
            n = _near(times[a], times[b], max_gap_s) + _near(times[b], times[a], max_gap_s)
            if n:
                links[(a, b)] = n
    return Visibility(hits, captures, links)


def _near(t: np.ndarray, other: np.ndarray, gap_s: float) -> int:
    """How many of the times ``t`` lie within ``gap_s`` of one of the sorted ``other``."""
    if len(other) == 0 or len(t) == 0:
        return 0
    j = np.clip(np.searchsorted(other, t), 1, len(other) - 1)
    d = np.minimum(np.abs(t - other[j - 1]), np.abs(other[j] - t))
    if len(other) == 1:
        d = np.abs(t - other[0])
    return int(np.sum(d <= gap_s))
